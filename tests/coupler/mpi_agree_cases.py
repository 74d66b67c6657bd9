"""Run under ``mpirun -n 2`` by test_ranks_agree.py: coupler rank 1 fails before its part of an
exchange (its participant rank is gone) while rank 0 has sent its requests and waits for the
other coupler ranks (``before_root``); every rank must raise rank 1's error instead of waiting.
Rank 0 prints each rank's outcome as JSON."""

from __future__ import annotations

import json

from mpi4py import MPI

from coupler.errors import CouplerError
from coupler.run.ranks import RanksRun, agree

comm = MPI.COMM_WORLD


class Client:
    """A participant client whose rank on coupler rank 1 is gone before the exchange."""

    def wait_alive(self, timeout):
        if comm.rank == 1:
            raise CouplerError("participant 'solid': its rank 1 is gone")

    def exchange(self, verb, header, parts, timeout=None, before_root=None):
        before_root()
        return [f"{verb} reply"]


run = RanksRun.__new__(RanksRun)  # only what _exchange uses
run.comm = comm
try:
    outcome = repr(agree(comm, run._exchange, Client(), "advance", None, [None, None], 1.0))
except CouplerError as exc:
    outcome = f"CouplerError: {exc}"
outcomes = comm.gather(outcome)
if comm.rank == 0:
    print(json.dumps(outcomes))
