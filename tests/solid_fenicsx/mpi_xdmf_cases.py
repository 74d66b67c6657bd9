"""The solid's mesh read from XDMF in parallel on the ranks of MPI.COMM_WORLD
(tests/solid_fenicsx/test_solid_mesh_xdmf.py): ``mpirun -n N python
tests/solid_fenicsx/mpi_xdmf_cases.py DIR`` converts small_fracture's solid.msh to DIR/solid.xdmf on
the N ranks (:mod:`solid_fenicsx.convert`), reads both files and prints as JSON from rank 0: the
converter's report, whether the two meshes are the same mesh matched by coordinates (points,
cells, tagged facets per boundary name, tagged cells per region name), the largest share of the
mesh one rank holds (none reads the whole file), whether the XDMF's input numbering is the file's rows on every number of
ranks (the whole job, and the job split in two), the largest difference of an elastic solution
on the two meshes, and the error every rank raised for bad files."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

import dolfinx
import dolfinx.io
import dolfinx.mesh
from mpi_mesh_cases import error_of, joined
from solid_fenicsx import Elasticity
from solid_fenicsx import mesh as solid_mesh
from solid_fenicsx.convert import convert, report
from solid_fenicsx.mesh import read_mesh

COMM = MPI.COMM_WORLD
ROOT = Path(__file__).resolve().parents[2]
MSH = ROOT / "cases" / "small_fracture" / "solid.msh"


def regions(solid) -> dict[str, set[int]]:
    """name -> the input cell ids of the cells with its tag (every rank)."""
    m, tags = solid.mesh, solid.cell_tags
    keep = tags.indices < m.topology.index_map(m.topology.dim).size_local
    original = np.asarray(m.topology.original_cell_index, np.int64)[tags.indices[keep]]
    found: dict[int, set[int]] = {}
    for ids, values in m.comm.allgather((original, tags.values[keep])):
        for i, v in zip(ids.tolist(), values.tolist()):
            found.setdefault(v, set()).add(i)
    return {name: found.get(tag, set()) for name, tag in solid.regions.items()}


def matched(a, b) -> dict:
    """Mesh `a` against mesh `b` with a's points renumbered as b's by their coordinates."""
    ja, jb = joined(a), joined(b)
    where = {tuple(x): i for i, x in enumerate(jb["points"].tolist())}
    perm = np.array([where.get(tuple(x), -1) for x in ja["points"].tolist()])
    bijective = bool((perm >= 0).all()) and len(set(perm.tolist())) == len(perm) == len(jb["points"])

    def cell_set(cells, ids=None):
        return {tuple(sorted(c)) for c in (cells if ids is None else cells[sorted(ids)]).tolist()}

    def facets(j, renumber, tags):
        return {name: {tuple(sorted(renumber[f[:3]].tolist())) for f in np.array(j["tags"]).reshape(-1, 4)
                       if f[3] == tag} for name, tag in tags.items()}

    same = {"points": bijective, "counts": ja["counts"] == jb["counts"],
            "cells": cell_set(perm[ja["cells"]]) == cell_set(jb["cells"]),
            "boundaries": a.boundaries == b.boundaries, "regions": a.regions == b.regions,
            "facets": facets(ja, perm, a.boundaries) == facets(jb, np.arange(len(perm)), b.boundaries),
            "tagged cells": {n: cell_set(perm[ja["cells"]], ids) for n, ids in regions(a).items()}
            == {n: cell_set(jb["cells"], ids) for n, ids in regions(b).items()}}
    return {"same": same, "perm": perm}


def displacement(solid) -> np.ndarray:
    """Both blocks held at bottom and top, 0.1 MPa on the fracture faces, LU: the vertex
    displacements in input numbering (every rank)."""
    s = Elasticity(solid, E=1e9, nu=0.25, solver="lu")
    s.add_dirichlet("bottom", 0.0)
    s.add_dirichlet("top", 0.0)
    s.add_pressure(["fracture_lower", "fracture_upper"], 1e5)
    return s.vertices.gather(s.solve_static(), root=None)


def numbering(path: Path) -> dict:
    """The XDMF's input numbering is the file's rows when read by the whole job and by each half."""
    with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(path), "r") as f:
        rows = (f.read_geometry_data("mesh"), np.asarray(f.read_topology_data("mesh"), np.int64))
    out = {}
    half = COMM.Split(0 if COMM.rank < max(1, COMM.size - 1) else 1, COMM.rank)
    for name, comm in (("job", COMM), ("split", half)):
        j = joined(read_mesh(path, comm=comm))
        same = bool(np.array_equal(j["points"], rows[0]) and np.array_equal(j["cells"], rows[1]))
        out[name] = COMM.allgather([comm.size, same])
    return out


def bad_files(directory: Path, good: Path) -> dict[str, str]:
    text = good.read_text()
    if COMM.rank == 0:
        (directory / "text.xdmf").write_text("not a mesh\n")
        (directory / "garbage.h5").write_text("not HDF5 either\n")
        (directory / "garbage.xdmf").write_text(text.replace("solid.h5:", "garbage.h5:"))
        (directory / "alone.xdmf").write_text(text)
        (directory / "dataset.xdmf").write_text(text.replace("/Mesh/mesh/topology", "/Mesh/nothing/topology"))
        (directory / "dataset.h5").write_bytes(good.with_suffix(".h5").read_bytes())
    cube = dolfinx.mesh.create_unit_cube(COMM, 2, 2, 2, dolfinx.mesh.CellType.hexahedron)
    with dolfinx.io.XDMFFile(COMM, str(directory / "hexahedra.xdmf"), "w") as f:
        f.write_mesh(cube)
    COMM.barrier()
    return {"missing": error_of(lambda: read_mesh(directory / "nothing.xdmf", comm=COMM)),
            "not XML": error_of(lambda: read_mesh(directory / "text.xdmf", comm=COMM)),
            "not HDF5": error_of(lambda: read_mesh(directory / "garbage.xdmf", comm=COMM)),
            "no HDF5": error_of(lambda: read_mesh(directory / "alone.xdmf", comm=COMM)),
            "no dataset": error_of(lambda: read_mesh(directory / "dataset.xdmf", comm=COMM)),
            "hexahedra": error_of(lambda: read_mesh(directory / "hexahedra.xdmf", comm=COMM)),
            "facet grid": error_of(lambda: read_mesh(good, tag_key="walls", comm=COMM)),
            "tag": error_of(lambda: read_mesh(good, comm=COMM).require_tags({"bottom": 1, "top": 9}, str(good)))}


def refuse(*args):
    raise AssertionError("rank 0 read the whole mesh file")


def main(directory: Path) -> None:
    path = directory / "solid.xdmf"
    made = convert(MSH, path, comm=COMM)
    text = report(path, made)
    msh = read_mesh(MSH, comm=COMM)
    read_on_root = solid_mesh._read_on_root
    solid_mesh._read_on_root = refuse  # the XDMF is not read whole on rank 0
    xdmf = read_mesh(path, comm=COMM)
    solid_mesh._read_on_root = read_on_root
    found = matched(msh, xdmf)
    u_msh, u_xdmf = displacement(msh), displacement(xdmf)
    held = xdmf.mesh.geometry.index_map()
    out = {"ranks": COMM.size, "report": text, "same": found["same"],
           "held": COMM.gather([held.size_local + held.num_ghosts, xdmf.num_points]),
           "displacement": float(np.max(np.abs(u_xdmf[found["perm"]] - u_msh)) / np.max(np.abs(u_msh))),
           "numbering": numbering(path), "errors": COMM.gather(bad_files(directory, path))}
    if COMM.rank == 0:
        print(json.dumps(out))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
