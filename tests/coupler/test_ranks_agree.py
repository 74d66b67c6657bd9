"""A failure on one coupler rank reaches every rank (coupler/run/ranks.py, agree): coupler rank 1
failing before its part of an exchange, while rank 0 waits for the coupler's ranks before its own
request, makes both raise rank 1's error (without the vote inside the exchange rank 0 waits in a
barrier and rank 1 in the agreement: the job hangs until the test's timeout). A failure outside
any vote ends the MPI job instead of hanging it (RanksRun.execute)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vc_helpers import ROOT, run_mpi

HERE = Path(__file__).resolve().parent


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_an_error_before_the_exchange_reaches_every_rank():
    outcomes = run_mpi(HERE / "mpi_agree_cases.py", 2, timeout=30)
    assert outcomes == ["CouplerError: participant 'solid': its rank 1 is gone"] * 2


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_a_failure_on_every_rank_is_raised_on_every_rank(tmp_path):
    outcomes = run_mpi(HERE / "mpi_alone_cases.py", 2, "together", tmp_path, timeout=60)
    assert outcomes == ["CouplerError: rank 0 cannot start", "CouplerError: rank 1 cannot start"]


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_a_failure_on_one_rank_alone_aborts_the_job(tmp_path):
    """Rank 1 fails outside any vote while rank 0 waits in an allreduce: after 2 s rank 1 writes
    the summary (status failed, its error) and aborts the job: exit code 4 (failed), no hang."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    start = time.perf_counter()
    proc = subprocess.run([shutil.which("mpirun"), "-n", "2", "--oversubscribe", sys.executable,
                           str(HERE / "mpi_alone_cases.py"), "alone", str(tmp_path)],
                          capture_output=True, text=True, env=env, timeout=120, cwd=ROOT)
    assert proc.returncode == 4, proc.stderr[-2000:]
    assert time.perf_counter() - start < 60
    assert ("varcouple: error: coupler rank 1: rank 1 cannot start; the other coupler ranks went on without it: "
            "the MPI job is aborted") in proc.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and "coupler rank 1: rank 1 cannot start" in summary["error"]
