"""How the fluid turns solid fractions into drag (transfer/penalization.py); its effect on
the flow through immersed plates is cases/parallel_plates (tests/cases/test_parallel_plates.py)."""

from __future__ import annotations

import numpy as np
import pytest

from transfer.grid import across_axis
from transfer.penalization import (LINES, PENALIZATIONS, REACH, drag_fraction, drag_fraction_of, face_fraction,
                                   plates_fraction, reach)


def test_wall_drag_in_one_dimension():
    """Fluid-centred cell next to a solid-centred one: D = nu/h^2 (h/d - 1), d = h (3/2 - f_c - f_s);
    solid-centred cells get the maximum (T = 1)."""
    nu, h, dmax = 1e-6, 0.1, 1.0
    f = np.array([1.0, 1.0, 0.3, 0.0, 0.0, 0.7, 1.0])
    T = drag_fraction(f, (1, 7, 1), (1.0, h, 1.0), nu, dmax, "wall")
    d = np.array([h * (1.5 - 0.3 - 1.0), h * (1.5 - 0.0 - 0.7)])
    np.testing.assert_allclose(T[[2, 4]], nu / h ** 2 * (h / d - 1) / dmax, rtol=1e-12)
    np.testing.assert_array_equal(T[[0, 1, 5, 6]], 1.0)
    assert T[3] == 0.0
    np.testing.assert_array_equal(drag_fraction(f, (1, 7, 1), (1, h, 1), nu, dmax, "linear"), f)


@pytest.mark.parametrize("mode", PENALIZATIONS)
def test_reach_is_how_far_the_drag_of_a_cell_reads_fractions(mode):
    """Making one cell solid among fluid cells changes T exactly within REACH[mode] face steps of it
    (the planes a Chorin slab rank receives beyond its ghost layer)."""
    shape = (7, 6, 5)
    f = np.random.default_rng(1).uniform(0.0, 0.4, size=int(np.prod(shape)))
    g = f.copy()
    centre = (2, 3, 3)  # (k, j, i)
    g[np.ravel_multi_index(centre, shape[::-1])] = 0.9
    before, after = (drag_fraction(a, shape, [1e-3] * 3, 1e-6, 1e3, mode, 2.0) for a in (f, g))
    changed = np.argwhere((before != after).reshape(shape[::-1]))
    assert np.abs(changed - centre).sum(axis=1).max() == REACH[mode]
    assert len(changed) == {0: 1, 1: 7}[REACH[mode]]


@pytest.mark.parametrize("mode", PENALIZATIONS)
def test_the_drag_of_some_cells_from_their_reach_is_the_whole_grids(mode):
    """drag_fraction_of a scattered set of cells (an OpenFOAM processor need not be a box), from the
    fractions of reach(cells) only, equals drag_fraction of the whole grid there bitwise; reach is the
    cells and their neighbours within REACH[mode] steps along each axis (grid edges cut off)."""
    shape = (7, 6, 5)
    rng = np.random.default_rng(2)
    f = np.where(rng.random(int(np.prod(shape))) < 0.4, 1.0, rng.uniform(0.0, 0.6, int(np.prod(shape))))
    cells = np.sort(rng.choice(f.size, 40, replace=False))
    across = across_axis(shape, [1e-3, 2e-3, 1.5e-3])  # z
    ids = reach(cells, shape, mode, across=across)
    whole = drag_fraction(f, shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode, 2.0)
    part = drag_fraction_of(cells, ids, f[ids], shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode, 2.0)
    np.testing.assert_array_equal(part, whole[cells])
    for cell in cells:  # one cell alone (a processor of one cell) from its own reach
        alone = reach([cell], shape, mode, across=across)
        assert drag_fraction_of([cell], alone, f[alone], shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode,
                                2.0)[0] == whole[cell], cell
    assert len(np.unique(whole[cells])) > 10  # the drag varies: not an equality of zeros
    corner = reach([0], shape, mode, across=across)  # cell (0, 0, 0): itself and +1 along each axis
    lines = sorted(42 * k + d for k in range(5) for d in (0, 1, 7))  # and the lines across the gap through them
    assert corner.tolist() == (lines if mode in LINES else [0, 1, 7, 42] if REACH[mode] else [0])
    if REACH[mode]:  # without its neighbours' fractions a wall cell's drag is wrong
        wet = cells[(whole[cells] > 0) & (whole[cells] < 1)][:1]
        assert len(wet) == 1
        alone = drag_fraction_of(wet, wet, f[wet], shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode)
        assert alone[0] != whole[wet[0]]


def plates(across: float, below: float, cells: int = 14) -> np.ndarray:
    """Solid fractions of a line of `cells` cells 1 high across two plates: the open gap is
    `across` cells from `below` cells above the line's start (exact fractions, as transfer gives)."""
    k = np.arange(cells, dtype=float)
    open_ = np.clip(np.minimum(k + 1, below + across) - np.maximum(k, below), 0.0, 1.0)
    return 1.0 - open_


def conductance_error(f, mode: str, nu: float = 1e-3, h: float = 0.5) -> float:
    """The relative error of the discrete lubrication conductance of the line of fractions `f`
    against e^3 / (12 nu), e the open length: the flow ``nu (u[k+1] - 2u[k] + u[k-1]) / h^2 - D[k]
    u[k] = -1`` (the in-plane velocity of the MAC grid's faces and OpenFOAM's cells) with u = 0 in
    the solid-centred cells, its flux ``h sum(u)``."""
    T = drag_fraction(f, (1, 1, len(f)), (1.0, 1.0, h), nu, 1.0, mode)
    fluid = np.flatnonzero(T < 1.0)  # the others stopped (at the drag D_max)
    m = len(fluid)
    A = nu / h ** 2 * (np.diag(np.ones(m - 1), 1) + np.diag(np.ones(m - 1), -1) - 2.0 * np.eye(m)) - np.diag(T[fluid])
    u = np.linalg.solve(A, -np.ones(m))
    e = h * np.sum(1.0 - f)
    return h * u.sum() / (e ** 3 / (12.0 * nu)) - 1.0


