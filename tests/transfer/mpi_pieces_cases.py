"""Run under ``mpirun -n P`` by test_pieces_ranks.py with an XDMF + HDF5 tet mesh: each rank
reads its rows (:meth:`transfer.pieces.Pieces.rows`) and gets its part, which is compared with
the cells :func:`transfer.partition.bisection` gives it of the whole mesh (read here whole with
h5py on every rank). Rank 0 prints JSON: per rank the cells and points it read, whether its
cell ids, cells and points are the bisection's, and whether the whole mesh joined on rank 0 is
the file's."""

from __future__ import annotations

import json
import sys

import h5py
import numpy as np
from mpi4py import MPI

from transfer.mesh import Mesh
from transfer.meshfile import MeshFile
from transfer.partition import bisection
from transfer.pieces import Pieces

comm = MPI.COMM_WORLD
path = sys.argv[1]
pieces = Pieces.rows(path, comm)
with h5py.File(path.removesuffix(".xdmf") + ".h5", "r") as f:
    whole = Mesh(f["/Mesh/mesh/geometry"][:], f["/Mesh/mesh/topology"][:], "tetra", reorient=True)
mine = np.flatnonzero(bisection(whole, comm.size) == comm.rank)
held = pieces.held[0].mesh if pieces.held else Mesh.empty("tetra")
report = {"cells_read": MeshFile.cells_read, "points_read": MeshFile.points_read, "cells": len(mine),
          "cell_ids": bool(np.array_equal(pieces.cell_ids, mine)),
          "cells_equal": bool(np.array_equal(pieces.point_ids[held.cells], whole.cells[mine])),
          "points_equal": bool(np.array_equal(held.points, whole.points[pieces.point_ids]))}
joined = pieces.whole()
reports = comm.gather(report)
if comm.rank == 0:
    print(json.dumps({"ranks": comm.size, "num_cells": whole.num_cells, "num_points": whole.num_points,
                      "per_rank": reports, "whole": bool(np.array_equal(joined.mesh.cells, whole.cells)
                                                         and np.array_equal(joined.mesh.points, whole.points))}))
