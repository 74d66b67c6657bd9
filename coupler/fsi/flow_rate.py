"""The flow through a fracture on the fluid grid: the volume flow rate through the cross-sections
x = const (inlet xmin to outlet xmax) and whether an open path connects them (percolation).

Both take the cells of a `block` of the grid (``(lower, upper)`` cell indices, the whole grid by
default) and `comm`: on several ranks each gives its block, slabs along one axis that tile the
grid (:class:`coupler.fsi.ranks.GridSlab`), and the result is the whole grid's on every rank;
``comm=None`` is the serial code."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums


def _block(grid, block) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) cell indices of `block`, the whole grid when None."""
    if block is None:
        return np.zeros(3, np.int64), np.asarray(grid.shape, np.int64)
    return np.asarray(block[0], np.int64), np.asarray(block[1], np.int64)


def _cells(grid, values, block) -> np.ndarray:
    """`values` at the cells of `block` (x fastest) as a (z, y, x) array."""
    lower, upper = _block(grid, block)
    nx, ny, nz = upper - lower
    return np.asarray(values).reshape(nz, ny, nx)


def section_flow_rates(grid, velocity: np.ndarray, block=None, comm=None) -> np.ndarray:
    """The volume flow rate Q [m^3/s] through each cross-section x = const of `grid`, one per
    column of cells along x: the cells' x velocity times their face area dy dz, summed over the
    section (over the ranks' blocks with `comm`: one allreduce of nx numbers)."""
    lower, upper = _block(grid, block)
    sections = np.zeros(grid.shape[0])
    sections[lower[0]:upper[0]] = _cells(grid, np.asarray(velocity)[:, 0], block).sum(axis=(0, 1))
    return RowSums(comm).sum(sections) * grid.spacing[1] * grid.spacing[2]


def percolates(grid, fraction: np.ndarray, solid: float = 0.5, block=None, comm=None) -> bool:
    """Whether the open cells (solid fraction below `solid`) connect the inlet column (x = 0)
    with the outlet column (the last one) through shared cell faces. With `comm` each rank labels
    its block, the ranks allgather their labels on the inlet, the outlet and the block's two end
    planes along the slab axis (planes, not volumes), and every rank joins the labels that
    meet across a cut and decides alike."""
    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    lower, upper = _block(grid, block)
    label, count = ndimage.label(_cells(grid, fraction, block) < solid)
    cut = np.flatnonzero(upper - lower != np.asarray(grid.shape))  # the slab axis (none: the whole grid)
    axis = int(cut[0]) if len(cut) else 0
    mine = {"count": count, "lower": lower, "upper": upper,
            "inlet": np.unique(label[:, :, 0]) if lower[0] == 0 else np.zeros(0, int),
            "outlet": np.unique(label[:, :, -1]) if upper[0] == grid.shape[0] else np.zeros(0, int),
            "first": np.take(label, 0, axis=2 - axis), "last": np.take(label, -1, axis=2 - axis)}
    blocks = comm.allgather(mine) if comm is not None and comm.Get_size() > 1 else [mine]
    offsets = np.cumsum([0] + [b["count"] for b in blocks])  # global label = offset + local label (0: solid)
    a_ids, b_ids = [], []
    for a, oa in zip(blocks, offsets):
        for b, ob in zip(blocks, offsets):
            if a is not b and a["upper"][axis] == b["lower"][axis] and a["count"] and b["count"]:
                both = (a["last"] > 0) & (b["first"] > 0)  # open cells facing each other across the cut
                a_ids.append(oa + a["last"][both])
                b_ids.append(ob + b["first"][both])
    n = int(offsets[-1]) + 1
    edges = (np.concatenate(a_ids), np.concatenate(b_ids)) if a_ids else (np.zeros(0, int), np.zeros(0, int))
    _, component = connected_components(coo_matrix((np.ones(len(edges[0])), edges), shape=(n, n)), directed=False)
    inlet, outlet = ({int(c) for b, o in zip(blocks, offsets) for c in component[o + b[end][b[end] > 0]]}
                     for end in ("inlet", "outlet"))
    return bool(inlet & outlet)
