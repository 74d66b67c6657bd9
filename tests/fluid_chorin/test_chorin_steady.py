"""The steady flow solved as steady (fluid_chorin/steady.py: Newton on the steady equations of
the MAC grid) against the pseudo-time march's steady state, on small grids: the same fields to
the march's tolerance, with immersed solids, a moving solid, a velocity inlet, a lid and
convection; a limit on the Newton steps is reported as not converged."""

from __future__ import annotations

import re

import numpy as np
import pytest

from fluid_chorin.solver import ChorinSolver
from fluid_chorin.spec import ChorinSpec
from fluid_chorin.steady import SteadyNewton

CHANNEL = {"grid": {"origin": [0, 0, 0], "spacing": [0.1, 0.05, 0.04], "shape": [10, 6, 5]},
           "inlet": {"velocity": [0.05, 0.01, 0.0]}, "outlet": {"pressure": 3.0}, "walls": "wall", "rho": 1000.0,
           "mu": 1.0, "tolerance": 1e-10}
CAVITY = {"grid": {"origin": [0, 0, 0], "spacing": [1 / 16] * 3, "shape": [16, 16, 1]}, "inlet": "wall",
          "outlet": "wall", "walls": "wall", "rho": 1.0, "mu": 0.01, "tolerance": 1e-9,
          "boundaries": {"zmin": "empty", "zmax": "empty", "ymax": {"velocity": [1.0, 0.0, 0.0]}}}


def solid(shape, seed=1):
    """Random solid fractions (about 40 % of the cells fluid, some partly solid) and velocities."""
    rng = np.random.default_rng(seed)
    n = int(np.prod(shape))
    return np.clip(rng.random(n) * 1.6 - 0.6, 0.0, 1.0), rng.normal(size=(n, 3)) * 0.01


def steady(config, method, inputs=None):
    solver = ChorinSolver(ChorinSpec.from_config({**config, "steady": method}))
    if inputs is not None:
        solver.set_solid(*inputs)
    run = solver.steady()
    assert run.converged, run.report
    return solver


def assert_same(march, newton, tolerance):
    for a, b in zip(march.state.q, newton.state.q):
        assert np.abs(a - b).max() <= tolerance * max(np.abs(a).max(), 1e-300)
    assert np.abs(march.state.p - newton.state.p).max() <= tolerance * np.abs(march.state.p).max()


@pytest.mark.parametrize("config,inputs,cfl", [(CHANNEL, solid([10, 6, 5]), 0.5), (CHANNEL, solid([10, 6, 5]), 0.02),
                                               (CAVITY, None, 0.5)])
def test_newton_gives_the_march_s_steady_state(config, inputs, cfl):
    """A channel with a velocity inlet (tangential too), an outlet pressure and random moving solid
    cells (Courant-limited march at cfl 0.02: the open face's relaxation then differs from the
    viscous step's), and the lid-driven cavity at Re 100 (convection: 8 Newton steps): the
    fields within 1000 times the march's tolerance of its steady state (measured 1e-9 to 1e-7)."""
    march = steady({**config, "cfl": cfl}, "march", inputs)
    newton = steady(config, "newton", inputs)
    assert_same(march, newton, 1000 * config["tolerance"])


def test_the_jacobian_is_the_derivative_of_the_steady_equations():
    """The coloured probes' Jacobian against column-by-column central differences of the residual
    at a random state (velocity inlet, open outlet, moving solid)."""
    config = {**CHANNEL, "grid": {**CHANNEL["grid"], "shape": [5, 4, 3]}}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    solver.set_solid(*solid([5, 4, 3]))
    newton = SteadyNewton(solver)
    base = [a.copy() for a in solver.state.q]
    solver.grid.set_normal(base)
    x = np.random.default_rng(2).normal(size=newton.nq + newton.ncell) * 0.01
    J = newton.jacobian(x, base).toarray()
    e, n = 1e-6, x.size
    probe = np.zeros((n, n))
    for j in range(n):
        d = np.zeros(n)
        d[j] = e
        probe[:, j] = (newton.residual(x + d, base, 0.0) - newton.residual(x - d, base, 0.0)) / (2 * e)
    assert np.abs(J - probe).max() < 1e-9 * np.abs(probe).max()


