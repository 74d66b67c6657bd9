"""How the fluid turns solid fractions into drag (transfer/penalization.py); its effect on
the flow through immersed plates is cases/parallel_plates (tests/cases/test_parallel_plates.py)."""

from __future__ import annotations

import numpy as np
import pytest

from transfer.penalization import PENALIZATIONS, REACH, drag_fraction, drag_fraction_of, reach


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
    ids = reach(cells, shape, mode)
    whole = drag_fraction(f, shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode, 2.0)
    part = drag_fraction_of(cells, ids, f[ids], shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode, 2.0)
    np.testing.assert_array_equal(part, whole[cells])
    assert len(np.unique(whole[cells])) > 10  # the drag varies: not an equality of zeros
    corner = reach([0], shape, mode)  # cell (0, 0, 0): itself and +1 along each axis
    assert corner.tolist() == ([0, 1, 7, 42] if REACH[mode] else [0])
    if REACH[mode]:  # without its neighbours' fractions a wall cell's drag is wrong
        wet = cells[(whole[cells] > 0) & (whole[cells] < 1)][:1]
        assert len(wet) == 1
        alone = drag_fraction_of(wet, wet, f[wet], shape, [1e-3, 2e-3, 1.5e-3], 1e-6, 1e3, mode)
        assert alone[0] != whole[wet[0]]
