"""Run under ``mpirun -n N`` by test_distributed_qp.py: the QP on which the plain active set
method cycles (test_nonsmooth_active_set.py), its rows split over the ranks as a
:class:`nonsmooth.distributed.DistributedQP`, solved by the active set method; rank 0 prints
the solution, the iterations and the iteration the monotone mode began as JSON."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_nonsmooth_active_set import CYCLING_A, CYCLING_B, CYCLING_U  # noqa: E402

from nonsmooth import BoundConstrainedQP  # noqa: E402
from nonsmooth.distributed import DistributedQP  # noqa: E402
from nonsmooth.solvers import solve  # noqa: E402

comm = MPI.COMM_WORLD
sol = solve(DistributedQP.from_serial(BoundConstrainedQP(CYCLING_A, CYCLING_B, -np.inf, CYCLING_U), comm), "active_set")
x = np.concatenate(comm.allgather(sol.x))
if comm.rank == 0:
    print(json.dumps({"ranks": comm.size, "x": x.tolist(), "iterations": sol.iterations, "converged": sol.converged,
                      "monotone_from": sol.info["monotone_from"]}))
