"""The Reynolds (local cubic law) solve against the lubrication solutions: parallel plates
exact at any resolution, an aperture varying along the flow (the apertures in series: the
harmonic mean of e^3) and across it (in parallel: the mean of e^3), mass conserved per cell,
a closed throat passing nothing."""

import numpy as np
import pytest

from fluid_reynolds.reynolds import solve

MU, DP, L, W = 1.0e-3, 1.0e3, 0.02, 0.01
PRESSURES = {"xmin": DP, "xmax": 0.0}


def midpoints(n: int, length: float) -> np.ndarray:
    return (np.arange(n) + 0.5) * length / n


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (5, 3), (17, 40)])
def test_parallel_plates_are_exact(shape):
    e = 1.0e-4
    flow = solve(np.full(shape, e), (L / shape[1], W / shape[0]), MU, PRESSURES)
    assert flow.flow_rate == pytest.approx(W * e**3 * DP / (12 * MU * L), rel=1e-12)
    x = midpoints(shape[1], L)
    assert np.allclose(flow.pressure, DP * (1 - x / L), rtol=0, atol=1e-9 * DP)  # linear
    assert flow.percolating and flow.residual < 1e-12


def aperture_along(x):
    return 1.0e-4 * (1.0 + 0.6 * np.sin(2 * np.pi * x / L))


def test_aperture_along_the_flow_is_the_harmonic_mean_of_the_cube():
    """e(x): the cells in series, Q = W dp / (12 mu int_0^L e^-3 dx)."""
    xs = np.linspace(0.0, L, 200001)
    exact = W * DP / (12 * MU * np.trapz(aperture_along(xs) ** -3, xs))
    for nx in (64, 128):
        e = np.tile(aperture_along(midpoints(nx, L)), (3, 1))
        q = solve(e, (L / nx, W / 3), MU, PRESSURES).flow_rate
        assert abs(q / exact - 1) < 5e-3, (nx, q / exact - 1)
    uniform = solve(np.full((3, 64), np.mean(aperture_along(xs))), (L / 64, W / 3), MU, PRESSURES).flow_rate
    assert uniform > 1.2 * exact  # the test can tell: the mean aperture's cubic law is far off


def aperture_across(y):
    return 1.0e-4 * (1.0 + 0.8 * np.cos(2 * np.pi * y / W))


def test_aperture_across_the_flow_is_the_mean_of_the_cube():
    """e(y): the strips in parallel, Q = dp / (12 mu L) int_0^W e^3 dy."""
    ys = np.linspace(0.0, W, 200001)
    exact = DP * np.trapz(aperture_across(ys) ** 3, ys) / (12 * MU * L)
    for ny in (32, 64):
        e = np.tile(aperture_across(midpoints(ny, W))[:, None], (1, 5))
        q = solve(e, (L / 5, W / ny), MU, PRESSURES).flow_rate
        assert abs(q / exact - 1) < 5e-3, (ny, q / exact - 1)


def rough(shape, seed=3):
    """A rough aperture map with contacts (e = 0 on about a fifth of the cells)."""
    rng = np.random.default_rng(seed)
    e = 1.0e-4 * (0.5 + rng.random(shape)) - 0.3e-4 * (rng.random(shape) < 0.2) * 10
    return np.maximum(e, 0.0)


def test_mass_is_conserved_in_every_cell():
    e = rough((30, 40))
    flow = solve(e, (L / 40, W / 30), MU, {"xmin": DP, "xmax": 0.0, "ymax": 0.4 * DP})
    assert flow.percolating and (~flow.solved & (e > 0)).any()  # isolated open pockets are excluded
    scale = np.abs(flow.flux_x).max()
    assert np.abs(flow.cell_balance()).max() < 1e-12 * scale
    # what enters leaves: xmin in, xmax and the open face ymax out
    assert flow.flux_x[:, 0].sum() == pytest.approx(flow.flux_x[:, -1].sum() + flow.flux_y[-1].sum(), rel=1e-12)
    assert flow.flux_y[-1].sum() > 0 and not flow.flux_y[0].any()  # ymin is closed
    assert np.all(flow.flux_x[:, 1:-1][(e[:, :-1] == 0) | (e[:, 1:] == 0)] == 0)  # nothing through a closed cell


def test_a_closed_throat_passes_nothing():
    e = np.full((6, 12), 1.0e-4)
    e[:, 5] = 0.0  # the throat at x = 5
    flow = solve(e, (L / 12, W / 6), MU, PRESSURES)
    plates = W * 1.0e-12 * DP / (12 * MU * L)
    assert abs(flow.flow_rate) < 1e-12 * plates and not flow.percolating  # no flow, to round-off
    assert np.allclose(flow.pressure[:, :5], DP, rtol=1e-13) and np.allclose(flow.pressure[:, 6:], 0.0, atol=1e-10)
    e[2, 5] = 1.0e-5  # one open cell: it passes W/6 e^3 ... in series with the rest
    assert solve(e, (L / 12, W / 6), MU, PRESSURES).flow_rate > 0


def test_a_fixed_inflow_gives_the_cubic_law_pressure_drop():
    """An inlet velocity u on the open part of xmin: Q = u e W enters, dp = 12 mu L Q / (W e^3)."""
    e, u, ny, nx = 1.0e-4, 0.01, 4, 9
    flow = solve(np.full((ny, nx), e), (L / nx, W / ny), MU, {"xmax": 0.0}, inflow=np.full(ny, u * e * W / ny))
    assert flow.flow_rate == pytest.approx(u * e * W, rel=1e-12)
    assert flow.flux_x[:, -1].sum() == pytest.approx(u * e * W, rel=1e-12)
    # the pressure at the inlet face: the first cell's plus the half cell's drop
    inlet = flow.pressure[0, 0] + 12 * MU * (L / nx / 2) * u / e**2
    assert inlet == pytest.approx(12 * MU * L * u / e**2, rel=1e-12)


def test_an_inflow_into_a_pocket_without_outlet_is_counted_as_dropped():
    """An inlet cell that is closed (row 2) or sealed from the outlet (row 3, behind row 2's wall
    and a closed cell) takes no flow (not in the solve); what it was given is ``dropped``, and the
    rest still passes (the participant warns with it; before, it went unsaid)."""
    e, u, ny, nx = 1.0e-4, 0.01, 4, 9
    aperture = np.full((ny, nx), e)
    aperture[2, :4] = 0.0  # a wall along x seals rows 3 from the outlet behind a closed column
    aperture[3, 4] = 0.0
    given = np.full(ny, u * e * W / ny)
    flow = solve(aperture, (L / nx, W / ny), MU, {"xmax": 0.0}, inflow=given)
    assert not flow.solved[2:, 0].any() and flow.dropped == pytest.approx(given[2:].sum(), rel=1e-12)
    assert flow.flow_rate == pytest.approx(given[:2].sum(), rel=1e-12)
    assert solve(np.full((ny, nx), e), (L / nx, W / ny), MU, {"xmax": 0.0}, inflow=given).dropped == 0.0
