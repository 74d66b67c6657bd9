"""``python -m solid_fenicsx.convert IN OUT.xdmf``: a tet mesh file as the XDMF + HDF5 the solid
reads in parallel (:mod:`solid_fenicsx.xdmf_mesh`), its facet and cell tags and their physical
names kept. Under ``mpirun -n N`` dolfinx writes each rank's part (IN itself is read as the solid
reads it: meshio on rank 0 for a gmsh file). Prints the counts and every tag with its name and
size; exit 0, or 2 with one line ``...: error: <file>: <reason>`` for bad input.

It lives in the solid participant, not in ``varcouple``'s command line: the coupler imports no
participant's solver modules (tests/test_layers.py), and the conversion is dolfinx's.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mpi4py import MPI

from . import xdmf_mesh
from .mesh import SolidMesh, SolidMeshError, agree, read_mesh, tag_counts

PROG = "python -m solid_fenicsx.convert"


def tag_sizes(solid: SolidMesh) -> dict[str, dict[str, int]]:
    """name -> the number of facets (``boundaries``) or tetrahedra (``regions``) with its tag."""
    tdim = solid.mesh.topology.dim
    return {"boundaries": tag_counts(solid.mesh, tdim - 1, solid.facet_tags, solid.boundaries),
            "regions": tag_counts(solid.mesh, tdim, solid.cell_tags, solid.regions)}


def convert(source: Path, target: Path, tag_key: str | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> SolidMesh:
    """Read `source` as the solid does and write it to `target` (collective)."""
    if target.suffix.lower() != ".xdmf":
        raise SolidMeshError(f"{target}: the output must be an .xdmf file")
    if not target.parent.is_dir():
        raise SolidMeshError(f"{target}: no directory {target.parent}")
    solid = read_mesh(source, tag_key=tag_key, comm=comm)
    error = None
    try:
        xdmf_mesh.write(target, solid)
    except Exception as exc:  # noqa: BLE001 - HDF5, permissions, disk: one line on every rank
        error = f"{target}: cannot write it ({type(exc).__name__}: {exc})"
    agree(comm, error)
    return solid


def report(target: Path, solid: SolidMesh) -> str:
    sizes = tag_sizes(solid)
    lines = [f"wrote {target} and {target.with_suffix('.h5').name}: {solid.num_points} points, "
             f"{solid.num_cells} tetrahedra, written by {solid.comm.size} rank(s)"]
    for kind, what in (("boundaries", "facets"), ("regions", "tetrahedra")):
        names = getattr(solid, kind)
        tags = ", ".join(f"{name} = {tag} ({sizes[kind][name]} {what})" for name, tag in names.items())
        lines.append(f"{kind} ({'facet' if kind == 'boundaries' else 'cell'} tags): {tags or 'none'}")
    return "\n".join(lines)


def main(argv: list[str] | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("source", metavar="IN", type=Path, help="tet mesh file (gmsh .msh, or any format meshio reads)")
    parser.add_argument("target", metavar="OUT", type=Path, help="the .xdmf file to write (its .h5 beside it)")
    parser.add_argument("--tag-key", default=None, metavar="KEY",
                        help="the cell data holding the tags (default: gmsh:physical, or the first integer one)")
    args = parser.parse_args(argv)
    try:
        solid = convert(args.source, args.target, args.tag_key, comm)
    except SolidMeshError as exc:
        if comm.rank == 0:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    text = report(args.target, solid)
    if comm.rank == 0:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
