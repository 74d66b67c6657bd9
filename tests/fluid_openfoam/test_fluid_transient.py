"""The transient OpenFOAM fluid (pimpleFoam over one coupling step, restarted from the step's
start) and the solid velocity applied per solid body (fluid_openfoam/zones.py), against
analytical solutions of a body moved impulsively in an incompressible fluid: the fluid's
pressure is the added mass of the moving wall."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from fluid_openfoam.case import CaseSpec
from fluid_openfoam.solver import OpenFOAMError, OpenFOAMSolver
from fluid_openfoam.zones import body_sources

needs_foam = pytest.mark.skipif(shutil.which("pimpleFoam") is None, reason="OpenFOAM (pimpleFoam) not installed")
RHO, DT = 1000.0, 1.0e-2


def transient(tmp_path, shape, spacing, boundaries, **extra) -> OpenFOAMSolver:
    cfg = {"grid": {"origin": [0.0, 0.0, 0.0], "spacing": spacing, "shape": shape},
           "inlet": {"pressure": 0.0}, "outlet": {"pressure": 0.0}, "walls": "slip", "boundaries": boundaries,
           "rho": RHO, "mu": 1.0e-3, "transient": True, "dt": DT, "tolerance": 1e-10, **extra}
    solver = OpenFOAMSolver(tmp_path / "case", CaseSpec.from_config(cfg))
    solver.setup()
    return solver


# ------------------------------------------------------------------------------ fast
def test_one_source_per_body_with_the_mean_velocity_of_its_wetted_layer():
    nx, ny, nz = 6, 1, 7
    f = np.zeros((nz, ny, nx))
    f[:2] = 1.0          # lower body: two layers
    f[2] = 0.6           # ... and a partly filled wetted layer (solid-centred)
    f[5:] = 1.0          # upper body
    v = np.zeros((nz, ny, nx, 3))
    v[:2, ..., 2] = 5.0  # inside the lower body: not its wall's velocity
    v[2, ..., 2] = np.linspace(1.0, 2.0, nx)
    v[5:, ..., 0] = -3.0
    src = body_sources(f.ravel(), v.reshape(-1, 3), (nx, ny, nz), d_max=10.0)
    assert [s.name for s in src] == ["solidBody0", "solidBody1"]
    lower, upper = src
    assert lower.cells.tolist() == list(range(3 * nx))
    assert lower.velocity == pytest.approx([0.0, 0.0, 1.5])  # the wetted layer (k = 2), not the interior
    assert lower.su == pytest.approx(10.0 * lower.velocity)
    assert upper.velocity == pytest.approx([-3.0, 0.0, 0.0])
    # a body at rest gets no source (quasi-static solids leave the case as it was)
    assert body_sources(f.ravel(), np.zeros((f.size, 3)), (nx, ny, nz), 10.0) == []


def test_a_body_slides_along_a_closed_grid_face_and_moves_through_an_open_one():
    """A body on the grid's zmin face moving up and sideways: through a closed face (wall, slip,
    symmetry, inlet) incompressibility forbids the normal motion, so only the tangential part
    is imposed, and the dropped part reported; through an open (pressure) face it moves."""
    nx, ny, nz = 4, 3, 5
    f = np.zeros((nz, ny, nx))
    f[:2] = 1.0
    v = np.zeros((nz, ny, nx, 3))
    v[:2] = [0.5, 0.0, 2.0]
    (src,) = body_sources(f.ravel(), v.reshape(-1, 3), (nx, ny, nz), 1.0, closed=["zmin", "zmax"])
    assert src.velocity == pytest.approx([0.5, 0.0, 0.0]) and src.dropped == {"zmin": 2.0}
    assert src.su == pytest.approx([0.5, 0.0, 0.0])
    (src,) = body_sources(f.ravel(), v.reshape(-1, 3), (nx, ny, nz), 1.0, closed=["zmax", "ymin", "ymax"])
    assert src.velocity == pytest.approx([0.5, 0.0, 2.0]) and src.dropped == {}
    # closed on every side it touches: held at rest (a zero source), the drop reported
    (src,) = body_sources(f.ravel(), v.reshape(-1, 3), (nx, ny, nz), 1.0, closed=["xmin", "zmin"])
    assert not src.su.any() and src.dropped == {"xmin": 0.5, "zmin": 2.0}


def test_transient_keys_are_checked():
    grid = {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [2, 2, 2]}
    with pytest.raises(ValueError, match="solid_velocity: unknown value 'cells'; use one of 'bodies', 'none'"):
        CaseSpec.from_config({"grid": grid, "solid_velocity": "cells"})
    with pytest.raises(ValueError, match="substeps: must be an integer >= 1, got 0"):
        CaseSpec.from_config({"grid": grid, "transient": True, "substeps": 0})
    spec = CaseSpec.from_config({"grid": grid, "transient": True, "dt": 0.1, "substeps": 4})
    assert spec.time_step == pytest.approx(0.025)
    assert spec.drag_value() == pytest.approx(1e4 * 40.0)  # the time-step rate 1/0.025 dominates


@needs_foam
def test_piston_moves_the_fluid_column_and_feels_its_added_mass(tmp_path):
    """1D: a body filling the channel's cross-section (cells 8-11 of 20) set moving at V from
    rest, both ends open at p = 0. Incompressibility moves the whole column at V; one Euler step
    accelerates it by V/dt, so p falls linearly behind the body and rises ahead of it:
    p = -rho V x / dt before, rho V (L - x) / dt after (the added mass rho L_fluid per area).
    The jump across the body is the inertia of the fluid outside it only: the penalized fluid
    inside passes its own to the penalty, which is why a surface-coupled rock keeps its rho_s
    (the flow rule, coupler/plan/effects/flow.py). Measured: U within 7e-4 of V (the penalization error, ~ grad p /
    D_max), p within 0.07%."""
    nx, L, V = 20, 0.2, 0.1
    empty = {f: "empty" for f in ("ymin", "ymax", "zmin", "zmax")}
    s = transient(tmp_path, [nx, 1, 1], [L / nx, 0.01, 0.01], empty)
    f = np.zeros(nx)
    f[8:12] = 1.0
    vel = np.zeros((nx, 3))
    vel[8:12, 0] = V
    U, p = s.solve(f, vel, 0.0, DT)
    assert s.application == "pimpleFoam" and s.last_run["converged"] and s.start == "0.01"
    assert s.last_run["velocity_sources"] == [[V, 0.0, 0.0]]
    assert np.abs(U[:, 0] - V).max() < 2e-3 * V and np.abs(U[:, 1:]).max() < 1e-9
    x = s.spec.grid.cell_centres()[:, 0]
    before, after = x < 0.08, x > 0.12
    assert p[before] * RHO == pytest.approx(-RHO * V * x[before] / DT, rel=2e-3)
    assert p[after] * RHO == pytest.approx(RHO * V * (L - x[after]) / DT, rel=2e-3)


@needs_foam
def test_squeezed_channel_pressure_is_the_added_mass_of_lubrication_theory(tmp_path):
    """2D: the floor of a channel (height h, length L, open ends at p = 0, slip roof) starts
    moving up at V; the body under it leaves the grid through an open zmin. Continuity gives
    the channel flux V (x - L/2), one Euler step from rest p = rho V x (L - x) / (2 h dt): the
    added mass rho L^2 / (12 h) per area of the added_mass cases. Measured: the channel's
    mean pressure within 0.08% of it (40 x 8 cells), the body at V within 0.2%."""
    nx, nz, L, hz, V, dt = 40, 8, 0.1, 0.0025, 0.01, 1e-4
    s = transient(tmp_path, [nx, 1, nz], [L / nx, 0.01, hz],
                  {"ymin": "empty", "ymax": "empty", "zmin": {"pressure": 0.0}}, dt=dt)
    f = np.zeros((nz, nx))
    f[:3] = 1.0
    vel = np.zeros((nz, nx, 3))
    vel[:3, :, 2] = V
    U, p = s.solve(f.ravel(), vel.reshape(-1, 3), 0.0, dt)
    x, h = s.spec.grid.cell_centres()[:nx, 0], (nz - 3) * hz
    exact = RHO * V * x * (L - x) / (2 * h * dt)
    channel = (p * RHO).reshape(nz, nx)[3:].mean(axis=0)
    assert np.abs(channel - exact).max() < 5e-3 * exact.max()
    assert U.reshape(nz, nx, 3)[:3, :, 2] == pytest.approx(V, rel=5e-3)


@needs_foam
def test_a_repeated_step_restarts_from_its_start_and_gives_the_same_fields(tmp_path):
    """The coupling iterations of one step each rerun pimpleFoam from the step's start (the
    participant's restore_state): identical inputs give identical outputs; a step that does
    not start where the fluid's state is raises."""
    nx = 10
    empty = {f: "empty" for f in ("ymin", "ymax", "zmin", "zmax")}
    s = transient(tmp_path, [nx, 1, 1], [0.01, 0.01, 0.01], empty, substeps=2)
    f = np.zeros(nx)
    f[4:6] = 1.0
    vel = np.zeros((nx, 3))
    vel[4:6, 0] = 0.05
    s.solve(f, vel, 0.0, DT)                      # step 0
    start = s.start
    U1, p1 = s.solve(f, 2 * vel, DT, DT)          # step 1, iteration 0
    assert s.start == "0.02"
    s.start = start                               # restore_state
    U2, p2 = s.solve(f, 2 * vel, DT, DT)          # step 1, iteration 1: same inputs
    assert np.array_equal(U1, U2) and np.array_equal(p1, p2)
    # the body accelerated from 0.05 to 0.1 in this step: p jump = rho L_fluid (dV / dt)
    assert (p1[6] - p1[3]) * RHO > 0
    with pytest.raises(OpenFOAMError, match="restore_state"):
        s.solve(f, vel, 5 * DT, DT)
