"""Which cells of a structured grid have their centre inside a tetrahedral mesh: the binary
solid fraction (cell-centre sampling) that the exact volume fractions of paper 2.3 replace,
kept as an option of the solid-fraction exchange to measure what they gain."""

from __future__ import annotations

import numpy as np

from transfer import Mesh, StructuredGrid

#: candidate (tetrahedron, cell centre) pairs tested at a time
CHUNK = 1 << 20


def centres_inside(S: Mesh, G: StructuredGrid, tolerance: float = 1e-9) -> np.ndarray:
    """Per grid cell (x fastest): True where its centre lies in a tetrahedron of `S`, a point on
    the solid's boundary included (barycentric coordinates >= -`tolerance`)."""
    inside = np.zeros(G.num_cells, bool)
    inside[centre_cells(S, G, tolerance)] = True
    return inside


def centre_cells(S: Mesh, G: StructuredGrid, tolerance: float = 1e-9) -> np.ndarray:
    """The ids of the grid cells (x fastest) whose centre lies in a tetrahedron of `S`
    (:func:`centres_inside`), sorted, each once: only the cells in the tetrahedra's bounding
    boxes are looked at, no array of the whole grid is made."""
    origin, h, n = np.asarray(G.origin, float), np.asarray(G.spacing, float), np.asarray(G.shape, np.int64)
    p = np.asarray(S.points)[S.cells]  # (m, 4, 3)
    lo = np.ceil((p.min(axis=1) - origin) / h - 0.5 - tolerance).astype(np.int64)
    hi = np.floor((p.max(axis=1) - origin) / h - 0.5 + tolerance).astype(np.int64)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, n - 1)
    extent = np.maximum(hi - lo + 1, 0)  # centres per axis in each tet's bounding box
    counts = extent.prod(axis=1)
    inverse = np.linalg.inv(np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1)))  # x -> barycentric 1..3
    found = []
    ends = np.cumsum(counts)
    first = 0
    while first < len(counts):  # tets whose candidate pairs fit in one chunk
        last = max(int(np.searchsorted(ends, (ends[first - 1] if first else 0) + CHUNK, side="right")), first + 1)
        tets = np.repeat(np.arange(first, last), counts[first:last])
        r = np.arange(len(tets)) - np.repeat(ends[first:last] - counts[first:last], counts[first:last])
        e = extent[tets]
        ijk = lo[tets] + np.stack([r % e[:, 0], (r // e[:, 0]) % e[:, 1], r // (e[:, 0] * e[:, 1])], axis=1)
        x = origin + (ijk + 0.5) * h
        lam = np.einsum("nij,nj->ni", inverse[tets], x - p[tets, 0])
        hit = (lam.min(axis=1) >= -tolerance) & (lam.sum(axis=1) <= 1 + tolerance)
        cells = ijk[hit]
        found.append(np.unique(cells[:, 0] + n[0] * (cells[:, 1] + n[1] * cells[:, 2])))
        first = last
    return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)
