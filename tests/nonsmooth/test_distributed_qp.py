"""The active set method on a DistributedQP (nonsmooth.distributed): on the QP where plain
PDAS cycles, rows split over 1, 2 and 3 ranks, the same iterates as the serial solver (the
same solution, iteration count and start of the monotone mode: the cycle and the monotone
mode's worst half decided over all ranks); the distributed problem's own checks."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from mpi4py import MPI

from nonsmooth import BoundConstrainedQP
from nonsmooth.distributed import DistributedQP
from nonsmooth.solvers import solve
from test_nonsmooth_active_set import CYCLING_A, CYCLING_B, CYCLING_U
from vc_helpers import ROOT, run_mpi


def serial():
    return solve(BoundConstrainedQP(CYCLING_A, CYCLING_B, -np.inf, CYCLING_U), "active_set")


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="already running under MPI")
@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_cycling_qp_on_ranks_equals_serial(ranks):
    reference = serial()
    assert reference.info["monotone_from"] is not None
    r = run_mpi(ROOT / "tests" / "nonsmooth" / "mpi_qp_cases.py", ranks)
    assert r["ranks"] == ranks and r["converged"]
    assert np.abs(np.array(r["x"]) - reference.x).max() <= 1e-12
    assert (r["iterations"], r["monotone_from"]) == (reference.iterations, reference.info["monotone_from"])


def test_distributed_problem_checks_its_bounds():
    qp = DistributedQP.from_serial(BoundConstrainedQP(CYCLING_A, CYCLING_B, -np.inf, CYCLING_U), MPI.COMM_SELF)
    assert qp.size == 5 and qp.kkt_residual(serial().x) <= 1e-12
    with pytest.raises(ValueError, match="empty feasible set: lower > upper at 5 components"):
        DistributedQP(qp.A, qp.b, 1.0, 0.0)
