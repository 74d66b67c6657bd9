"""Quadrature rules: on simplices (the pieces of element intersections) and
tensor Gauss rules on [0, 1]^d (element mass matrices of Q1 cells).

Simplex rules are returned in barycentric coordinates with weights summing to
one (they are multiplied by the measure of the simplex). Degree 1 is the
centroid, degree 2 the symmetric positive rule, higher degrees the
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
