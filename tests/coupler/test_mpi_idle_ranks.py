"""A participant on several MPI ranks: the ranks other than 0 sleep while they wait for rank
0's next verb (coupler/protocol/participant.py, idle_barrier) instead of spinning in the
broadcast, so they leave the cores to the other participants' solvers; and they still get
every verb with its arguments."""

from __future__ import annotations

import shutil

import pytest

from vc_helpers import run_mpi

SCRIPT = '''
import json, sys, time
from mpi4py import MPI
from coupler.protocol.participant import _MpiRoot, _mpi_worker

class Recorder:
    def __init__(self):
        self.calls = []
    def configure(self, config):
        self.calls.append(config)
    def take_reports(self):
        return []

comm, idle = MPI.COMM_WORLD, float(sys.argv[1])
handler = Recorder()
cpu, wall = time.process_time(), time.perf_counter()
if comm.rank == 0:
    root = _MpiRoot(handler, comm)
    time.sleep(idle)  # the coupler busy elsewhere: the other ranks wait for the next verb
    root.configure({"E": 1.0})
    time.sleep(idle)
    root.configure({"E": 2.0})
    root.stop()
else:
    _mpi_worker(handler, comm, None)  # configure only: no parts
found = comm.gather({"cpu": time.process_time() - cpu, "wall": time.perf_counter() - wall, "calls": handler.calls})
if comm.rank == 0:
    print(json.dumps(found))
'''


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_waiting_ranks_sleep_and_get_every_verb(tmp_path):
    script = tmp_path / "idle.py"
    script.write_text(SCRIPT)
    ranks = run_mpi(script, 2, 1.5)
    worker = ranks[1]
    assert worker["calls"] == [{"E": 1.0}, {"E": 2.0}]
    assert worker["wall"] > 2.9
    # spinning in MPI_Bcast took a whole core: about 3 s of CPU in these 3 s (less on a loaded machine)
    assert worker["cpu"] < 0.3, worker
