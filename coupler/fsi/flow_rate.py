"""The flow through a fracture on the fluid grid: the volume flow rate through the cross-sections
x = const (inlet xmin to outlet xmax) and whether an open path connects them (percolation).

Both take the cells of a `block` of the grid (``(lower, upper)`` cell indices, the whole grid by
default) and `comm`: on several ranks each gives its block, blocks that tile the grid (the
coupler's slabs along one axis: :class:`coupler.fsi.ranks.GridSlab`), and the result is the
whole grid's on every rank; ``comm=None`` is the serial code."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums
from transfer.labels import box_bounds, label_boxes


def _cells(grid, values, block) -> np.ndarray:
    """`values` at the cells of `block` (x fastest) as a (z, y, x) array."""
    lower, upper = box_bounds(grid.shape, block)
    nx, ny, nz = upper - lower
    return np.asarray(values).reshape(nz, ny, nx)


def section_flow_rates(grid, velocity: np.ndarray, block=None, comm=None) -> np.ndarray:
    """The volume flow rate Q [m^3/s] through each cross-section x = const of `grid`, one per
    column of cells along x: the cells' x velocity times their face area dy dz, summed over the
    section (over the ranks' blocks with `comm`: one allreduce of nx numbers)."""
    lower, upper = box_bounds(grid.shape, block)
    sections = np.zeros(grid.shape[0])
    sections[lower[0]:upper[0]] = _cells(grid, np.asarray(velocity)[:, 0], block).sum(axis=(0, 1))
    return RowSums(comm).sum(sections) * grid.spacing[1] * grid.spacing[2]


def percolates(grid, fraction: np.ndarray, solid: float = 0.5, block=None, comm=None) -> bool:
    """Whether the open cells (solid fraction below `solid`) connect the inlet column (x = 0)
    with the outlet column (the last one) through shared cell faces. With `comm` each rank labels
    its block, the labels joined across the blocks' faces (:func:`transfer.labels.label_boxes`:
    planes, not volumes), and the ranks allgather the labels on their inlet and outlet columns,
    so every rank decides alike."""
    lower, upper = box_bounds(grid.shape, block)
    label, _ = label_boxes(_cells(grid, fraction, block) < solid, grid.shape, (lower, upper), comm)
    ends = (np.unique(label[:, :, 0]) if lower[0] == 0 else np.zeros(0, int),
            np.unique(label[:, :, -1]) if upper[0] == grid.shape[0] else np.zeros(0, int))
    found = comm.allgather(ends) if comm is not None and comm.Get_size() > 1 else [ends]
    inlet, outlet = ({int(c) for part in found for c in part[end] if c > 0} for end in (0, 1))
    return bool(inlet & outlet)
