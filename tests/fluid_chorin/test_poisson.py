"""The pressure Poisson solver's choice (fluid_chorin/poisson.py): ``auto`` factorizes small grids
and anisotropic ones (a fracture's cells, far thinner across the aperture than along it), where
CG + GAMG needs its weak-coupling threshold to converge; bench/poisson.py measures the costs."""

from __future__ import annotations

import numpy as np
import pytest

import fluid_chorin.poisson
from fluid_chorin.solver import ChorinSolver
from fluid_chorin.spec import ChorinSpec


def solver(shape, aspect: float = 1.0, poisson: str = "auto", blocks: bool = False) -> ChorinSolver:
    """Pressure-driven flow along x on a grid of cells aspect times longer than high, with two
    penalized blocks around a wavy gap (a fracture's coefficients) when `blocks`."""
    h = 1.0 / shape[0]
    s = ChorinSolver(ChorinSpec.from_config({
        "grid": {"origin": [0, 0, 0], "spacing": [h, h, h / aspect], "shape": list(shape)},
        "inlet": {"pressure": 1.0}, "outlet": {"pressure": 0.0}, "walls": "wall", "rho": 1000.0, "mu": 1e-3,
        "poisson": poisson}))
    if blocks:
        x, y, z = np.meshgrid(*[(np.arange(n) + 0.5) / n for n in shape], indexing="ij")
        gap = np.abs(z - 0.5 - 0.08 * np.sin(6 * np.pi * x) * np.cos(4 * np.pi * y)) <= 0.17
        s.set_solid(np.where(gap, 0.0, 1.0).transpose(2, 1, 0).ravel())
    return s


def method(s: ChorinSolver) -> str:
    return s.poisson(s.stable_dt(s.state)).method


def test_auto_factorizes_anisotropic_cells_on_larger_grids(monkeypatch):
    monkeypatch.setattr(fluid_chorin.poisson, "DIRECT_CELLS", 100)
    monkeypatch.setattr(fluid_chorin.poisson, "DIRECT_CELLS_ANISOTROPIC", 1000)
    assert method(solver((12, 12, 6))) == "gamg"            # 864 isotropic cells: beyond 100
    assert method(solver((12, 12, 6), aspect=10)) == "direct"  # 10:1, within 1000
    assert method(solver((12, 12, 6), aspect=9)) == "gamg"
    assert method(solver((12, 12, 8), aspect=10)) == "gamg"    # 1152 cells: beyond 1000 too
    assert method(solver((4, 4, 4))) == "direct"


@pytest.mark.parametrize("threshold,converges", [(fluid_chorin.poisson.GAMG_THRESHOLD, True), (-1.0, False)])
def test_gamg_converges_on_a_fracture_grid_with_its_threshold(monkeypatch, threshold, converges):
    """CG + GAMG on 125:1 cells around penalized blocks: a few tens of iterations with the
    threshold; without it (PETSc's default) not in 100."""
    monkeypatch.setattr(fluid_chorin.poisson, "GAMG_THRESHOLD", threshold)
    s = solver((12, 12, 24), aspect=125, poisson="gamg", blocks=True)
    P = s.poisson(s.stable_dt(s.state))
    P.ksp.setTolerances(max_it=100)
    rhs = np.random.default_rng(0).standard_normal(s.state.p.shape)
    _, report = P.solve(rhs)
    assert report.converged == converges
    if converges:
        assert report.iterations <= 40 and report.residual <= 1e-10
