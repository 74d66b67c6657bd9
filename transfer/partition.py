"""Partitions of cells among ranks, for meshes that every rank holds whole (files the CLI
reads, tests) or whose centres one rank gathers (:func:`transfer.pieces.balanced`): slabs along
an axis and recursive coordinate bisection of the cell centres.
Each gives the owner rank of every cell; :meth:`transfer.distributed.Part.of_cells` makes a
rank's part of them, :func:`part_rows` its cells and the vertices it owns (a participant's part)."""

from __future__ import annotations

import numpy as np


def _centres(mesh) -> np.ndarray:
    return mesh.points[mesh.cells].mean(axis=1)


def _split(order: np.ndarray, parts: int) -> np.ndarray:
    """Owner of the items taken in `order`: `parts` runs of equal length (to one)."""
    owner = np.empty(len(order), dtype=np.int64)
    owner[order] = np.arange(len(order)) * parts // max(len(order), 1)
    return owner


def slabs(mesh, parts: int, axis: int) -> np.ndarray:
    """Owner of every cell: `parts` slabs of equal cell counts along `axis` (0, 1, 2)."""
    return _split(np.argsort(_centres(mesh)[:, axis], kind="stable"), parts)


def bisection(mesh, parts: int) -> np.ndarray:
    """Owner of every cell by recursive coordinate bisection of the cell centres (:func:`bisect`)."""
    return bisect(_centres(mesh), parts)


def bisect(centres: np.ndarray, parts: int) -> np.ndarray:
    """Owner of every point of `centres` (n, 3) by recursive coordinate bisection: the points
    are cut across their longest extent, in counts proportional to the ranks on each side."""
    owner = np.zeros(len(centres), dtype=np.int64)

    def cut(items, first, count):
        if count == 1 or len(items) == 0:
            owner[items] = first
            return
        x = centres[items]
        axis = int(np.argmax(x.max(axis=0) - x.min(axis=0)))
        order = items[np.argsort(x[:, axis], kind="stable")]
        left = count // 2
        k = len(order) * left // count
        cut(order[:k], first, left)
        cut(order[k:], first + left, count - left)

    cut(np.arange(len(centres)), 0, parts)
    return owner


def grid_slab(shape, parts: int, rank: int, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell index range (lower, upper) of `rank`'s slab of a grid of `shape` cut along `axis`."""
    lower, upper = np.zeros(3, np.int64), np.asarray(shape, np.int64).copy()
    n = int(shape[axis])
    lower[axis], upper[axis] = rank * n // parts, (rank + 1) * n // parts
    return lower, upper


def part_rows(mesh, rank: int, parts: int) -> tuple[np.ndarray, np.ndarray]:
    """(cells, vertices) of `rank`'s part of `mesh` (held whole on every rank): its cells by
    :func:`bisection`, as ``mpirun -n N varcouple transfer`` cuts a file, and the vertices it
    owns, each vertex owned once, by the lowest rank whose cells use it (a vertex of no cell by
    rank 0)."""
    owner = bisection(mesh, parts)
    vertex_owner = np.full(mesh.num_points, parts, np.int64)
    np.minimum.at(vertex_owner, mesh.cells.ravel(), np.repeat(owner, mesh.cells.shape[1]))
    vertex_owner[vertex_owner == parts] = 0
    return np.flatnonzero(owner == rank), np.flatnonzero(vertex_owner == rank)
