"""The OpenFOAM fluid participant on a plane Poiseuille (parallel-plate) channel.

2D (one cell in z, empty front and back), pressure inlet at xmin and outlet at xmax,
no-slip walls at ymin/ymax: the exact solution is the parabola for any channel length,
and the flow rate per unit width is the cubic law Q = w^3 dp / (12 mu L). The cell-centred
discretisation with the wall half a cell from the first centre over-predicts Q by
2 (h/w)^2 (0.5% at 20 cells across, measured).
"""

from __future__ import annotations

import shutil
import time
import uuid

import numpy as np
import pytest

from fluid_openfoam.case import CaseSpec
from fluid_openfoam.solver import OpenFOAMError, OpenFOAMSolver

pytestmark = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")

W, L, DP, MU, RHO, NX = 1.0e-3, 2.0e-3, 1.0e-2, 1.0e-3, 1000.0, 4


def channel_config(n_across: int, **extra) -> dict:
    h = W / n_across
    cfg = {"grid": {"origin": [0.0, 0.0, 0.0], "spacing": [L / NX, h, h], "shape": [NX, n_across, 1]},
           "location": "cells", "inlet": {"pressure": DP}, "outlet": {"pressure": 0.0},
           "boundaries": {"zmin": "empty", "zmax": "empty"}, "mu": MU, "rho": RHO,
           "max_iterations": 3000, "tolerance": 1e-8}
    cfg.update(extra)
    return cfg


def cubic_law(w: float) -> float:
    return w ** 3 * DP / (12 * MU * L)


def flow_rate(U: np.ndarray, n_across: int) -> np.ndarray:
    """Q per unit width through each x column of cells."""
    return U[:, 0].reshape(n_across, NX).sum(axis=0) * (W / n_across)


@pytest.mark.parametrize("n_across, bound", [(10, 0.025), (20, 0.01)])
def test_cubic_law_real_walls(tmp_path, n_across, bound):
    s = OpenFOAMSolver(tmp_path / "case", CaseSpec.from_config(channel_config(n_across)))
    s.setup()
    t0 = time.perf_counter()
    U, p = s.solve(np.zeros(s.n))
    wall = time.perf_counter() - t0
    assert s.last_run["converged"], s.last_run
    err = flow_rate(U, n_across) / cubic_law(W) - 1
    print(f"{n_across} cells across: cubic-law error {err.max():+.4%}, simpleFoam {wall:.2f} s, "
          f"{s.last_run['iterations']} iterations")
    assert np.all(np.abs(err) < bound)
    assert np.ptp(err) < 1e-6  # the same flow rate through every section
    # kinematic pressure, linear from DP/RHO to 0
    x = (np.arange(NX) + 0.5) * L / NX
    np.testing.assert_allclose(p.reshape(n_across, NX)[0], DP / RHO * (1 - x / L), rtol=1e-6)
    np.testing.assert_allclose(U[:, 1:], 0.0, atol=1e-10 * np.abs(U).max())


@pytest.mark.parametrize("penalization", ["wall", "linear"])
def test_immersed_half_channel_and_restart(tmp_path, penalization):
    """A solid fraction of 1 in the lower half: no flow there, a Poiseuille flow of aperture
    w/2 above. With penalization "linear" the wall sits at the centre of the first solid cell
    (half a cell too far), so Q is over-predicted by about (1 + h/(w/2))^3 (measured +16.3%
    at 10 cells across). The "wall" drag puts it on the cell face: the same +2 (h/w)^2 as a
    real wall (measured +2.00%)."""
    n = 20
    s = OpenFOAMSolver(tmp_path / "case", CaseSpec.from_config(channel_config(n, penalization=penalization)))
    s.setup()
    yc = (np.arange(n) + 0.5) * W / n
    frac = np.repeat((yc < W / 2).astype(float), NX)
    U, p = s.solve(frac)
    assert s.last_run["converged"]
    solid = frac == 1
    assert np.abs(U[solid]).max() < 1e-3 * np.abs(U).max()
    ratio = flow_rate(U, n) / cubic_law(W / 2)
    print(f"immersed, 10 cells across, binary mask, {penalization}: Q / cubic law = {ratio.max():.4f}")
    if penalization == "linear":
        assert np.all((ratio > 1.0) & (ratio < (1 + (W / n) / (W / 2)) ** 3 * 1.01))
    else:
        np.testing.assert_allclose(ratio, 1 + 2 * (2 / n) ** 2, rtol=1e-4)
    # warm restart with the same input: converged at once, same fields
    start = s.start
    U2, _ = s.solve(frac)
    assert s.last_run["iterations"] <= 2
    np.testing.assert_allclose(U2, U, rtol=0, atol=1e-6 * np.abs(U).max())
    # repeating from the same start gives identical outputs
    s.start = start
    U3, p3 = s.solve(frac)
    np.testing.assert_array_equal(U3, U2)


