"""The steady Reynolds equation of a fracture, the local cubic law (paper 1): in the fracture's
mean plane div(e^3 / (12 mu) grad p) = 0, with e(x, y) the local aperture, on a structured grid
of cells (x fastest).

Finite volumes, one pressure per cell: the flux between two neighbouring cells is
T (p_a - p_b) with the transmissibility T = w / (12 mu int e^-3 ds) along the segment between
their centres (w the face's width); for an aperture constant per cell that integral is exact,
the harmonic mean of e^3 over the two half cells. A fixed-pressure face of the grid closes the
segment at the face (half a cell); any other face passes nothing. Cells with e = 0 are closed
and excluded, and so are open cells that no path connects to a fixed-pressure face (their
pressure is not defined by the flow: they take the nearest solved cell's). One sparse direct
solve (SuperLU, symmetric mode) of the symmetric positive definite system."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage

#: the faces of the plane grid: x (the flow's direction, inlet xmin, outlet xmax) and the other in-plane axis y
PLANE_FACES = ("xmin", "xmax", "ymin", "ymax")


@dataclass
class ReynoldsFlow:
    """The solution: ``pressure`` (ny, nx) [Pa] per cell; ``flux_x`` (ny, nx + 1) [m^3/s]
    through each face normal to x (positive along +x), ``flux_y`` (ny + 1, nx) along +y;
    ``solved`` the cells in the system; ``residual`` ||A p - b|| / ||b|| of the solve;
    ``dropped`` [m^3/s] the given inflow into inlet cells that reach no fixed pressure (taken by
    nothing: not in the solve)."""

    pressure: np.ndarray
    flux_x: np.ndarray
    flux_y: np.ndarray
    solved: np.ndarray
    percolating: bool
    residual: float
    dropped: float = 0.0

    @property
    def flow_rate(self) -> float:
        """Q [m^3/s]: what enters through the inlet face xmin."""
        return float(self.flux_x[:, 0].sum())

    def cell_balance(self) -> np.ndarray:
        """The net outflow of each cell [m^3/s] (zero, to round-off, where the mass is conserved)."""
        return np.diff(self.flux_x, axis=1) + np.diff(self.flux_y, axis=0)


def transmissibilities(aperture: np.ndarray, spacing, viscosity: float):
    """T between neighbours along x (ny, nx - 1) and y (ny - 1, nx), and of the half cells at
    the faces normal to x and to y (ny, nx) each: w / (12 mu int e^-3 ds), 0 across a closed cell."""
    dx, dy = (float(s) for s in spacing)
    e = np.maximum(np.asarray(aperture, float), 0.0)
    open_ = e > 0
    inv = np.full(e.shape, np.inf)
    inv[open_] = e[open_] ** -3.0  # e^-3: the resistance per unit length
    tx = dy / (6.0 * viscosity * dx * (inv[:, :-1] + inv[:, 1:]))  # int e^-3 over two half cells: dx/2 (a + b)
    ty = dx / (6.0 * viscosity * dy * (inv[:-1] + inv[1:]))
    half_x = dy / (6.0 * viscosity * dx * inv)
    half_y = dx / (6.0 * viscosity * dy * inv)
    return tx, ty, half_x, half_y


def percolates(aperture: np.ndarray) -> bool:
    """Whether open cells (e > 0) connect the inlet column (x = 0) with the outlet column
    through shared faces."""
    return _connects(ndimage.label(np.asarray(aperture) > 0)[0])


def _connects(label: np.ndarray) -> bool:
    """Whether a component of `label` (0: none) holds cells of both the first and the last column."""
    return bool(set(np.unique(label[:, 0])) & set(np.unique(label[:, -1])) - {0})


def _boundary_cells(shape) -> dict:
    """The (row, column) index of the cells along each face of the plane grid."""
    ny, nx = shape
    return {"xmin": (slice(None), 0), "xmax": (slice(None), nx - 1), "ymin": (0, slice(None)),
            "ymax": (ny - 1, slice(None))}


def solve(aperture: np.ndarray, spacing, viscosity: float, pressures: dict[str, float],
          inflow: np.ndarray | None = None) -> ReynoldsFlow:
    """The Reynolds flow through the plane grid of apertures ``aperture`` (ny, nx) [m] with cells
    ``spacing`` = (dx, dy) [m], ``viscosity`` mu [Pa s] and the fixed pressure [Pa] of some of the
    faces :data:`PLANE_FACES` (``pressures``; the others closed but xmin given ``inflow``: the
    flow rate (ny,) [m^3/s] into each cell of the inlet column, a fixed inlet velocity)."""
    e = np.maximum(np.asarray(aperture, float), 0.0)
    if e.ndim != 2 or min(e.shape) < 1:
        raise ValueError(f"aperture must be a (ny, nx) array, got shape {e.shape}")
    unknown = set(pressures) - set(PLANE_FACES)
    if unknown:
        raise ValueError(f"unknown faces {sorted(unknown)} (faces: {', '.join(PLANE_FACES)})")
    ny, nx = e.shape
    tx, ty, half_x, half_y = transmissibilities(e, spacing, viscosity)
    half = {"xmin": half_x, "xmax": half_x, "ymin": half_y, "ymax": half_y}
    cells = _boundary_cells(e.shape)
    # the cells in the system: open, and connected to a fixed-pressure face
    label, _ = ndimage.label(e > 0)
    fed = set()
    for face in pressures:
        fed |= set(np.unique(label[cells[face]]))
    solved = np.isin(label, sorted(fed - {0}))
    n = int(solved.sum())
    index = np.full(e.shape, -1)
    index[solved] = np.arange(n)
    diagonal, rhs = np.zeros(n), np.zeros(n)
    rows, cols, vals = [], [], []
    for t, a, b in ((tx, index[:, :-1], index[:, 1:]), (ty, index[:-1], index[1:])):
        both = (a >= 0) & (b >= 0) & (t > 0)
        a, b, t = a[both], b[both], t[both]
        rows += [a, b]
        cols += [b, a]
        vals += [-t, -t]
        np.add.at(diagonal, a, t)
        np.add.at(diagonal, b, t)
    for face, p in pressures.items():
        i, t = index[cells[face]], half[face][cells[face]]
        on = i >= 0
        np.add.at(diagonal, i[on], t[on])
        np.add.at(rhs, i[on], t[on] * float(p))
    fed_inlet, dropped = np.zeros(ny), 0.0
    if inflow is not None:  # into the solved cells only: an open pocket without an outlet takes nothing
        given = np.asarray(inflow, float).reshape(ny)
        fed_inlet = np.where(solved[:, 0], given, 0.0)
        dropped = float(given.sum() - fed_inlet.sum())
        np.add.at(rhs, index[:, 0][solved[:, 0]], fed_inlet[solved[:, 0]])
    pressure = np.zeros(e.shape)
    residual = 0.0
    if n:
        A = sp.csc_matrix((np.concatenate([*vals, diagonal]),
                           (np.concatenate([*rows, np.arange(n)]), np.concatenate([*cols, np.arange(n)]))),
                          shape=(n, n))
        # symmetric positive definite: SuperLU in symmetric mode, a minimum-degree ordering of A + A^T and
        # no pivoting
        factor = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        x = factor.solve(rhs)
        residual = float(np.linalg.norm(A @ x - rhs) / max(np.linalg.norm(rhs), np.finfo(float).tiny))
        pressure[solved] = x
        nearest = ndimage.distance_transform_edt(~solved, return_distances=False, return_indices=True)
        pressure = pressure[tuple(nearest)]
    else:  # nothing open reaches a fixed pressure: no flow
        pressure[:] = pressures.get("xmax", next(iter(pressures.values()), 0.0))
    flux_x, flux_y = np.zeros((ny, nx + 1)), np.zeros((ny + 1, nx))
    p = np.where(solved, pressure, 0.0)
    flux_x[:, 1:-1] = np.where(solved[:, :-1] & solved[:, 1:], tx * (p[:, :-1] - p[:, 1:]), 0.0)
    flux_y[1:-1] = np.where(solved[:-1] & solved[1:], ty * (p[:-1] - p[1:]), 0.0)
    boundary = {"xmin": (flux_x, (slice(None), 0), 1.0), "xmax": (flux_x, (slice(None), nx), -1.0),
                "ymin": (flux_y, (0, slice(None)), 1.0), "ymax": (flux_y, (ny, slice(None)), -1.0)}
    for face, value in pressures.items():  # inflow through xmin / ymin is along +, through xmax / ymax along -
        flux, where, sign = boundary[face]
        c = cells[face]
        flux[where] = sign * np.where(solved[c], half[face][c] * (float(value) - p[c]), 0.0)
    if inflow is not None:
        flux_x[:, 0] = fed_inlet
    return ReynoldsFlow(pressure, flux_x, flux_y, solved, _connects(label), residual, dropped)
