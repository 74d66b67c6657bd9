"""Quadrature rules: on simplices (the pieces of element intersections) and
tensor Gauss rules on [0, 1]^d (element mass matrices of Q1 cells).

Simplex rules are returned in barycentric coordinates with weights summing to
one (they are multiplied by the measure of the simplex). Degree 1 is the
centroid, degree 2 the symmetric positive rule, degree 4 Dunavant's 6-point
(triangle) and Keast's 11-point (tetrahedron) rules, other degrees the
Grundmann-Moeller rules (exact to degree 2s+1, some weights negative).

Degrees are bounded by :data:`MAX_DEGREE` (:func:`check_degree`).
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations_with_replacement
from math import factorial

import numpy as np

from .errors import QuadratureError

#: Largest quadrature degree accepted. Above it the Grundmann-Moeller rules cost
#: binomial(s + 4, 4) points per intersection piece in 3D (s = degree // 2: 1001 at
#: degree 20, 3876 at 30, 292825 at 99) and lose accuracy to the cancellation of their
#: alternating weights (sum |w| = 2.6e3 at 20, 1.3e5 at 30, 2.3e10 at 60: a monomial of
#: the rule's own degree comes out with a relative error of 1e-12, 7e-11, 9e-6). Default
#: degrees are at most 8 (Q1 x Q1 on hexahedra), and Q1 on jittered hexahedra has
#: converged to 1e-12 by degree 16. Measured on 64 jittered hexahedra x 162 tetrahedra
#: (Q1 -> P1, one thread): 0.3 s at degree 8, 1.8 s at 16, 3.7 s at 20, 14 s at 30, linear
#: in the points: degree 99 would take about 18 minutes, for a worse result.
MAX_DEGREE = 20


def _compositions(total: int, parts: int):
    """All tuples of `parts` non-negative integers summing to `total`."""
    for bars in combinations_with_replacement(range(parts), total):
        yield np.bincount(np.asarray(bars, dtype=int), minlength=parts)


def _orbit(*coords):
    """All distinct permutations of barycentric coordinates."""
    from itertools import permutations

    return sorted(set(permutations(coords)))


def _degree4(dim: int):
    if dim == 2:  # Dunavant (1985), 6 points, positive weights
        groups = [(0.223381589678011, (0.445948490915965, 0.445948490915965, 0.108103018168070)),
                  (0.109951743655322, (0.091576213509771, 0.091576213509771, 0.816847572980459))]
    else:  # Keast (1986), 11 points
        a, b = 0.399403576166799, 0.100596423833201
        groups = [(-0.0789333333333333, (0.25, 0.25, 0.25, 0.25)),
                  (0.0457333333333333, (1 / 14, 1 / 14, 1 / 14, 11 / 14)),
                  (0.149333333333333, (a, a, b, b))]
    points = [p for _, c in groups for p in _orbit(*c)]
    weights = [w for w, c in groups for _ in _orbit(*c)]
    weights = np.asarray(weights)
    return np.asarray(points), weights / weights.sum()


def _grundmann_moeller(dim: int, s: int):
    points, weights = [], []
    for i in range(s + 1):
        d = 2 * s + 1
        denom = d + dim - 2 * i
        w = (-1) ** i * 2.0 ** (-2 * s) * denom**d / (factorial(i) * factorial(d + dim - i))
        for beta in (_compositions(s - i, dim + 1) if s - i > 0 else [np.zeros(dim + 1, int)]):
            points.append((2 * beta + 1) / denom)
            weights.append(w)
    weights = np.asarray(weights)
    return np.asarray(points), weights / weights.sum()


def check_degree(degree) -> int:
    """`degree` if it is an integer in [1, :data:`MAX_DEGREE`], else :class:`QuadratureError`."""
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or not 1 <= degree <= MAX_DEGREE:
        raise QuadratureError(f"quadrature degree {degree!r} is out of range: use an integer from 1 to "
                              f"{MAX_DEGREE} (higher rules cost ~degree^3 points per intersection piece and "
                              f"lose accuracy to their negative weights)")
    return int(degree)


@lru_cache(maxsize=None)
def simplex_rule(dim: int, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Rule exact for polynomials of total degree `degree` on a `dim`-simplex."""
    if dim not in (2, 3):
        raise ValueError(f"simplex rules for dim 2 or 3, got {dim}")
    n = dim + 1
    if degree <= 1:
        points, weights = np.full((1, n), 1.0 / n), np.ones(1)
    elif degree == 2:
        a = 1.0 / 6.0 if dim == 2 else 0.1381966011250105
        points = np.full((n, n), a)
        np.fill_diagonal(points, 1.0 - dim * a)
        weights = np.full(n, 1.0 / n)
    elif degree == 4:
        points, weights = _degree4(dim)
    else:
        points, weights = _grundmann_moeller(dim, degree // 2)
    points, weights = np.ascontiguousarray(points), np.ascontiguousarray(weights)
    points.setflags(write=False)
    weights.setflags(write=False)
    return points, weights


@lru_cache(maxsize=None)
def gauss_tensor(dim: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n^dim-point Gauss-Legendre rule on [0, 1]^dim (weights sum to 1)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    grids = np.meshgrid(*([x] * dim), indexing="ij")
    wgrids = np.meshgrid(*([w] * dim), indexing="ij")
    points = np.stack([g.ravel() for g in grids], axis=1)
    weights = np.prod(np.stack([g.ravel() for g in wgrids], axis=1), axis=1)
    return points, weights
