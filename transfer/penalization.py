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
``"lubrication"``
    For pressure-driven flow along a gap (a fracture): each column's gap across it
    (:func:`transfer.grid.across_axis`) made plates at the column's mean walls
    (:func:`plates_fraction`), then the ``"wall"`` drag, except that the two cut cells of each
    gap (the end cells of its run of fluid-centred cells) get the drag that gives the column the
    lubrication conductance of its local opening, ``e^3 / (12 nu)`` (the cubic law, paper
    section 4.2's ``e_h``; ``e`` the column's open length): exact for plates at any resolution
    and wall offset (:func:`cut_cell_drag`), where the wall mode's conductance errs by
    ``O(h^2 / e^2)``, and it is the throats of a rough gap, a few cells across, that set its flow.
    The Chorin fluid also gives the faces in the gap's plane their own columns' drag
    (:func:`face_fraction`). A shear-driven flow or an immersed body's wall keeps ``"wall"`` (the
    default): the calibration is for a uniform pressure gradient along the gap. The drag can be
    slightly negative (to ``-nu / (2 h^2)``, where both walls lie near the centres of solid
    cells); the OpenFOAM fluid's table clips it at zero there.
"""

from __future__ import annotations

import numpy as np

from .grid import across_axis, cell_ijk, wall_distance

#: how solid volume fractions become drag (the modes above)
PENALIZATIONS = ("wall", "linear", "power", "lubrication")
#: how many cells away along each axis :func:`drag_fraction` of a cell reads fractions, per mode
#: (and along the axis across the gap, the whole line of cells, in the modes of :data:`LINES`)
REACH = {"wall": 1, "linear": 0, "power": 0, "lubrication": 1}
#: the modes whose drag of a cell reads the whole line of cells across the gap through it
LINES = ("lubrication",)


def default_drag(nu: float, h_min: float, u_ref: float = 0.0, rate: float = 0.0) -> float:
    """``D_max = 1e4 max(nu / h_min^2, rate, u_ref / h_min)`` [1/s]: ``nu/h^2`` is the viscous
    relaxation rate of one cell, ``rate`` the time-step rate ``1/dt`` of a transient solver,
    ``u_ref/h`` the advective rate (``u_ref`` the inlet speed, if given). A fully solid cell then
    carries a velocity about 1e-4 of its fluid neighbours' (relative to its solid velocity)."""
    return 1.0e4 * max(nu / h_min ** 2, rate, u_ref / h_min)


def drag_fraction(fraction, shape, spacing, nu: float, d_max: float, mode: str,
                  exponent: float | None = None, across: int | None = None) -> np.ndarray:
    """The field ``T`` in [0, 1] (written as ``solid``) for the table ``[(0, 0), (1, d_max)]``
    (``"lubrication"``: at least ``-nu / (2 h^2 d_max)``).
    ``fraction`` is per cell, x fastest; ``shape`` (nx, ny, nz) and ``spacing`` of the grid;
    ``mode`` and ``exponent`` (of ``"power"``) as the participant's settings declare them;
    ``across`` the axis across the gap (``"lubrication"``; none: :func:`across_axis` of ``shape``)."""
    f = np.clip(np.asarray(fraction, dtype=np.float64).reshape(-1), 0.0, 1.0)
    if mode == "linear":
        return f
    if mode == "power":
        return f ** float(exponent)
    if mode not in ("wall", "lubrication"):
        raise ValueError(f"unknown penalization {mode!r} (one of {', '.join(PENALIZATIONS)})")
    nx, ny, nz = (int(s) for s in shape)
    F = f.reshape(nz, ny, nx)  # [k, j, i]
    spacing = np.asarray(spacing, dtype=float)
    gap = None if mode == "wall" else 2 - (across_axis(shape, spacing) if across is None else int(across))
    if gap is not None:
        F = plates_fraction(F, gap)
    D = np.zeros_like(F)
    for axis, h in zip((2, 1, 0), spacing):  # x, y, z
        if F.shape[axis] > 1:
            wall = wall_drag(F, axis, h, nu)
            D += wall if axis != gap else cut_cell_drag(F, axis, h, nu, wall)
    T = np.where(F >= 0.5, 1.0, np.minimum(D / d_max, 1.0))
    return T.reshape(-1)


def runs(lines):
    """The runs of fluid-centred cells (fraction < 1/2) in the rows of ``lines``: their row, first
    and last cell, in order (row by row, along each row)."""
    fluid = lines < 0.5
    solid_before = np.pad(~fluid[:, :-1], ((0, 0), (1, 0)), constant_values=True)
    solid_after = np.pad(~fluid[:, 1:], ((0, 0), (0, 1)), constant_values=True)
    line, lo = np.nonzero(fluid & solid_before)
    return line, lo, np.nonzero(fluid & solid_after)[1]


