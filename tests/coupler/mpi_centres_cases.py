"""Run under ``mpirun -n P`` by test_centres_ranks.py: the binary solid fraction at the cell centres
on P coupler ranks (coupler.fsi.ranks.slab_centres) against the serial mask of the whole mesh
(coupler.fsi.centres.centres_inside). Each rank holds the tetrahedra whose centroid lies in the
next rank's grid slab, so every centre of a rank's slab lies in tetrahedra another rank holds.
Rank 0 prints, as JSON, per case the cells of all slabs whose distributed mask differs from the
serial one, those whose mask from the rank's own tetrahedra alone (no OR over the ranks) does,
and the cells inside."""

from __future__ import annotations

import json

import numpy as np
from mpi4py import MPI

from coupler.fsi.centres import centre_cells, centres_inside
from coupler.fsi.ranks import GridSlab, slab_centres
from transfer import Mesh, StructuredGrid
from transfer.generate import box_tetrahedra

comm = MPI.COMM_WORLD
GRID = StructuredGrid((0, 0, 0), (1, 1, 1), (8, 3, 3))  # slabs along x


def dealt(S: Mesh, slab: GridSlab) -> Mesh:
    """The tetrahedra of `S` this rank holds: those whose centroid lies in the slab of the next rank."""
    bounds = comm.allgather(slab.block[0][0])[1:] + [GRID.shape[0]]
    column = np.floor((S.points[S.cells].mean(axis=1)[:, 0] - GRID.origin[0]) / GRID.spacing[0])
    next_rank = (np.searchsorted(bounds, column, side="right") + 1) % comm.size
    cells = S.cells[next_rank == comm.rank]
    vertices, local = np.unique(cells, return_inverse=True)
    return (Mesh(S.points[vertices], local.reshape(-1, 4), "tetra") if len(cells)
            else Mesh.empty("tetra", "no tetrahedra"))


def case(S: Mesh) -> dict:
    slab = GridSlab(comm, GRID, "centres")
    mine = dealt(S, slab)
    serial = centres_inside(S, GRID)[slab.ids]
    ranks = slab_centres(comm, mine, slab)
    alone = np.isin(slab.ids, centre_cells(mine, GRID))
    return {"differ": comm.allreduce(int(np.count_nonzero(ranks != serial))),
            "differ_alone": comm.allreduce(int(np.count_nonzero(alone != serial))),
            "inside": comm.allreduce(int(np.count_nonzero(serial))),
            "tetrahedra": comm.allgather(mine.num_cells)}


CASES = {"jittered box": box_tetrahedra((6, 2, 2), (0.3, 0.2, 0.4), (7.6, 2.7, 2.9), jitter=0.2, seed=3),
         "between the centres": box_tetrahedra((1, 1, 1), (3.6, 0.6, 0.6), (3.9, 0.9, 0.9))}
found = {"ranks": comm.size, **{name: case(S) for name, S in CASES.items()}}
if comm.rank == 0:
    print(json.dumps(found), flush=True)
