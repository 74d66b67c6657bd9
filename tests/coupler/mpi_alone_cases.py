"""Run under ``mpirun -n 2`` by test_ranks_agree.py: a coupler run whose start fails on rank 1
alone (``alone``: rank 0 waits in a collective call for it) or on both ranks (``together``).
Alone, rank 1 must abort the MPI job within RanksRun.alone_seconds (here 2 s) and write the
summary; together, both ranks raise and rank 0 prints each rank's outcome as JSON."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from mpi4py import MPI

from coupler.errors import CouplerError
from coupler.run.ranks import RanksRun

comm = MPI.COMM_WORLD
case, out = sys.argv[1], Path(sys.argv[2])


def start():
    if case == "together" or comm.rank == 1:
        raise CouplerError(f"rank {comm.rank} cannot start")
    comm.allreduce(1)  # rank 0, alone: waits for rank 1 here for ever


run = RanksRun.__new__(RanksRun)  # only what execute's failure path uses
run.comm, run.root, run.failures, run.alone_seconds = comm, comm.rank == 0, comm.Dup(), 2.0
run.out, run.summary, run.start = out, {"status": "running"}, start
try:
    run.execute(progress=False)
    outcome = "completed"
except CouplerError as exc:
    outcome = f"CouplerError: {exc}"
outcomes = comm.gather(outcome)
if comm.rank == 0:
    print(json.dumps(outcomes))
