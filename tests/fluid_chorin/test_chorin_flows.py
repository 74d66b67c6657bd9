"""The Chorin fluid (fluid_chorin) against known flows: the lid-driven cavity of Ghia, Ghia &
Shin (1982), the Taylor-Green vortex, immersed parallel plates (the cubic law, as the
OpenFOAM fluid), and a rotating immersed cylinder whose per-cell velocity drives the fluid
(circular Couette flow)."""

from __future__ import annotations

import numpy as np
import pytest

from coupler.protocol.slabs import slab_bounds
from coupler.checks.cubic_law import flow_rates
from fluid_chorin.solver import ChorinSolver
from fluid_chorin.spec import ChorinSpec
from transfer import FunctionSpace, StructuredGrid, Transfer
from transfer.generators import GENERATORS, parameters

# Ghia, U., Ghia, K. N., Shin, C. T. (1982). High-Re solutions for incompressible flow using
# the Navier-Stokes equations and a multigrid method. J. Comput. Phys. 48, 387-411.
# Table I: u along the vertical line through the cavity's centre (x = 0.5), lid at y = 1 moving
# with u = 1; Table II: v along the horizontal line through the centre (y = 0.5).
GHIA_Y = [1.0, 0.9766, 0.9688, 0.9609, 0.9531, 0.8516, 0.7344, 0.6172, 0.5, 0.4531, 0.2813, 0.1719, 0.1016,
          0.0703, 0.0625, 0.0547, 0.0]
GHIA_U = {100: [1.0, 0.84123, 0.78871, 0.73722, 0.68717, 0.23151, 0.00332, -0.13641, -0.20581, -0.21090, -0.15662,
                -0.10150, -0.06434, -0.04775, -0.04192, -0.03717, 0.0],
          400: [1.0, 0.75837, 0.68439, 0.61756, 0.55892, 0.29093, 0.16256, 0.02135, -0.11477, -0.17119, -0.32726,
                -0.24299, -0.14612, -0.10338, -0.09266, -0.08186, 0.0]}
GHIA_X = [1.0, 0.9688, 0.9609, 0.9531, 0.9453, 0.9063, 0.8594, 0.8047, 0.5, 0.2344, 0.2266, 0.1563, 0.0938, 0.0781,
          0.0703, 0.0625, 0.0]
GHIA_V = {100: [0.0, -0.05906, -0.07391, -0.08864, -0.10313, -0.16914, -0.22445, -0.24533, 0.05454, 0.17527,
                0.17507, 0.16077, 0.12317, 0.10890, 0.10091, 0.09233, 0.0],
          400: [0.0, -0.12146, -0.15663, -0.19254, -0.22847, -0.23827, -0.44993, -0.38598, 0.05186, 0.30174, 0.30203,
                0.28124, 0.22965, 0.20920, 0.19713, 0.18360, 0.0]}
#: Table II at Re 400, x = 0.9063: -0.23827 breaks the profile between -0.22847 (x = 0.9453) and
#: -0.44993 (x = 0.8594); every other entry is matched here within 0.01 and this one is -0.38: a
#: misprint in the table, left out
MISPRINT = {400: [GHIA_X.index(0.9063)], 100: []}


def cavity(n: int, re: float) -> ChorinSolver:
    """The unit cavity at Reynolds number ``re`` (lid speed 1, nu = 1/re) on n x n cells, solved
    to steady state by pseudo-time stepping."""
    config = {"grid": {"origin": [0, 0, 0], "spacing": [1 / n] * 3, "shape": [n, n, 1]}, "inlet": "wall",
              "outlet": "wall", "walls": "wall", "rho": 1.0, "mu": 1.0 / re, "tolerance": 1e-6,
              "boundaries": {"zmin": "empty", "zmax": "empty", "ymax": {"velocity": [1.0, 0.0, 0.0]}}}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    run = solver.steady()
    assert run.converged and run.report.residual < 1e-6, run
    assert all(p.converged for p in run.poisson)
    return solver


