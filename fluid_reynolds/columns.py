"""The fluid grid seen from the fracture's mean plane: its columns across the fracture (along the
grid's thinner extent of y and z, :func:`transfer.grid.across_axis`; a 2D grid's single cell is in the plane),
the local
aperture of each column and the plane grid the Reynolds equation is solved on.

The aperture of a column is its open length, the integral of (1 - solid fraction) across the
grid: with the coupler's exact solid fractions of the deformed solid, the mean gap between the
faces over the column (zero where they touch). A plane grid of another resolution takes the
columns' apertures and gives back its pressure and flux by the L2 projection between the two
(Q0 on both, :class:`transfer.Transfer`, conservative)."""

from __future__ import annotations

import numpy as np

from transfer import FunctionSpace, StructuredGrid, Transfer
from transfer.grid import across_axis


class Columns:
    """The columns of `grid` across the fracture and the plane grid of ``resolution`` = [n_x, n_y]
    cells (None: one cell per column). Plane arrays are (n_y, n_x), y the other in-plane axis."""

    def __init__(self, grid: StructuredGrid, resolution=None):
        self.grid = grid
        self.across = across_axis(grid.shape, grid.spacing)
        self.side = 3 - self.across  # the in-plane axis besides x
        shape, spacing = np.asarray(grid.shape), np.asarray(grid.spacing, float)
        self.height = float(spacing[self.across] * shape[self.across])
        self.columns = (int(shape[self.side]), int(shape[0]))
        self.plane = self.columns if resolution is None else (int(resolution[1]), int(resolution[0]))
        extent = (float(spacing[0] * shape[0]), float(spacing[self.side] * shape[self.side]))
        self.spacing = (extent[0] / self.plane[1], extent[1] / self.plane[0])
        self.faces = ("xmin", "xmax") + (("ymin", "ymax") if self.side == 1 else ("zmin", "zmax"))
        self.down = self.up = None
        if self.plane != self.columns:
            columns, plane = (FunctionSpace(self.layer(n), "Q0") for n in (self.columns, self.plane))
            self.down, self.up = Transfer.assemble(columns, plane, "l2"), Transfer.assemble(plane, columns, "l2")

    def layer(self, cells) -> StructuredGrid:
        """A grid of one layer across the fracture, (n_y, n_x) cells in the plane: its cells
        numbered as a plane array's (C order)."""
        g = self.grid
        shape, spacing = list(g.shape), np.asarray(g.spacing, float) * np.asarray(g.shape)
        shape[0], shape[self.side], shape[self.across] = cells[1], cells[0], 1
        return StructuredGrid(g.origin, spacing / np.asarray(shape), shape)

    def cells(self, values: np.ndarray) -> np.ndarray:
        """Per-cell values of the fluid grid (x fastest) as (n_z, n_y, n_x)."""
        nx, ny, nz = self.grid.shape
        return np.asarray(values, float).reshape(nz, ny, nx)

    def aperture(self, fraction: np.ndarray) -> np.ndarray:
        """The plane grid's apertures [m] from the solid fraction of the fluid grid's cells."""
        open_ = 1.0 - np.clip(self.cells(fraction), 0.0, 1.0)
        length = open_.sum(axis=2 - self.across) * self.grid.spacing[self.across]
        return self.to_plane(length)

    def to_plane(self, columns: np.ndarray) -> np.ndarray:
        return columns if self.down is None else self.down(columns.ravel()).reshape(self.plane)

    def to_columns(self, plane: np.ndarray) -> np.ndarray:
        return plane if self.up is None else self.up(plane.ravel()).reshape(self.columns)

    def spread(self, plane: np.ndarray) -> np.ndarray:
        """A plane field given to every cell of its column (x fastest)."""
        columns = self.to_columns(plane)
        nx, ny, nz = self.grid.shape
        spread = columns[None] if self.across == 2 else columns[:, None, :]
        return np.broadcast_to(spread, (nz, ny, nx)).ravel()

    def velocity(self, flux_x: np.ndarray, flux_y: np.ndarray, fraction: np.ndarray) -> np.ndarray:
        """The cells' velocity (n_cells, 3) [m/s] that carries the plane's flux: the flux per unit
        width at the plane cells' centres (the mean of their two faces'), on each column, shared
        among its cells by their open share (evenly in a closed column), so the cells of a
        cross-section x = const pass what the plane passes there."""
        dx, dy = self.spacing
        per_width = [self.to_columns(0.5 * (flux_x[:, :-1] + flux_x[:, 1:]) / dy),
                     self.to_columns(0.5 * (flux_y[:-1] + flux_y[1:]) / dx)]
        open_ = 1.0 - np.clip(self.cells(fraction), 0.0, 1.0)
        axis = 2 - self.across
        total = open_.sum(axis=axis, keepdims=True)
        n = self.grid.shape[self.across]
        share = np.divide(open_, total, out=np.full_like(open_, 1.0 / n), where=total > 0)
        h = float(self.grid.spacing[self.across])
        velocity = np.zeros((open_.size, 3))
        for component, q in zip((0, self.side), per_width):
            q = q[None] if self.across == 2 else q[:, None, :]
            velocity[:, component] = (q * share / h).ravel()
        return velocity