def test_bad_input_and_failure_are_clear(tmp_path):
    s = OpenFOAMSolver(tmp_path / "case", CaseSpec.from_config(channel_config(4)))
    s.setup()
    with pytest.raises(ValueError, match="expected 16"):
        s.solve(np.zeros(5))
    (s.case / "system" / "fvSchemes").write_text("garbage")
    with pytest.raises(OpenFOAMError, match="simpleFoam failed"):
        s.solve(np.zeros(s.n))


@pytest.fixture
def session(tmp_path):
    from coupler.run.launch import Launcher
    from coupler.run.client import CouplerSession

    coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
    launcher = Launcher(coupler.run_id, tmp_path, coupler.endpoints)
    try:
        yield coupler, launcher
    finally:
        launcher.stop_all(timeout=3.0)
        coupler.close()


def test_participant_speaks_the_protocol(session, tmp_path):
    from coupler.protocol.wire import Field

    coupler, launcher = session
    launcher.start("fluid", "fluid_openfoam")
    fluid = coupler.client("fluid", 60.0, process_check=lambda: launcher.check("fluid"))
    fluid.wait_alive(30.0)
    info = fluid.announce()
    assert info["kind"] == "openfoam_fluid" and info["provides"] == ["pressure", "velocity"]
    assert set(info["accepts"]) == {"solid_fraction", "solid_velocity"}

    n_across, nx = 8, 6
    cfg = channel_config(n_across, case_dir=str(tmp_path / "fluidcase"))
    cfg["grid"]["shape"] = [nx, n_across, 1]
    cfg["grid"]["spacing"][0] = L / nx
    fluid.configure(cfg)
    header, arrays = fluid.geometry()
    assert header["grid"]["shape"] == [nx, n_across, 1] and not arrays
    n = nx * n_across
    yc = (np.arange(n_across) + 0.5) * W / n_across
    frac = np.repeat((yc < W / 2).astype(float), nx)
    inputs = {"solid_fraction": Field("solid_fraction", frac), "solid_velocity": Field("solid_velocity", np.zeros((n, 3)))}
    fluid.save_state(0)
    out = fluid.advance(0, 0, 0.0, 1.0, inputs)
    p, u = out["pressure"].data, out["velocity"].data
    assert p.shape == (n,) and u.shape == (n, 3)
    assert out["pressure"].units == "Pa" and out["velocity"].units == "m/s"
    assert np.abs(u[frac == 1]).max() < 1e-3 * np.abs(u).max()
    # pressure in Pa: from about DP at the inlet to 0 at the outlet
    assert 0.5 * DP < p.max() <= DP and p.min() >= 0
    fluid.restore_state(0)
    again = fluid.advance(0, 1, 0.0, 1.0, inputs)
    np.testing.assert_allclose(again["velocity"].data, u, rtol=0, atol=1e-12 * np.abs(u).max())
    np.testing.assert_allclose(again["pressure"].data, p, rtol=0, atol=1e-12 * np.abs(p).max())
    fluid.finish()
    assert launcher.wait("fluid", 10.0) == 0


def test_non_finite_output_is_an_error(tmp_path, monkeypatch):
    import fluid_openfoam.solver as solver_mod

    s = OpenFOAMSolver(tmp_path / "case", CaseSpec.from_config(channel_config(4, max_iterations=5)))
    s.setup()
    real = solver_mod.read_internal_field

    def poisoned(path, n=None):
        arr = real(path, n).copy()
        if path.name == "U":
            arr[3, 1] = np.nan
        return arr

    monkeypatch.setattr(solver_mod, "read_internal_field", poisoned)
    with pytest.raises(OpenFOAMError, match=r"non-finite U \(first at cell 3\)"):
        s.solve(np.zeros(s.n))
    assert s.start == "0"  # the failed result is not made current
