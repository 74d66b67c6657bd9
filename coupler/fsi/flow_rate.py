"""The flow through a fracture on the fluid grid: the volume flow rate through the cross-sections
x = const (inlet xmin to outlet xmax) and whether an open path connects them (percolation)."""

from __future__ import annotations

import numpy as np


def section_flow_rates(grid, velocity: np.ndarray) -> np.ndarray:
    """The volume flow rate Q [m^3/s] through each cross-section x = const of `grid`, one per
    column of cells along x: the cells' x velocity times their face area dy dz, summed over the
    section."""
    nx, ny, nz = grid.shape
    ux = np.asarray(velocity)[:, 0].reshape(nz, ny, nx)
    return ux.sum(axis=(0, 1)) * grid.spacing[1] * grid.spacing[2]


def percolates(grid, fraction: np.ndarray, solid: float = 0.5) -> bool:
    """Whether the open cells (solid fraction below `solid`) connect the inlet column (x = 0)
    with the outlet column (the last one) through shared cell faces."""
    from scipy import ndimage

    nx, ny, nz = grid.shape
    label, _ = ndimage.label(np.asarray(fraction).reshape(nz, ny, nx) < solid)
    inlet, outlet = set(np.unique(label[:, :, 0])), set(np.unique(label[:, :, -1]))
    return bool((inlet & outlet) - {0})
