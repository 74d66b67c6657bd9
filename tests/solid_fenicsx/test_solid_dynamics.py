"""solid_fenicsx dynamics (paper eq. 13): Newmark / generalized-alpha, effective
density rho_s - rho_f, energy, checkpoints for implicit coupling."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI  # noqa: E402

from solid_fenicsx import Elasticity, Scheme, box_mesh  # noqa: E402
from solid_fenicsx.cases import bar_oscillation, measured_period  # noqa: E402


def test_scheme_coefficients():
    nm = Scheme.newmark()
    assert (nm.beta, nm.gamma, nm.alpha_m, nm.alpha_f) == (0.25, 0.5, 0.0, 0.0)
    ga = Scheme.generalized_alpha(1.0)
    assert np.allclose((ga.alpha_m, ga.alpha_f, ga.beta, ga.gamma), (0.5, 0.5, 0.25, 0.5))
    ga = Scheme.generalized_alpha(0.0)
    assert np.isclose(ga.gamma, 0.5 - ga.alpha_m + ga.alpha_f)
    t = np.linspace(0, 3, 301)
    assert np.isclose(measured_period(t, np.cos(2 * np.pi * t / 1.5)), 1.5, rtol=1e-3)


def test_bar_period_and_effective_density():
    """Released bar: period 4 L / c with c = sqrt(E / (rho_s - rho_f)) (1 % : 20 cells, 80 steps/period)."""
    dry = bar_oscillation(density=2000.0, fluid_density=0.0)
    assert abs(dry.period / dry.exact_period - 1) < 0.01
    wet = bar_oscillation(density=2000.0, fluid_density=1000.0)
    assert abs(wet.period / wet.exact_period - 1) < 0.01
    assert np.isclose(wet.period / dry.period, np.sqrt(1000.0 / 2000.0), rtol=1e-3)
    # average acceleration conserves the discrete energy (no load, exact solves)
    assert np.abs(dry.energy - dry.energy[0]).max() < 1e-8 * dry.energy[0]


def test_generalized_alpha_dissipates_monotonically():
    r = bar_oscillation(scheme="generalized_alpha", rho_inf=0.5, periods=1.0)
    assert abs(r.period / r.exact_period - 1) < 0.02
    assert np.all(np.diff(r.energy) <= 1e-12 * r.energy[0])
    assert r.energy[-1] < 0.99 * r.energy[0]


def test_energy_conservation_block_cg():
    """Newmark on a 3D block with CG + GAMG (tight tolerance), free vibration."""
    solid = box_mesh(upper=(1.0, 0.5, 0.5), shape=(6, 3, 3))
    s = Elasticity(solid, E=1e9, nu=0.3, density=2500.0, scheme="newmark", dt=2e-5, rtol=1e-14)
    s.add_dirichlet("xmin", 0.0)
    s.v.interpolate(lambda x: np.stack([0 * x[0], 0 * x[0], 0.1 * x[0] ** 2]))  # a bending kick
    s.initialize()
    e0 = sum(s.energy())
    energies = []
    for _ in range(25):
        s.step()
        energies.append(sum(s.energy()))
    assert np.abs(np.array(energies) - e0).max() < 1e-8 * e0
    assert s.energy()[1] > 1e-3 * e0  # energy did move into strain


@pytest.mark.parametrize("scheme", ["newmark", "generalized_alpha"])
def test_restore_state_repeats_steps_identically(scheme):
    solid = box_mesh(upper=(1.0, 0.5, 0.5), shape=(4, 2, 2))
    s = Elasticity(solid, E=1e9, nu=0.3, density=2500.0, scheme=scheme, dt=5e-5, rtol=1e-10)
    s.add_dirichlet("xmin", 0.0)
    f = s.add_traction_field("xmax", name="fluid")
    n = solid.num_points
    root = MPI.COMM_WORLD.rank == 0

    def load(k):
        s.set_vertex_field("fluid", np.tile([0.0, 0.0, -1e5 * (k + 1)], (n, 1)) if root else None)

    for k in range(3):
        load(k)
        s.step()
    state = s.save_state()
    results = []
    for _ in range(3):  # three coupling iterations of one window of two steps
        s.restore_state(state)
        for k in (3, 4):
            load(k)
            s.step()
        results.append([s.u.x.array.copy(), s.v.x.array.copy(), s.a.x.array.copy(), s.t])
    ref = results[0]
    scale = np.abs(ref[0]).max()
    assert scale > 0
    for other in results[1:]:
        for a, b in zip(ref[:3], other[:3]):
            assert np.abs(a - b).max() <= 1e-12 * max(np.abs(a).max(), 1e-300)
        assert other[3] == ref[3]
    assert f.x.array.any()
    # the state is a copy: stepping on does not change it
    assert state["t"] == pytest.approx(3 * 5e-5) and state["step_count"] == 3
