"""Drag (volume penalization) fields from solid volume fractions, for the fluids on the grid.

A fluid participant adds ``-D (U - U_s)`` (kinematic, per cell, ``U_s`` the solid's velocity)
to its momentum equation, ``D = T D_max``: ``T`` in [0, 1] comes from the cell's solid volume
fraction (exact, from :mod:`transfer`) and ``D_max`` (1/s) from :func:`default_drag` unless a
scene gives it. The OpenFOAM fluid writes ``T`` as its ``solid`` field under the linear
``solidification`` table ``[(0, 0), (1, D_max)]``; the Chorin fluid multiplies it out. Modes
(``"penalization"`` in the fluid config):

``"linear"``
    ``T = f`` (the solid fraction). Because ``D_max`` is huge (about 1e4 viscous rates of
    a cell), even a cell with f = 0.01 is nearly stopped: the immersed wall sits, in
    effect, at the centre of the first cell the solid touches. First order, up to a cell
    of error in the wall position.
``"power"``
    ``T = f**k`` (``"penalization_exponent"`` k). Still first order: the wall moves with
    ``k`` but not to the right place for every fraction.
``"wall"`` (default)
    A sub-cell wall position from the fractions, along each grid axis. Cells whose centre
    is in the solid (f >= 1/2) get ``D_max`` (velocity ~ 0 at their centre). A fluid-centred
    cell c (f < 1/2) whose neighbour s along axis a (spacing h) is solid-centred sees, with
    the viscous flux of the discrete Laplacian, a wall at the centre of s (distance h). The
    true wall lies at ``d = h (3/2 - f_c - f_s)`` from c's centre (exact in 1D: either the
    wall crosses c, then f_s = 1 and d = (1/2 - f_c) h, or it crosses s, then f_c = 0 and
    d = (3/2 - f_s) h). The drag ``D_c = nu / h^2 (h / d - 1)`` adds the missing wall shear
    ``nu u_c / d - nu u_c / h`` per unit area, so the wall flux is ``nu u_c / d``: the
    standard cell-centred wall treatment, at the sub-cell position. Terms of both sides
    and all axes add up. ``d`` is clipped to ``[h / 50, h]``. For walls aligned with a grid
    axis this is second order (measured in cases/parallel_plates); for oblique walls it is a
    per-axis approximation. A solid sliver with no solid-centred cell is not seen.
"""

from __future__ import annotations

import numpy as np

from .grid import cell_ijk, wall_distance

#: how solid volume fractions become drag (the modes above)
PENALIZATIONS = ("wall", "linear", "power")
#: how many cells away along each axis :func:`drag_fraction` of a cell reads fractions, per mode
REACH = {"wall": 1, "linear": 0, "power": 0}


def default_drag(nu: float, h_min: float, u_ref: float = 0.0, rate: float = 0.0) -> float:
    """``D_max = 1e4 max(nu / h_min^2, rate, u_ref / h_min)`` [1/s]: ``nu/h^2`` is the viscous
    relaxation rate of one cell, ``rate`` the time-step rate ``1/dt`` of a transient solver,
    ``u_ref/h`` the advective rate (``u_ref`` the inlet speed, if given). A fully solid cell then
    carries a velocity about 1e-4 of its fluid neighbours' (relative to its solid velocity)."""
    return 1.0e4 * max(nu / h_min ** 2, rate, u_ref / h_min)


def drag_fraction(fraction, shape, spacing, nu: float, d_max: float, mode: str,
                  exponent: float | None = None) -> np.ndarray:
    """The field ``T`` in [0, 1] (written as ``solid``) for the table ``[(0, 0), (1, d_max)]``.
    ``fraction`` is per cell, x fastest; ``shape`` (nx, ny, nz) and ``spacing`` of the grid;
    ``mode`` and ``exponent`` (of ``"power"``) as the participant's settings declare them."""
    f = np.clip(np.asarray(fraction, dtype=np.float64).reshape(-1), 0.0, 1.0)
    if mode == "linear":
        return f
    if mode == "power":
        return f ** float(exponent)
    if mode != "wall":
        raise ValueError(f"unknown penalization {mode!r} (one of {', '.join(PENALIZATIONS)})")
    nx, ny, nz = (int(s) for s in shape)
    F = f.reshape(nz, ny, nx)  # [k, j, i]
    solid = F >= 0.5
    D = np.zeros_like(F)
    for axis, h in zip((2, 1, 0), np.asarray(spacing, dtype=float)):  # x, y, z
        n = F.shape[axis]
        if n < 2:
            continue
        for side in (1, -1):
            # neighbour along axis on this side: s[c] = F[c + side]
            sl_c = [slice(None)] * 3
            sl_s = [slice(None)] * 3
            sl_c[axis] = slice(0, n - 1) if side == 1 else slice(1, n)
            sl_s[axis] = slice(1, n) if side == 1 else slice(0, n - 1)
            fc, fs = F[tuple(sl_c)], F[tuple(sl_s)]
            hit = (fc < 0.5) & (fs >= 0.5)
            d = wall_distance(fc, fs, h)
            D[tuple(sl_c)] += np.where(hit, nu / h ** 2 * (h / d - 1.0), 0.0)
    T = np.where(solid, 1.0, np.minimum(D / d_max, 1.0))
    return T.reshape(-1)


def reach(cells, shape, mode: str, at_least: int = 0) -> np.ndarray:
    """The cells whose fractions :func:`drag_fraction` of ``cells`` reads (grid indices, x fastest,
    sorted): each cell and those within ``REACH[mode]`` cells of it along each axis, or within
    ``at_least`` cells (another stencil read with it: a rigid body's interface layer, 1)."""
    cells = np.asarray(cells, dtype=np.int64).reshape(-1)
    ijk, found = cell_ijk(cells, shape), [cells]
    nx, ny, _ = (int(s) for s in shape)
    layers = max(REACH[mode], at_least)
    for axis, n in enumerate(int(s) for s in shape):
        for step in (s for s in range(-layers, layers + 1) if s):
            moved = ijk[(ijk[:, axis] + step >= 0) & (ijk[:, axis] + step < n)].copy()
            moved[:, axis] += step
            found.append((moved[:, 2] * ny + moved[:, 1]) * nx + moved[:, 0])
    return np.unique(np.concatenate(found))


def drag_fraction_of(cells, ids, fraction, shape, spacing, nu: float, d_max: float, mode: str,
                     exponent: float | None = None) -> np.ndarray:
    """:func:`drag_fraction` of the grid's ``cells`` (grid indices) from the fractions at ``ids``
    only (``fraction[k]`` of cell ``ids[k]``; ``ids`` must hold :func:`reach` of ``cells``): the
    same values as on the whole grid, computed on the box around ``ids`` (other cells of the box
    are read as fluid; none is within reach of ``cells``)."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    cells = np.asarray(cells, dtype=np.int64).reshape(-1)
    at = cell_ijk(ids, shape)
    lo = at.min(axis=0) if len(ids) else np.zeros(3, np.int64)
    box = (at.max(axis=0) + 1 - lo) if len(ids) else np.ones(3, np.int64)

    def local(ijk):
        ijk = ijk - lo
        return (ijk[:, 2] * box[1] + ijk[:, 1]) * box[0] + ijk[:, 0]

    F = np.zeros(int(np.prod(box)))
    F[local(at)] = np.asarray(fraction, dtype=np.float64).reshape(-1)
    return drag_fraction(F, box, spacing, nu, d_max, mode, exponent)[local(cell_ijk(cells, shape))]
