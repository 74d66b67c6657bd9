"""Run under ``mpirun -n N`` by test_distributed.py: every pair of spaces assembled both
serially (on rank 0, the whole meshes) and distributed (each rank its own cells, source and
target cut differently), with the differences printed as JSON by rank 0.

Partitions do not align: the source in slabs along x, the target along z (grids in blocks
along y); in the case "empty ranks" only the first half of the ranks hold target cells.
"""

from __future__ import annotations

import json
import sys

import numpy as np
from mpi4py import MPI

from transfer import FunctionSpace, StructuredGrid, Transfer
from transfer.distributed import Part, gather
from transfer.generate import box_hexahedra, box_tetrahedra, rectangle
from transfer.partition import grid_slab, slabs
from transfer.petsc import gather_matrix

comm = MPI.COMM_WORLD


def field(x):
    return np.sin(3 * x[:, 0]) + x[:, 1] * x[:, 2] + 2 * x[:, 2] ** 2


def mesh_part(mesh, family, axis, ranks=None):
    ranks = ranks or comm.size
    owner = slabs(mesh, ranks, axis)
    return Part.of_cells(mesh, np.flatnonzero(owner == comm.rank), family)


def grid_part(grid, family, axis):
    return Part.grid_block(grid, *grid_slab(grid.shape, comm.size, comm.rank, axis), family)


def tets(n, seed, **kw):
    return box_tetrahedra((n,) * 3, jitter=0.2, seed=seed, name=f"tets{n}", **kw)


def surface(cell_type, shape, seed, height):
    return rectangle(shape, lower=(0.1, 0.1), upper=(0.9, 0.9), cell_type=cell_type, jitter=0.2, seed=seed,
                     height=height)


GRID = StructuredGrid.from_bounds((-0.1, -0.1, -0.1), (1.1, 1.1, 1.1), (7, 6, 8), name="grid")
SMALL = box_tetrahedra((4, 4, 4), (0.2, 0.1, 0.3), (0.8, 0.9, 0.7), jitter=0.2, seed=5, name="inner")
CURVED = lambda x, y: 0.4 + 0.1 * x + 0.05 * np.sin(3 * y)  # noqa: E731


def cases():
    """name -> (serial source space, serial target space, source part, target part, kwargs)."""
    a, b = tets(4, 1), tets(5, 2)
    hexes = box_hexahedra((3, 4, 3), jitter=0.15, seed=3, name="hexes")
    tri, quad = surface("triangle", (6, 5), 2, CURVED), surface("quad", (5, 7), 3, CURVED)
    trace = surface("triangle", (5, 5), 4, lambda x, y: 0.3 + 0.2 * x + 0.1 * y)
    yield "tets P1 -> tets P1", a, "P1", b, "P1", mesh_part(a, "P1", 0), mesh_part(b, "P1", 2), {}
    yield "tets P0 -> tets P0", a, "P0", b, "P0", mesh_part(a, "P0", 0), mesh_part(b, "P0", 2), {}
    yield "hexes Q1 -> tets P1", hexes, "Q1", b, "P1", mesh_part(hexes, "Q1", 0), mesh_part(b, "P1", 2), {}
    yield "grid Q1 -> tets P1", GRID, "Q1", b, "P1", grid_part(GRID, "Q1", 1), mesh_part(b, "P1", 2), {}
    yield "tets P1 -> grid Q0 (partial)", SMALL, "P1", GRID, "Q0", mesh_part(SMALL, "P1", 0), \
        grid_part(GRID, "Q0", 1), {}
    yield "tets P1 -> triangles P1 (trace)", a, "P1", trace, "P1", mesh_part(a, "P1", 0), \
        mesh_part(trace, "P1", 1), {}
    yield "triangles P1 -> quads Q1 (mortar)", tri, "P1", quad, "Q1", mesh_part(tri, "P1", 0), \
        mesh_part(quad, "Q1", 1), {}
    half = max(1, comm.size // 2)
    yield "tets P1 -> tets P1 (empty ranks)", a, "P1", b, "P1", mesh_part(a, "P1", 0), \
        mesh_part(b, "P1", 2, ranks=half) if comm.rank < half else Part.of_cells(b, [], "P1"), {}


def compare(name, smesh, sfam, tmesh, tfam, ps, pt, kwargs) -> dict:
    out = {}
    for method in ("l2", "pseudo_l2"):
        S, T = FunctionSpace(smesh, sfam), FunctionSpace(tmesh, tfam)
        u = S.interpolate(field)
        dt = Transfer.assemble(ps, pt, method, comm=comm, **kwargs)
        v = gather(pt, dt.apply(u[ps.global_dofs]), comm)
        covered = gather(pt, dt.covered, comm)
        B, D = gather_matrix(dt.B, comm), gather_matrix(dt.D, comm)
        Tm = gather_matrix(dt.matrix(), comm) if method == "pseudo_l2" else None
        conservation = dt.conservation_error(u[ps.global_dofs])
        stats = dt.stats
        if comm.rank:
            continue
        serial = Transfer.assemble(S, T, method, **kwargs)
        vs = serial(u)
        scale = np.nanmax(np.abs(vs))
        out[method] = {
            "B": float(abs(B - serial.B).max() / abs(serial.B).max()),
            "D": float(abs(D - serial.D).max() / abs(serial.D).max()),
            "T": float(abs(Tm - serial.matrix()).max() / abs(serial.matrix()).max()) if Tm is not None else 0.0,
            "v": float(np.nanmax(np.abs(v - vs)) / scale),
            "nan_same": bool(np.array_equal(np.isnan(v), np.isnan(vs))),
            "covered_same": bool(np.array_equal(covered, serial.covered)),
            "covered_fraction": serial.covered_fraction,
            "conservation": conservation,
            "pairs": [stats["pairs_intersected"], serial.stats["pairs_intersected"]],
        }
    return out


def main():
    results = {}
    for name, *args in cases():
        results[name] = compare(name, *args)
    if comm.rank == 0:
        print(json.dumps({"ranks": comm.size, "cases": results}))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
