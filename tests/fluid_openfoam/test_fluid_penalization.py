"""How the fluid turns solid fractions into drag (transfer/penalization.py); its effect on
the flow through immersed plates is cases/parallel_plates (tests/cases/test_parallel_plates.py)."""

from __future__ import annotations

import numpy as np
import pytest

from transfer.penalization import PENALIZATIONS, REACH, drag_fraction


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