def centrelines(solver: ChorinSolver, n: int):
    """u(y) on x = 1/2 and v(x) on y = 1/2 (MAC faces on those lines, n even), walls included."""
    u = solver.state.q[0][0][:, n // 2]
    v = solver.state.q[1][0][n // 2, :]
    centres = (np.arange(n) + 0.5) / n
    at = np.concatenate([[0.0], centres, [1.0]])
    return (lambda y: np.interp(y, at, np.concatenate([[0.0], u, [1.0]])),
            lambda x: np.interp(x, at, np.concatenate([[0.0], v, [0.0]])))


@pytest.mark.parametrize("re", [100, 400])
def test_lid_driven_cavity_matches_ghia_within_two_percent(re):
    """64 x 64 cells, steady to 1e-6: every tabulated centreline velocity within 2 % of the lid
    speed (measured: Re 100 0.4 % in u, 0.8 % in v; Re 400 0.8 % and 0.8 %; 3 and 10 s)."""
    n = 64
    u_of_y, v_of_x = centrelines(cavity(n, re), n)
    du = np.abs(u_of_y(GHIA_Y) - GHIA_U[re])
    dv = np.delete(np.abs(v_of_x(GHIA_X) - GHIA_V[re]), MISPRINT[re])
    assert du.max() < 0.02 and dv.max() < 0.02, (du.max(), dv.max())
    assert du.max() < 0.01  # and the vertical profile to 1 %
    if re == 400:  # the left-out entry is far off: the solution is not near it
        assert abs(v_of_x([0.9063])[0] - GHIA_V[400][MISPRINT[400][0]]) > 0.1


def test_taylor_green_vortex_decays_at_the_exact_rate_on_32_cubed():
    """u = sin x cos z, w = -cos x sin z on [0, pi]^3 with symmetry faces (an exact solution of
    the Navier-Stokes equations, its convection balanced by the pressure): the kinetic energy
    decays as exp(-4 nu t). 32^3 cells, to t = 0.2: the decay rate within 1 % (measured 0.1 %)."""
    n, nu, T = 32, 0.05, 0.2
    h = np.pi / n
    config = {"grid": {"origin": [0, 0, 0], "spacing": [h] * 3, "shape": [n] * 3}, "inlet": "symmetry",
              "outlet": "symmetry", "walls": "symmetry", "rho": 1.0, "mu": nu, "transient": True, "dt": T,
              "tolerance": 1e-10}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    faces, centres = np.arange(n + 1) * h, (np.arange(n) + 0.5) * h
    q = solver.state.q
    q[0][:] = np.sin(faces)[None, None, :] * np.cos(centres)[:, None, None]
    q[2][:] = -np.cos(centres)[None, None, :] * np.sin(faces)[:, None, None]

    def energy():
        return 0.5 * sum(float(np.sum(a * a)) for a in solver.state.q) * h ** 3

    e0 = energy()
    run = solver.transient(0.0, T)
    assert run.converged and solver.state.t == pytest.approx(T)
    rate = -np.log(energy() / e0) / T
    assert rate == pytest.approx(4 * nu, rel=0.01)
    assert np.abs(solver.state.q[1]).max() < 1e-12  # no flow out of the vortex's plane


@pytest.mark.parametrize("steady", ["march", "newton"])
@pytest.mark.parametrize("n_across,offset,low,high", [(8, 0.3, 0.0, 0.05), (8, 0.0, 0.025, 0.04),
                                                      (4, 0.3, 0.05, 0.065)])
def test_immersed_plates_follow_the_cubic_law(n_across, offset, low, high, steady):
    """The geometry of cases/parallel_plates (the plates generator: exact fractions of two
    tetrahedral blocks, grid lines off the walls; w = 1 mm, L = 2 mm, dp = 0.01 Pa, mu = 1e-3 Pa s),
    the 'wall' penalization: 8 cells across within 5 % of Q = w^3 dp / (12 mu L) (measured +1.44 % at
    offset 0.3, +3.13 % = 2 (h/w)^2 with the walls on grid faces, as real walls; 4 across +5.77 %:
    the OpenFOAM fluid's figures to three digits), by the march and by Newton on the steady equations."""
    w, length, dp, mu = 1e-3, 2e-3, 1e-2, 1e-3
    p = parameters("plates", {"aperture": w, "length": length, "cells_across": n_across, "offset": offset})
    grid = GENERATORS["plates"].grid(p)
    G = StructuredGrid(grid["origin"], grid["spacing"], grid["shape"])
    volumes = Transfer.assemble(FunctionSpace(GENERATORS["plates"].mesh(p).mesh, "P0"), FunctionSpace(G, "Q0"), "l2").D
    config = {"grid": grid, "inlet": {"pressure": dp}, "outlet": {"pressure": 0.0}, "rho": 1000.0, "mu": mu,
              "boundaries": {"zmin": "empty", "zmax": "empty"}, "tolerance": 1e-9, "steady": steady}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    solver.set_solid(np.asarray(volumes.diagonal()) / G.cell_measures())
    assert solver.steady().converged
    Q = flow_rates(G, solver.cell_velocity(), across=1)
    assert np.ptp(Q) < 1e-9 * Q.mean()  # the same flow rate through every column
    assert low < Q.mean() / (w ** 3 * dp / (12 * mu * length)) - 1 < high


@pytest.mark.parametrize("n_across,offset", [(3, 0.1), (3, 0.45), (4, 0.3), (4, 0.85), (8, 0.3)])
def test_lubrication_penalization_gives_plates_the_cubic_law_at_any_resolution(n_across, offset):
    """The plates of the test above with penalization "lubrication": Q = w^3 dp / (12 mu L) to 5e-4
    at 3, 4 and 8 cells across and any offset of the walls to the grid (measured 0.5e-4 to 3.7e-4:
    the solid cells' leak at the finite drag D_max; the drag itself is exact to round-off,
    tests/fluid_openfoam/test_fluid_penalization.py); the "wall" penalization errs by more than
    1 % on each of these grids (-4.7 % to +21 %)."""
    w, length, dp, mu = 1e-3, 2e-3, 1e-2, 1e-3
    p = parameters("plates", {"aperture": w, "length": length, "cells_across": n_across, "offset": offset})
    grid = GENERATORS["plates"].grid(p)
    G = StructuredGrid(grid["origin"], grid["spacing"], grid["shape"])
    volumes = Transfer.assemble(FunctionSpace(GENERATORS["plates"].mesh(p).mesh, "P0"), FunctionSpace(G, "Q0"), "l2").D
    error = {}
    for mode in ("lubrication", "wall"):
        config = {"grid": grid, "inlet": {"pressure": dp}, "outlet": {"pressure": 0.0}, "rho": 1000.0, "mu": mu,
                  "boundaries": {"zmin": "empty", "zmax": "empty"}, "tolerance": 1e-9, "steady": "newton",
                  "penalization": mode}
        solver = ChorinSolver(ChorinSpec.from_config(config))
        solver.set_solid(np.asarray(volumes.diagonal()) / G.cell_measures())
        assert solver.steady().converged
        Q = flow_rates(G, solver.cell_velocity(), across=1)
        error[mode] = Q.mean() / (w ** 3 * dp / (12 * mu * length)) - 1
    assert abs(error["lubrication"]) < 5e-4
    assert abs(error["wall"]) > 0.01


def test_lubrication_penalization_refuses_slabs_that_cut_the_lines_across_the_gap():
    """The drag of penalization "lubrication" reads whole lines across the gap: the slab cut that
    the solver's slabs and the scene check share (coupler.protocol.slabs) refuses slabs along that
    axis on two ranks, naming the axis and the setting to change; one rank, or slabs in the gap's
    plane, are cut."""
    with pytest.raises(ValueError, match=r"whole lines of cells along y \(across the gap\), the slabs along y "
                                         r"of 2 ranks would cut them: set slab_axis"):
        slab_bounds((8, 16, 1), 2, "y", whole=1)
    assert slab_bounds((8, 16, 1), 1, "y", whole=1) == (1, [0, 16])
    assert slab_bounds((8, 16, 1), 2, "x", whole=1) == (0, [0, 4, 8])


def couette(n: int, omega: float):
    """A cylinder of radius R1 = 0.3 rotating at ``omega`` inside a fixed ring r > R2 = 0.8, both
    immersed in a 2D grid of n x n cells over [-1, 1]^2 (slip box faces), nu = 0.1; fractions and
    per-cell solid velocities (the mean of omega x r over each cell's overlap with the cylinder)
    from 16 x 16 samples per cell. Returns (radius, u_theta, exact u_theta, fraction) per cell."""
    R1, R2, h = 0.3, 0.8, 2.0 / n
    config = {"grid": {"origin": [-1, -1, 0], "spacing": [h] * 3, "shape": [n, n, 1]}, "inlet": "slip",
              "outlet": "slip", "walls": "slip", "boundaries": {"zmin": "empty", "zmax": "empty"}, "rho": 1.0,
              "mu": 0.1, "tolerance": 1e-8}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    m = 16
    corner = -1 + np.arange(n) * h
    sub = (np.arange(m) + 0.5) / m * h
    X = corner[None, :, None, None] + sub[None, None, None, :] + np.zeros((n, n, m, m))
    Y = corner[:, None, None, None] + sub[None, None, :, None] + np.zeros((n, n, m, m))
    r = np.hypot(X, Y)
    inner = r < R1
    fraction = (inner | (r > R2)).mean(axis=(2, 3)).ravel()
    count = np.maximum(inner.sum(axis=(2, 3)), 1)
    velocity = np.zeros((n * n, 3))
    velocity[:, 0] = (np.where(inner, -omega * Y, 0.0).sum(axis=(2, 3)) / count).ravel()
    velocity[:, 1] = (np.where(inner, omega * X, 0.0).sum(axis=(2, 3)) / count).ravel()
    solver.set_solid(fraction, velocity)
    assert solver.steady().converged
    centre = -1 + (np.arange(n) + 0.5) * h
    cx, cy = (a.ravel() for a in np.meshgrid(centre, centre))
    radius = np.hypot(cx, cy)
    U = solver.cell_velocity()
    u_theta = (-cy * U[:, 0] + cx * U[:, 1]) / radius
    a, b = -omega * R1 ** 2 / (R2 ** 2 - R1 ** 2), omega * R1 ** 2 * R2 ** 2 / (R2 ** 2 - R1 ** 2)
    return radius, u_theta, a * radius + b / radius, fraction, U


def test_a_rotating_immersed_cylinder_drags_the_fluid_with_its_wall():
    """Circular Couette flow driven by the per-cell solid velocity (which the OpenFOAM fluid cannot
    apply: it moves each body rigidly with one velocity): the fluid cells next to the rotating wall
    move at 0.92 of the wall's speed on average (exact there 0.94), and u_theta(r) = A r + B / r in
    the gap within 5 % of the wall speed (measured 4.2 % at worst, 0.9 % on average, 64^2 cells)."""
    n, omega, R1, h = 64, 1.0, 0.3, 2.0 / 64
    radius, u_theta, exact, fraction, _ = couette(n, omega)
    wall = omega * R1
    gap = (radius > R1 + h) & (radius < 0.8 - h)
    assert np.abs(u_theta - exact)[gap].max() < 0.05 * wall
    assert np.abs(u_theta - exact)[gap].mean() < 0.015 * wall
    next_to_wall = (radius > R1) & (radius < R1 + h) & (fraction < 0.5)
    assert next_to_wall.sum() > 20
    assert u_theta[next_to_wall].mean() > 0.9 * wall
    assert abs(u_theta[next_to_wall].mean() - exact[next_to_wall].mean()) < 0.05 * wall


def test_a_cylinder_at_rest_leaves_the_fluid_at_rest():
    _, _, _, _, U = couette(16, 0.0)
    assert np.abs(U).max() == 0.0


def test_a_long_steady_solve_logs_its_progress(monkeypatch, caplog):
    """A steady solve longer than PROGRESS_SECONDS says where it is (step, residual, dt) in the
    participant's log; the last line's residual is above the tolerance (it was not done yet)."""
    import fluid_chorin.solver

    monkeypatch.setattr(fluid_chorin.solver, "PROGRESS_SECONDS", 0.0)
    with caplog.at_level("INFO", logger="varcouple.fluid_chorin"):
        cavity(8, 100)
    lines = [r.getMessage() for r in caplog.records if "pseudo-time step" in r.getMessage()]
    assert len(lines) > 10 and "of at most 20000: residual" in lines[-1] and "tolerance 1e-06" in lines[-1]
    assert float(lines[-1].split("residual ")[1].split()[0]) >= 1e-6