@pytest.mark.parametrize("across", [3.0, 4.0, 8.0, 1.4, 2.7])
def test_lubrication_drag_gives_plates_the_cubic_law_at_any_wall_offset(across):
    """Penalization "lubrication": plates `across` cells apart at arbitrary offsets to the grid pass
    e^3 / (12 nu) to round-off (single-cell openings included); the "wall" mode errs there (up to
    +26 % at 3 cells across), so the check can fail."""
    offsets = np.linspace(2.02, 2.98, 13)
    errors = {mode: np.array([conductance_error(plates(across, b), mode) for b in offsets])
              for mode in ("lubrication", "wall")}
    np.testing.assert_allclose(errors["lubrication"], 0.0, atol=1e-12)
    assert np.abs(errors["wall"]).max() > 0.01


def test_lubrication_drag_reads_the_whole_line_across_the_gap():
    """The cut cells' drag follows the opposite wall of their run (many cells away along the axis
    across the gap, z here: the thinner extent), nothing across another axis, and runs that reach
    the grid's end keep the wall drag; drag_fraction_of from reach() gives the whole grid's."""
    f = plates(6.0, 2.3)  # walls at 2.3 and 8.3 cells
    g = plates(5.0, 2.3)  # the upper wall a cell lower
    shape = (3, 2, len(f))
    F, G = (np.tile(a[:, None, None], (1, 2, 3)).ravel() for a in (f, g))
    args = (shape, (1e-3, 1e-3, 5e-6), 1e-3, 1e9)
    lub, wall = drag_fraction(F, *args, "lubrication"), drag_fraction(F, *args, "wall")
    low = np.ravel_multi_index((2, 0, 0), shape[::-1])  # the first cell above the lower wall
    assert lub[low] != wall[low]
    assert drag_fraction(G, *args, "lubrication")[low] != lub[low]
    open_top = np.tile(plates(12.0, 2.3)[:, None, None], (1, 2, 3)).ravel()  # no upper wall in the grid
    np.testing.assert_array_equal(drag_fraction(open_top, *args, "lubrication"), drag_fraction(open_top, *args, "wall"))
    cells = np.array([low, low + 1])
    ids = reach(cells, shape, "lubrication", across=2)
    np.testing.assert_array_equal(drag_fraction_of(cells, ids, F[ids], *args, "lubrication"), lub[cells])


def test_a_face_between_two_columns_is_open_over_the_overlap_of_their_openings():
    """face_fraction: the larger of the two cells' fractions, so a face between columns whose gaps
    are offset (a step of the grid's staircase) opens over their overlap, exactly for walls in
    the cells, and its lubrication drag is the cubic law of that overlap; boundary faces take
    their cell's fractions."""
    left, right = plates(4.0, 2.3), plates(5.0, 3.6)  # open over [2.3, 6.3] and [3.6, 8.6] cells
    F = np.stack([left, right], axis=-1)[:, None, :]  # [k, j, i]: two columns along x
    faces = face_fraction(F, 2)
    assert faces.shape == (len(left), 1, 3)
    np.testing.assert_array_equal(faces[:, 0, 0], left)
    np.testing.assert_array_equal(faces[:, 0, 2], right)
    overlap = plates(6.3 - 3.6, 3.6)
    np.testing.assert_allclose(faces[:, 0, 1], overlap, atol=1e-15)
    assert conductance_error(faces[:, 0, 1], "lubrication") == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(face_fraction(F, 0)[[0, -1]], F[[0, -1]])


def sloped(low: tuple, high: tuple, cells: int = 24) -> np.ndarray:
    """Solid fractions of a line of cells across a gap whose walls are sloped within the column:
    the lower wall rising linearly from low[0] to low[1] cells across the column's width, the
    upper from high[0] to high[1] (the column-mean of each cell's solid: exact)."""
    k = np.arange(cells, dtype=float)[:, None]
    s = np.linspace(0.0, 1.0, 2001)[None, :]  # across the column's width
    lower, upper = low[0] + (low[1] - low[0]) * s, high[0] + (high[1] - high[0]) * s
    open_ = np.clip(np.minimum(k + 1, upper) - np.maximum(k, lower), 0.0, 1.0)
    return 1.0 - np.trapz(open_, s, axis=1)


@pytest.mark.parametrize("low,high", [((2.0, 4.0), (9.0, 8.3)), ((2.2, 8.0), (14.0, 19.5)), ((2.6, 3.4), (5.3, 4.5))])
def test_lubrication_drag_gives_a_sloped_column_the_cubic_law_of_its_mean_opening(low, high):
    """Walls sloped within a column spread their solid over several cells (partly solid cells deep
    in the gap): penalization "lubrication" gives the column the cubic law of its open length, the
    gap made plates at the column's mean walls (plates_fraction, which keeps plates as they are)."""
    f = sloped(low, high)
    assert ((f > 0.01) & (f < 0.49)).any()  # partly solid cells in the run
    assert conductance_error(f, "lubrication") == pytest.approx(0.0, abs=1e-12)
    assert abs(conductance_error(f, "wall")) > 0.01
    flat = plates(6.0, 2.3)[:, None, None]
    np.testing.assert_allclose(plates_fraction(flat, 0), flat, atol=1e-15)
