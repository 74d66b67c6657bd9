"""The flow through a fracture on the fluid grid: the volume flow rate through the cross-sections
x = const (inlet xmin to outlet xmax) and whether an open path connects them (percolation).

Both take the cells of a `block` of the grid (``(lower, upper)`` cell indices, the whole grid by
default) and `comm`: on several ranks each gives its block, blocks that tile the grid (the
coupler's slabs along one axis: :class:`coupler.fsi.ranks.GridSlab`), and the result is the
whole grid's on every rank; ``comm=None`` is the serial code."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

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


def column_open_lengths(grid, fraction: np.ndarray, across: int, block=None, comm=None) -> np.ndarray:
    """Each column of cells across the fracture (axis `across`, 1 or 2): its open length, the sum
    of (1 - solid fraction) h over the column (the local aperture e of the fracture plane, as
    the Reynolds fluid reads it), as a 2-D array whose last axis is x (inlet to outlet); the
    whole grid's on every rank (one allreduce of the plane)."""
    lower, upper = box_bounds(grid.shape, block)
    axis = 2 - across  # of the (z, y, x) cells
    local = (1.0 - _cells(grid, fraction, block)).sum(axis=axis) * grid.spacing[across]
    kept = [d for d in (2, 1, 0) if d != across]
    plane = np.zeros([grid.shape[d] for d in kept])
    plane[tuple(slice(lower[d], upper[d]) for d in kept)] = local
    return RowSums(comm).sum(plane)


def throat_aperture(lengths: np.ndarray) -> float:
    """The narrowest opening of the widest open path from the inlet (first index of the last axis)
    to the outlet (its last index) through columns sharing a side: the largest e such that the
    columns open by at least e connect them (0 when none do)."""

    def connects(e: float) -> bool:
        label, _ = ndimage.label(lengths >= e)
        return bool((set(np.unique(label[:, 0])) & set(np.unique(label[:, -1]))) - {0})

    values = np.unique(lengths[lengths > 0])
    if values.size == 0 or not connects(values[0]):
        return 0.0
    lo, hi = 0, values.size - 1  # connects(values[lo]) holds; find the largest such index
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if connects(values[mid]) else (lo, mid - 1)
    return float(values[lo])
