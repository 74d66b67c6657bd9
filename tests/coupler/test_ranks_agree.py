"""A failure on one coupler rank reaches every rank (coupler/run/ranks.py, agree): coupler rank 1
failing before its part of an exchange, while rank 0 waits for the coupler's ranks before its own
request, makes both raise rank 1's error (without the vote inside the exchange rank 0 waits in a
barrier and rank 1 in the agreement: the job hangs until the test's timeout)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_an_error_before_the_exchange_reaches_every_rank():
    outcomes = run_mpi(HERE / "mpi_agree_cases.py", 2, timeout=30)
    assert outcomes == ["CouplerError: participant 'solid': its rank 1 is gone"] * 2
