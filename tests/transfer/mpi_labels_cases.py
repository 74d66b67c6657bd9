"""Run under ``mpirun -n P`` (P = 2, 3, 4) by test_labels_ranks.py: connected components on a grid
tiled by the ranks' index boxes (transfer/labels.py) against scipy's on the whole grid (every
rank computes both). Rank 0 prints JSON: per tiling and mask the serial and the joined counts,
each rank's own count of components in its box and whether every rank's labels equal the serial
ones."""

from __future__ import annotations

import json

import numpy as np
from mpi4py import MPI
from scipy import ndimage

from transfer.labels import label_boxes

comm = MPI.COMM_WORLD
SHAPE = (8, 6, 5)  # nx, ny, nz


def split(n: int, parts: int) -> list[int]:
    return [n * p // parts for p in range(parts + 1)]


def blocks(nx: int, ny: int, nz: int) -> list:
    """decomposePar's simple blocks: nx ny nz boxes, x fastest over the processors."""
    cuts = [split(s, b) for s, b in zip(SHAPE, (nx, ny, nz))]
    return [((cuts[0][i], cuts[1][j], cuts[2][k]), (cuts[0][i + 1], cuts[1][j + 1], cuts[2][k + 1]))
            for k in range(nz) for j in range(ny) for i in range(nx)]


def slabs(axis: int, parts: int) -> list:
    return blocks(*[parts if d == axis else 1 for d in range(3)])


TILINGS = {
    2: {"slabs along x": slabs(0, 2), "slabs along z": slabs(2, 2),
        "one plane and the rest": [((0, 0, 0), (1, 6, 5)), ((1, 0, 0), (8, 6, 5))]},
    3: {"slabs along y": slabs(1, 3), "blocks 3x1x1": blocks(3, 1, 1),
        # rank 0's upper face meets two boxes: the cuts are not aligned
        "a box under two": [((0, 0, 0), (8, 6, 2)), ((0, 0, 2), (3, 6, 5)), ((3, 0, 2), (8, 6, 5))],
        "an empty box": [((0, 0, 0), (8, 6, 2)), ((0, 0, 2), (8, 6, 5)), ((0, 0, 5), (8, 6, 5))]},
    4: {"blocks 2x2x1": blocks(2, 2, 1), "blocks 1x2x2": blocks(1, 2, 2), "slabs along x": slabs(0, 4),
        "blocks 2x1x2": blocks(2, 1, 2)},
}


def bars(*corners_lists) -> np.ndarray:
    """A (z, y, x) mask of the polylines given by their (i, j, k) corners (one axis at a time)."""
    mask = np.zeros(SHAPE[::-1], bool)
    for corners in corners_lists:
        for a, b in zip(corners, corners[1:]):
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            mask[lo[2]:hi[2] + 1, lo[1]:hi[1] + 1, lo[0]:hi[0] + 1] = True
    return mask


def masks() -> dict:
    """Bodies crossing the cuts at x = 4, y = 3, z = 2 or 3 (the tilings' main cuts)."""
    rng = np.random.default_rng(7)
    out = {"none": np.zeros(SHAPE[::-1], bool), "all": np.ones(SHAPE[::-1], bool),
           "one cut": bars([(1, 1, 1), (6, 1, 1)]),
           "several cuts": bars([(0, 1, 1), (6, 1, 1), (6, 5, 1), (6, 5, 4)]),
           # leaves x < 4 and comes back: two pieces in that box, one body
           "U leaving and re-entering": bars([(1, 1, 1), (6, 1, 1), (6, 4, 1), (1, 4, 1)], [(1, 1, 3), (1, 4, 3)]),
           # cells meeting along an edge across x = 4 and y = 3, along an edge across z = 2, at a corner across x = 4
           "diagonal only": bars([(1, 1, 1), (3, 1, 1), (3, 2, 1)], [(4, 3, 1), (6, 3, 1)], [(1, 4, 1), (1, 5, 1)],
                                 [(2, 5, 2), (2, 5, 4)], [(3, 0, 3), (3, 0, 3)], [(4, 1, 4), (4, 1, 4)]),
           "checkerboard": (np.indices(SHAPE[::-1]).sum(axis=0) % 2).astype(bool)}
    for density in (0.3, 0.5, 0.7):
        for seed in range(3):
            out[f"random {density} #{seed}"] = rng.uniform(size=SHAPE[::-1]) < density
    return out


def in_box(array, lower, upper):
    return array[lower[2]:upper[2], lower[1]:upper[1], lower[0]:upper[0]]


def labelling(tilings) -> dict:
    out = {}
    for name, boxes in tilings.items():
        lower, upper = (np.asarray(b) for b in boxes[comm.rank])
        out[name] = {}
        for what, mask in masks().items():
            serial, count = ndimage.label(mask)
            labels, total = label_boxes(in_box(mask, lower, upper).ravel(), SHAPE, (lower, upper), comm)
            own = ndimage.label(in_box(mask, lower, upper))[1]
            out[name][what] = {"serial": count, "ranks": total, "own": comm.allgather(own),
                               "equal": all(comm.allgather(bool(np.array_equal(labels, in_box(serial, lower, upper)))))}
    return out


def wrong_tilings() -> dict:
    """Boxes that overlap, or leave a gap: every rank fails alike."""
    out = {}
    for name, cut in (("overlap", 1), ("gap", -1)):
        boxes = slabs(0, comm.size)
        boxes[0] = ((0, 0, 0), (boxes[0][1][0] + cut, 6, 5))  # rank 0's box one plane too long or short
        try:
            label_boxes(in_box(np.ones(SHAPE[::-1], bool), *boxes[comm.rank]), SHAPE, boxes[comm.rank], comm)
        except ValueError as exc:
            out[name] = comm.allgather(str(exc))
    return out


def main():
    tilings = TILINGS[comm.size]
    result = {"ranks": comm.size, "labels": labelling(tilings), "wrong tilings": wrong_tilings()}
    if comm.rank == 0:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
