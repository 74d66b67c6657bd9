"""Lattice meshes: graded node coordinates and boxes split into tetrahedra."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..mesh import lattice_tetrahedra


def graded_nodes(start: float, stop: float, h_fine: float, fine_length: float = 0.0,
                 growth: float = 1.25) -> np.ndarray:
    """Node coordinates on [start, stop]: spacing about ``h_fine`` over the first
    ``fine_length`` from ``start``, then cells growing geometrically by a ratio
    of at most ``growth`` (chosen so the last node lands on ``stop``). Pass
    start > stop to refine toward the upper end (the nodes then run from start
    to stop; :func:`solid_fenicsx.mesh.box_mesh` sorts its axes)."""
    length = abs(stop - start)
    if h_fine <= 0 or length <= 0 or growth < 1:
        raise ValueError("graded_nodes needs h_fine > 0, start != stop and growth >= 1")
    fine_length = min(max(fine_length, 0.0), length)
    n_fine = int(round(fine_length / h_fine))
    fine = np.linspace(0.0, fine_length, n_fine + 1) if n_fine else np.zeros(1)
    h = fine_length / n_fine if n_fine else h_fine
    rest = length - fine[-1]
    if rest <= 1e-12 * length:
        x = fine
    elif growth == 1.0 or rest <= h * growth * 1.5:
        n = max(1, int(round(rest / h)))
        x = np.concatenate([fine, fine[-1] + np.linspace(0, rest, n + 1)[1:]])
    else:
        k0 = 1 if n_fine else 0  # first coarse cell: h * r (after fine cells) or h
        n = 1
        while h * sum(growth ** k for k in range(k0, k0 + n)) < rest:
            n += 1
        lo, hi = 1.0, growth  # ratio r with h * (r^k0 + ... + r^(k0+n-1)) = rest
        for _ in range(100):
            r = 0.5 * (lo + hi)
            lo, hi = (r, hi) if h * sum(r ** k for k in range(k0, k0 + n)) < rest else (lo, r)
        steps = h * r ** np.arange(k0, k0 + n)
        steps *= rest / steps.sum()
        x = np.concatenate([fine, fine[-1] + np.cumsum(steps)])
    x[-1] = length
    return start + np.sign(stop - start) * x


def box_arrays(axes: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Points and tetrahedra of a lattice with node coordinates ``axes`` = (xs, ys, zs)
    (each increasing); every lattice hexahedron is split into six tets."""
    xs, ys, zs = (np.asarray(a, float) for a in axes)
    for a in (xs, ys, zs):
        if len(a) < 2 or np.any(np.diff(a) <= 0):
            raise ValueError("box node coordinates must be increasing, at least two per axis")
    nx, ny, nz = len(xs) - 1, len(ys) - 1, len(zs) - 1
    Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])  # x fastest
    return points, lattice_tetrahedra((nx, ny, nz))
