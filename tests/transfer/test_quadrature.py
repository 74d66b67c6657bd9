"""Quadrature rules: simplex rules exact to their degree, tensor Gauss rules."""

from itertools import product
from math import factorial

import numpy as np
import pytest

from transfer.quadrature import gauss_tensor, simplex_rule


def exponents(nvars: int, max_total: int):
    """All exponent tuples of nvars variables with total degree <= max_total."""
    return [e for e in product(range(max_total + 1), repeat=nvars) if sum(e) <= max_total]


def barycentric_moment(alpha, dim: int) -> float:
    """Mean over a dim-simplex of prod_i lambda_i^alpha_i = prod alpha_i! dim! / (|alpha| + dim)!."""
    return np.prod([factorial(a) for a in alpha]) * factorial(dim) / factorial(sum(alpha) + dim)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5, 6])
def test_simplex_rule_exact_up_to_degree(dim, degree):
    bary, w = simplex_rule(dim, degree)
    assert bary.shape == (len(w), dim + 1)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.all(bary >= -1e-15), "points outside the simplex"
    np.testing.assert_allclose(w.sum(), 1.0, rtol=0, atol=1e-14)
    for alpha in exponents(dim + 1, degree):
        approx = w @ np.prod(bary ** np.asarray(alpha), axis=1)
        exact = barycentric_moment(alpha, dim)
        assert abs(approx - exact) <= 1e-14 * max(1.0, exact) + 1e-15, (alpha, approx, exact)


@pytest.mark.parametrize("dim", [2, 3])
def test_low_degree_rules_have_positive_weights(dim):
    for degree in (1, 2):
        _, w = simplex_rule(dim, degree)
        assert np.all(w > 0)


def test_simplex_rule_rejects_other_dimensions():
    with pytest.raises(ValueError):
        simplex_rule(1, 2)
    with pytest.raises(ValueError):
        simplex_rule(4, 2)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_gauss_tensor_exact_per_axis(dim, n):
    x, w = gauss_tensor(dim, n)
    assert x.shape == (n**dim, dim)
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-14)
    for e in product(range(2 * n), repeat=dim):  # degree <= 2n - 1 in every variable
        exact = np.prod([1.0 / (k + 1) for k in e])
        assert abs(w @ np.prod(x ** np.asarray(e), axis=1) - exact) < 1e-14, e