def plates_fraction(F, axis: int) -> np.ndarray:
    """The fractions ``F`` (``[k, j, i]``) with each gap across ``axis`` made two flat walls: a run of
    fluid-centred cells between two solid-centred ones, with the solid on each side of it up to the
    middle of the solid before the next run (or the line's end), gets the exact fractions of the
    plates whose walls hold as much solid on each side of the run's middle. The open length and
    its mean position are kept; a wall spread over many cells (a face sloped within its column,
    cells partly solid deep into the gap) becomes the column's mean wall, whose cut cells
    :func:`cut_cell_drag` calibrates. Plates are left as they are; other lines too."""
    n = F.shape[axis]
    lines = np.moveaxis(F, axis, -1).reshape(-1, n)
    line, lo, hi = runs(lines)
    if not len(line):
        return F
    same = line[1:] == line[:-1]
    start = np.zeros(len(line), np.int64)
    start[1:] = np.where(same, (hi[:-1] + 1 + lo[1:]) // 2, 0)  # the solid between two runs split in the middle
    end = np.full(len(line), n, np.int64)
    end[:-1] = np.where(same, start[1:], n)
    mid = (lo + hi + 1) // 2
    solid = np.pad(np.cumsum(lines, axis=1), ((0, 0), (1, 0)))
    z_lo = start + solid[line, mid] - solid[line, start]  # the walls [cells from the line's start]
    z_hi = end - (solid[line, end] - solid[line, mid])
    first = np.zeros(lines.size, np.int64)  # each cell's run (+1), 0 on lines without one
    first[line * n + start] = np.arange(1, len(line) + 1)
    seg = np.maximum.accumulate(first).reshape(lines.shape) - 1
    seg[~np.isin(np.arange(len(lines)), line)] = -1
    bounded = (lo > 0) & (hi < n - 1)
    at = (seg >= 0) & bounded[np.maximum(seg, 0)]
    k = np.broadcast_to(np.arange(n, dtype=float), lines.shape)[at]
    r = seg[at]
    out = lines.copy()
    out[at] = 1.0 - np.clip(np.minimum(k + 1.0, z_hi[r]) - np.maximum(k, z_lo[r]), 0.0, 1.0)
    return np.moveaxis(out.reshape(np.moveaxis(F, axis, -1).shape), -1, axis)


def wall_drag(F, axis: int, h: float, nu: float) -> np.ndarray:
    """The ``"wall"`` mode's drag [1/s] along ``axis`` of the array ``F`` of fractions, spacing ``h``:
    ``nu / h^2 (h / d - 1)`` per solid-centred neighbour of a fluid-centred cell (the module doc)."""
    n, D = F.shape[axis], np.zeros_like(F)
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
    return D


def cut_cell_drag(F, axis: int, h: float, nu: float, wall) -> np.ndarray:
    """The ``"lubrication"`` mode's drag [1/s] along ``axis`` (across the gap): ``wall`` (the
    ``"wall"`` drag along it) with the end cells of each run of ``m`` fluid-centred cells between
    two solid-centred ones replaced so that the run's discrete flow under a uniform pressure
    gradient G, ``nu (u[k+1] - 2 u[k] + u[k-1]) / h^2 - D[k] u[k] = -G`` (``u = 0`` in the solid
    cells: the cell-centred stencil of the MAC grid's in-plane faces and of OpenFOAM's cells),
    carries ``h sum(u) = G e^3 / (12 nu)``, ``e`` the open length of the run and its two ends.

    With ``D = 0`` inside the run the discrete ``u`` is a quadratic in the cell index ``k``,
    ``u[k] = G h^2 / (2 nu) (k + p) (q - k)``, and each end row holds for one drag:
    ``D_lo = nu / h^2 (1 - p) (q + 1) / (p q)`` at ``k = 0``, the mirror image at ``k = m - 1``.
    Its sum is ``m p q + (q - p) m (m - 1) / 2 - m (m - 1) (2m - 1) / 6``, set to ``(e / h)^3 / 6``
    with ``q - p`` kept at the distance between the walls' sub-cell positions (:func:`wall_distance`,
    rescaled to add up to ``e``): both roots move by the same amount, a quadratic equation in
    closed form per run. A single cell (``m = 1``) gets ``nu / h^2 (12 h^3 / e^3 - 2)``. Runs
    without a root at least inside the run's end cells (an opening too thin for its cells) and
    runs that reach the grid's end keep ``wall``."""
    n = F.shape[axis]
    lines = np.moveaxis(F, axis, -1).reshape(-1, n)
    D = np.moveaxis(wall, axis, -1).reshape(-1, n).copy()
    line, lo, hi = runs(lines)
    inside = (lo > 0) & (hi < n - 1)
    line, lo, hi = line[inside], lo[inside], hi[inside]
    m = (hi - lo + 1).astype(float)
    opened = np.pad(np.cumsum(1.0 - lines, axis=1), ((0, 0), (1, 0)))
    E = (opened[line, hi + 2] - opened[line, lo - 1])  # the open length in cells
    a = wall_distance(lines[line, lo], lines[line, lo - 1], h) / h
    b = wall_distance(lines[line, hi], lines[line, hi + 1], h) / h
    t = E - (m - 1.0)  # the walls' parts beyond the end cells' centres
    half = (m - 1.0 + t * (b - a) / (a + b)) / 2.0  # (q - p) / 2
    with np.errstate(invalid="ignore", divide="ignore"):
        R = (E ** 3 / 6.0 - half * m * (m - 1.0) + m * (m - 1.0) * (2.0 * m - 1.0) / 6.0) / m  # p q
        r = np.sqrt(R + half ** 2)
        p, q = r - half, r + half
        top = q - (m - 1.0)
        d_lo = (1.0 - p) * (q + 1.0) / (p * q)
        d_hi = (1.0 - top) * (p + m) / (top * (p + m - 1.0))
    single = m == 1
    d_lo = np.where(single, 12.0 / E ** 3 - 2.0, d_lo)
    ok = single | ((t > 0) & (p > 0) & (top > 0) & np.isfinite(d_lo) & np.isfinite(d_hi))
    least = -0.5  # the single cell's lowest (e = 2 h); never below it
    D[line[ok], lo[ok]] = nu / h ** 2 * np.maximum(d_lo[ok], least)
    many = ok & ~single
    D[line[many], hi[many]] = nu / h ** 2 * np.maximum(d_hi[many], least)
    return np.moveaxis(D.reshape(np.moveaxis(F, axis, -1).shape), -1, axis)


def face_fraction(F, axis: int) -> np.ndarray:
    """The solid fractions of the faces normal to array axis ``axis`` of the cells' fractions
    ``F`` (``[k, j, i]``; a face per cell boundary, the grid's boundary faces included): the larger
    of the two cells' (the cell's own on the boundary). Between two columns across a gap whose
    walls differ (a step of the grid's staircase) a face is open over the overlap of the two
    openings, as it is in the limit of fine cells across, where a face next to a solid-centred
    cell is closed; the ``"lubrication"`` drag of these faces gives each face column the cubic
    law of that overlap (a MAC grid's in-plane faces; measured in cases/hm_fracture's README). A
    wall sloped along the flow becomes a staircase whose steps pass the smaller opening: first
    order in the spacing in the plane (cases/lubrication along the flow: -1.6 % in e_h)."""
    F = np.asarray(F, dtype=np.float64)
    n = F.shape[axis]
    padded = np.concatenate([np.take(F, [0], axis=axis), F, np.take(F, [n - 1], axis=axis)], axis=axis)
    return np.maximum(np.take(padded, np.arange(n + 1), axis=axis), np.take(padded, np.arange(1, n + 2), axis=axis))


def reach(cells, shape, mode: str, at_least: int = 0, across: int | None = None) -> np.ndarray:
    """The cells whose fractions :func:`drag_fraction` of ``cells`` reads (grid indices, x fastest,
    sorted): each cell and those within ``REACH[mode]`` cells of it along each axis, or within
    ``at_least`` cells (another stencil read with it: a rigid body's interface layer, 1); in the
    modes of :data:`LINES` also the whole lines along the axis ``across`` the gap through each of
    them (:func:`transfer.grid.across_axis`; required there)."""
    if mode in LINES and across is None:
        raise ValueError(f"reach of penalization {mode!r} needs the axis across the gap")
    cells = np.asarray(cells, dtype=np.int64).reshape(-1)
    ijk, found = cell_ijk(cells, shape), [cell_ijk(cells, shape)]
    sizes = [int(s) for s in shape]
    layers = max(REACH[mode], at_least)
    for axis, n in enumerate(sizes):
        for step in (s for s in range(-layers, layers + 1) if s):
            moved = ijk[(ijk[:, axis] + step >= 0) & (ijk[:, axis] + step < n)].copy()
            moved[:, axis] += step
            found.append(moved)
    ijk = np.unique(np.concatenate(found), axis=0)
    if mode in LINES:
        lines = np.unique(np.delete(ijk, across, axis=1), axis=0)
        k = np.repeat(np.arange(sizes[across]), len(lines))
        ijk = np.insert(np.tile(lines, (sizes[across], 1)), across, k, axis=1)
    nx, ny = sizes[0], sizes[1]
    return np.unique((ijk[:, 2] * ny + ijk[:, 1]) * nx + ijk[:, 0])


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
    T = drag_fraction(F, box, spacing, nu, d_max, mode, exponent, across_axis(shape, spacing))
    return T[local(cell_ijk(cells, shape))]
