"""Convergence: projecting a smooth field from a fine P1 mesh onto refined P1 meshes,
the true L2 error (by quadrature on the target tets) falls as h^2.

The source (32^3 x 6 tets) is much finer than the targets (3, 6, 12 cells per
axis), so its own interpolation error, O(h_source^2), stays well below the
projection error on the finest target.
"""

import numpy as np
import pytest

from transfer import FunctionSpace, Transfer
from transfer.generate import box_tetrahedra
from transfer.quadrature import simplex_rule

from vc_helpers import p1_l2_error

TARGETS = (3, 6, 12)


def f(x):
    return np.sin(np.pi * x[:, 0]) * np.cos(np.pi * x[:, 1]) * np.exp(x[:, 2])


@pytest.fixture(scope="module")
def fine_source():
    return FunctionSpace(box_tetrahedra((32, 32, 32), jitter=0.15, seed=11, name="fine"), "P1")


def test_l2_error_helper_is_exact_for_interpolated_linears():
    """The error helper itself: zero for a field in the space, the right value for a constant offset."""
    m = box_tetrahedra((2, 2, 2), jitter=0.2, seed=1)
    g = lambda x: 1 + x @ [1.0, 2.0, -1.0]
    rule = simplex_rule(3, 5)
    assert p1_l2_error(m, g(m.points), g, rule) < 1e-14
    np.testing.assert_allclose(p1_l2_error(m, g(m.points) + 0.5, g, rule), 0.5, rtol=1e-13)


def test_projection_converges_at_rate_two(fine_source, method):
    u = fine_source.interpolate(f)
    rule = simplex_rule(3, 5)
    errors, h = [], []
    for n in TARGETS:
        target = box_tetrahedra((n, n, n), jitter=0.15, seed=100 + n, name=f"target{n}")
        T = Transfer.assemble(fine_source, FunctionSpace(target, "P1"), method)
        v = T(u)
        assert np.all(np.isfinite(v))
        errors.append(p1_l2_error(target, v, f, rule))
        h.append(1.0 / n)
    rate = np.polyfit(np.log(h), np.log(errors), 1)[0]
    assert 1.8 < rate < 2.3, (errors, rate)
    # and each refinement gains: the errors fall monotonically
    assert errors[0] > errors[1] > errors[2]


def test_l2_is_the_best_approximation(fine_source):
    """On the same target, the L2 projection is at least as accurate as the pseudo-L2
    one and as nodal interpolation (up to the source's own, much smaller, error)."""
    u = fine_source.interpolate(f)
    rule = simplex_rule(3, 5)
    target = box_tetrahedra((6, 6, 6), jitter=0.15, seed=106)
    V = FunctionSpace(target, "P1")
    e_l2 = p1_l2_error(target, Transfer.assemble(fine_source, V, "l2")(u), f, rule)
    e_pl2 = p1_l2_error(target, Transfer.assemble(fine_source, V, "pseudo_l2")(u), f, rule)
    e_int = p1_l2_error(target, V.interpolate(f), f, rule)
    assert e_l2 < e_pl2 and e_l2 < e_int
