"""Quadrature rules: on simplices (the pieces of element intersections) and
tensor Gauss rules on [0, 1]^d (element mass matrices of Q1 cells).

Simplex rules are returned in barycentric coordinates with weights summing to
one (they are multiplied by the measure of the simplex). Degree 1 is the
centroid, degree 2 the symmetric positive rule, degree 4 Dunavant's 6-point
(triangle) and Keast's 11-point (tetrahedron) rules, other degrees the
Grundmann-Moeller rules (exact to degree 2s+1, some weights negative).
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations_with_replacement
from math import factorial

import numpy as np


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
