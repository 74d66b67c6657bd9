"""Connected components (face neighbours) of a mask on a structured grid whose cells are held
by MPI ranks in index boxes: the solid bodies of the rigid-body model (paper 2.3, Step 6:
:mod:`transfer.bodies`) and the open paths of the percolation check.

Rank r holds the cells of its box ``[lower, upper)`` (cell indices along x, y, z); the boxes
of the ranks tile the grid: slabs along one axis, decomposePar's blocks in three axes, any
other tiling, a box may be empty. Each rank labels its box (scipy.ndimage, face neighbours);
the ranks allgather each box's bounds, its labels on its faces inside the grid (planes, not
volumes) and the first cell of each of its components; every rank then joins the labels that
face each other across a shared face (the connected components of that graph) and numbers the
components by their first cell in the grid's order (x fastest). That is scipy's numbering of
the whole grid, so the labels equal the serial ones, on every rank.

Cost per rank: one allgather; each rank receives every rank's faces inside the grid (4 B per
face cell) and first cells (8 B per component of its box), e.g. on slabs along x of an
nx x ny x nz grid ``8 (P - 1) ny nz`` B for the faces; the join is a graph over every box's
components.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .grid import box_cells, cell_ijk


def box_bounds(shape, box=None) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, upper)`` cell indices of ``box``, the whole grid of ``shape`` when None."""
    if box is None:
        return np.zeros(3, np.int64), np.asarray(shape, np.int64)
    return np.asarray(box[0], np.int64).reshape(3), np.asarray(box[1], np.int64).reshape(3)


def cell_box(cells, shape) -> tuple[np.ndarray, np.ndarray] | None:
    """The index box ``(lower, upper)`` that the distinct grid ``cells`` fill, None when they fill none."""
    cells = np.asarray(cells, np.int64).reshape(-1)
    if cells.size == 0:
        return None
    ijk = cell_ijk(cells, shape)
    lower, upper = ijk.min(axis=0), ijk.max(axis=0) + 1
    return (lower, upper) if int(np.prod(upper - lower)) == len(np.unique(cells)) == cells.size else None


def _faces(labels, lower, upper, shape) -> dict:
    """The box's label planes on its faces inside the grid: (axis, side) -> (z, y, x) minus axis."""
    if labels.size == 0:
        return {}
    return {(d, side): np.ascontiguousarray(np.take(labels, -side, axis=2 - d), dtype=np.int32)
            for d in range(3) for side in (0, 1) if (lower[d] > 0, upper[d] < shape[d])[side]}


def _tiling_problem(boxes, shape) -> str | None:
    """Why the ranks' boxes do not tile the grid (None: they do)."""
    shape = np.asarray(shape, np.int64)
    for r, (lo, hi) in enumerate(boxes):
        if np.any(lo < 0) or np.any(hi > shape) or np.any(hi < lo):
            return f"rank {r}'s box {lo.tolist()} to {hi.tolist()} is not inside the grid of {shape.tolist()} cells"
    full = [r for r, (lo, hi) in enumerate(boxes) if np.all(hi > lo)]
    for a in full:
        for b in (b for b in full if b > a):
            if np.all(np.maximum(boxes[a][0], boxes[b][0]) < np.minimum(boxes[a][1], boxes[b][1])):
                return f"the boxes of ranks {a} and {b} overlap"
    if sum(int(np.prod(hi - lo)) for lo, hi in boxes) != int(np.prod(shape)):
        return f"the boxes of the ranks do not cover the grid of {shape.tolist()} cells"
    return None


def _joins(a, b, d) -> tuple[np.ndarray, np.ndarray]:
    """The local labels of box ``a`` and box ``b`` that face each other across the plane where
    ``a``'s upper face along axis ``d`` meets ``b``'s lower face (both nonzero)."""
    lo, hi = np.maximum(a["lower"], b["lower"]), np.minimum(a["upper"], b["upper"])
    others = [e for e in (2, 1, 0) if e != d]  # the plane's array axes
    if any(lo[e] >= hi[e] for e in others):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pa, pb = (box["faces"][(d, side)][tuple(slice(lo[e] - box["lower"][e], hi[e] - box["lower"][e]) for e in others)]
              for box, side in ((a, 1), (b, 0)))
    both = (pa > 0) & (pb > 0)
    return pa[both].astype(np.int64), pb[both].astype(np.int64)


def label_boxes(mask, shape, box=None, comm=None) -> tuple[np.ndarray, int]:
    """The connected components (face neighbours) of ``mask`` over the grid of ``shape``:
    ``(labels, count)``, ``labels`` a (z, y, x) array of this rank's ``box`` (0 outside the mask,
    1 to ``count`` the components of the whole grid, numbered as scipy.ndimage.label numbers
    them on the whole grid). ``mask``: the box's cells, x fastest. With ``comm`` every rank
    gives its box of a tiling (module doc; collective); ``comm=None``: the box is the grid,
    scipy's labelling."""
    lower, upper = box_bounds(shape, box)
    labels, count = ndimage.label(np.asarray(mask, bool).reshape(tuple((upper - lower)[::-1])))
    if comm is None or comm.Get_size() == 1:
        if np.any(lower != 0) or np.any(upper != np.asarray(shape)):
            raise ValueError(f"one rank labels the whole grid of {list(shape)} cells, got the box "
                             f"{lower.tolist()} to {upper.tolist()}")
        return labels, count
    shape = np.asarray(shape, np.int64)
    present, at = np.unique(labels.reshape(-1), return_index=True)
    first = box_cells(lower, upper, shape).reshape(-1)[at[present > 0]]  # labels are numbered by first cell
    mine = {"lower": lower, "upper": upper, "count": count, "first": first,
            "faces": _faces(labels, lower, upper, shape)}
    boxes = comm.allgather(mine)
    problem = _tiling_problem([(b["lower"], b["upper"]) for b in boxes], shape)
    if problem:
        raise ValueError(problem)
    offsets = np.cumsum([0] + [b["count"] for b in boxes])  # node offset + local label - 1
    edges = [np.zeros((2, 0), np.int64)]
    for a, oa in zip(boxes, offsets):
        for b, ob in zip(boxes, offsets):
            for d in range(3):
                if a["upper"][d] == b["lower"][d] and (d, 1) in a["faces"] and (d, 0) in b["faces"]:
                    la, lb = _joins(a, b, d)
                    edges.append(np.stack([oa + la - 1, ob + lb - 1]))
    edges = np.concatenate(edges, axis=1)
    n = int(offsets[-1])
    total, component = connected_components(coo_matrix((np.ones(edges.shape[1]), tuple(edges)), shape=(n, n)),
                                             directed=False)
    firsts = np.full(total, np.iinfo(np.int64).max)
    np.minimum.at(firsts, component, np.concatenate([b["first"] for b in boxes]))
    number = np.empty(total, np.int64)
    number[np.argsort(firsts)] = np.arange(1, total + 1)  # by first cell, as scipy numbers them
    me = comm.Get_rank()
    lut = np.concatenate([[0], number[component[offsets[me]:offsets[me + 1]]]])
    return lut[labels], total
