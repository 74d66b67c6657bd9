"""The solid participant (solid_fenicsx/participant.py) in process: every inner solve
reported to the coupler (converged or not, iterations, residual against tolerance), and
loads on boundaries that select no facet refused at configure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from coupler.coupled_run import participant_config  # noqa: E402
from coupler.scene import load  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BLOCK = ROOT / "cases" / "block_compression"


def participant(config):
    from solid_fenicsx.participant import SolidParticipant

    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p


def block_config(**changes) -> dict:
    """The solid's config of cases/block_compression with `changes`."""
    return {**participant_config(load(BLOCK), "solid"), **changes}


def advance(p, window=0, dt=1.0):
    """One advance: (outputs, solve reports, figures)."""
    out = p.advance(window, 0, window * dt, dt, {})
    solves, figures = p.take_reports()
    return out, solves, figures


def test_a_capped_krylov_solve_is_reported_unconverged():
    p = participant(block_config(linear_solver="cg", rtol=1e-20, max_iterations=3))
    out, (report,), _ = advance(p)
    assert (report.solver, report.converged, report.iterations, report.detail) == (
        "CG+GAMG static", False, 3, "DIVERGED_MAX_IT")
    assert report.tolerance == 1e-20 and 1e-20 < report.residual < 1.0
    assert np.all(np.isfinite(out["displacement"].data))


@pytest.mark.parametrize("solver, name, iterations", [("cg", "CG+GAMG static", None), ("lu", "LU static", 1)])
def test_a_normal_solve_is_reported_converged(solver, name, iterations):
    _, (report,), _ = advance(participant(block_config(linear_solver=solver, rtol=1e-10)))
    assert report.solver == name and report.converged and report.residual <= report.tolerance == 1e-10
    assert report.iterations == iterations if iterations else report.iterations > 1


def test_a_time_step_reports_the_initial_acceleration_and_the_step():
    p = participant(block_config(linear_solver="cg", rtol=1e-10, dynamic=True))
    _, first, _ = advance(p, 0, dt=1e-4)
    assert [r.solver for r in first] == ["CG+JACOBI initial acceleration", "CG+GAMG time step"]
    _, second, _ = advance(p, 1, dt=1e-4)
    assert [r.solver for r in second] == ["CG+GAMG time step"]
    assert all(r.converged and r.residual <= r.tolerance for r in first + second)