def test_a_newton_step_limit_is_reported_not_converged():
    solver = ChorinSolver(ChorinSpec.from_config({**CAVITY, "steady": "newton", "newton_iterations": 2}))
    run = solver.steady()
    assert not run.converged and run.report.iterations == 2 and run.report.residual > CAVITY["tolerance"]
    assert "limit of 2 Newton steps reached" in run.report.detail


def test_a_jacobian_is_factorized_once_and_an_unsolved_system_is_not_converged(monkeypatch):
    """The preconditioner is built at most once per Jacobian (scipy's GMRES ``info`` once called
    solves failed whose true residual met the tolerance, and the same Jacobian was factorized
    again); a linear solve that misses its tolerance even with its own Jacobian's preconditioner
    (the Schur complement by LU) leaves the solve not converged, however small the step it gave
    (before: taken, and a tiny step reported as converged)."""
    from fluid_chorin import steady as module

    run = ChorinSolver(ChorinSpec.from_config({**CAVITY, "steady": "newton"})).steady()
    jacobians, factorizations = (int(w) for w in re.findall(r"(\d+) (?:Jacobians|preconditioners)", run.report.detail))
    assert run.converged and 1 <= factorizations <= jacobians, run.report.detail

    solve = module.Block.solve
    monkeypatch.setattr(module.Block, "solve", lambda self, b, rtol, atol: (*solve(self, b, rtol, atol)[:2], False))
    run = ChorinSolver(ChorinSpec.from_config({**CAVITY, "steady": "newton", "newton_iterations": 30})).steady()
    assert not run.converged and ("its last linear solve missed" in run.report.detail
                                  or "limit of 30 Newton steps reached" in run.report.detail)


def test_newton_refuses_several_ranks():
    solver = ChorinSolver.__new__(ChorinSolver)
    solver.slabs = type("S", (), {"size": 2})()
    with pytest.raises(ValueError, match="steady = 'newton' needs the fluid on one rank, got ranks = 2"):
        SteadyNewton(solver)


def duct(n: int, multigrid: bool) -> str:
    """Newton's report on a duct 0.1 mm high between walls, ``n`` cells across it (cells
    ``320 / n * 32`` times longer than high), its Schur complement by multigrid or by LU."""
    config = {"grid": {"origin": [0, 0, 0], "spacing": [1e-3, 1e-3, 1e-4 / n], "shape": [6, 4, n]},
              "inlet": {"pressure": 10.0}, "outlet": {"pressure": 0.0}, "walls": "wall", "rho": 1000.0,
              "mu": 1e-3, "tolerance": 1e-9, "steady": "newton"}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    solver._newton = SteadyNewton(solver)
    solver._newton.multigrid = multigrid
    run = solver.steady()
    assert run.converged, run.report
    return run.report.detail


def test_a_thin_gap_s_linear_solves_do_not_grow_with_the_cells_across():
    """GMRES takes at most 30 iterations per solve at 8 and at 32 cells across a duct (measured 15
    and 18) with the lines' lumped inverse in the Schur complement (a column's Poiseuille
    conductance) factorized; SIMPLE's ``diag(A)^-1`` in its place takes 23 and 264."""
    for n in (8, 32):
        detail = duct(n, multigrid=False)
        assert int(re.search(r"(\d+) GMRES iterations", detail).group(1)) <= 30, (n, detail)


def test_a_schur_complement_multigrid_misses_is_factorized_from_then_on():
    """At 8 cells across one V-cycle on the Schur complement serves (33 GMRES iterations); at 32
    it misses half of KRYLOV iterations and the solve goes on with its LU (78 in all)."""
    assert "1 preconditioners (Schur complement by multigrid)" in duct(8, multigrid=True)
    assert "2 preconditioners (Schur complement by LU)" in duct(32, multigrid=True)
