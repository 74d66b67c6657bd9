"""Run under ``mpirun -n P`` (P = 2, 3, 4) by test_labels_ranks.py: connected components and rigid
bodies on a grid tiled by the ranks' index boxes (transfer/labels.py, transfer/bodies.py) against
scipy's and the serial functions on the whole grid (every rank computes both). Rank 0 prints
JSON: per tiling and mask the serial and the joined counts, each rank's own count of components
in its box and whether every rank's labels equal the serial ones; per tiling and field the
largest differences of the bodies."""

from __future__ import annotations

import json

import numpy as np
from mpi4py import MPI
from scipy import ndimage

from transfer.bodies import rigid_bodies
from transfer.grid import BOX_FACES
from transfer.grid import box_cells
from transfer.labels import label_boxes
from transfer.penalization import reach

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


def fields(seed: int):
    """Smooth solid fractions (bodies of a few cells, some at the grid's faces) and random velocities."""
    rng = np.random.default_rng(seed)
    f = ndimage.uniform_filter(rng.uniform(size=SHAPE[::-1]), 2)
    f = np.clip((f - 0.5) * 6 + 0.5, 0.0, 1.0).ravel()
    v = rng.normal(size=(f.size, 3))
    if seed % 2:
        v[:] = rng.normal(size=3)  # one velocity everywhere: every body moves with it
    return f, v


def relative(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b), initial=0.0) / max(np.max(np.abs(a), initial=0.0), 1e-300))


def bodies(tilings) -> dict:
    out = {}
    closed_sets = {0: BOX_FACES, 1: ("xmin", "zmax"), 2: (), 3: ("ymin", "ymax", "zmin")}
    for name, boxes in tilings.items():
        lower, upper = (np.asarray(b) for b in boxes[comm.rank])
        own = box_cells(lower, upper, SHAPE).ravel()
        ids = reach(own, SHAPE, "wall")  # the box and its face neighbours, as the OpenFOAM fluid's inputs
        out[name] = {}
        for seed, closed in closed_sets.items():
            f, v = fields(seed)
            serial = rigid_bodies(f, v, SHAPE, closed)
            mine = rigid_bodies(f[ids], v[ids], SHAPE, closed, (lower, upper), ids, comm)
            joined = [np.sort(np.concatenate(comm.allgather(b.cells))) for b in mine]
            everywhere = comm.allgather([(b.velocity.tobytes(), b.dropped) for b in mine])
            held = np.sum(comm.allgather([len(b.cells) > 0 for b in mine]), axis=0)
            out[name][seed] = {
                "bodies": [len(serial), len(mine)], "dropped": sum(len(b.dropped) for b in serial),
                "across boxes": int(np.count_nonzero(held > 1)),
                "same on every rank": all(e == everywhere[0] for e in everywhere),
                "cells": len(serial) == len(mine) and all(np.array_equal(a.cells, c) for a, c in zip(serial, joined)),
                "in the box": all(comm.allgather(bool(np.all(np.isin(np.concatenate([own[:0]] + [b.cells for b in mine]),
                                                                      own))))),
                "velocity": max((relative(a.velocity, b.velocity) for a, b in zip(serial, mine)), default=0.0),
                "drops": len(serial) == len(mine) and all(a.dropped.keys() == b.dropped.keys() and all(
                    abs(a.dropped[k] - b.dropped[k]) <= 1e-14 * abs(a.dropped[k]) for k in a.dropped)
                    for a, b in zip(serial, mine))}
    return out


def missing_rows() -> str:
    """Rank 1 gives its box's cells without their face neighbours: every rank fails alike."""
    lower, upper = (np.asarray(b) for b in slabs(0, comm.size)[comm.rank])
    ids = box_cells(lower, upper, SHAPE).ravel()
    if comm.rank != 1:
        ids = reach(ids, SHAPE, "wall")
    f, v = fields(0)
    try:
        rigid_bodies(f[ids], v[ids], SHAPE, (), (lower, upper), ids, comm)
    except ValueError as exc:
        return str(exc)
    return ""


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
    result = {"ranks": comm.size, "labels": labelling(tilings), "wrong tilings": wrong_tilings(), "bodies": bodies(tilings),
              "missing": comm.allgather(missing_rows())}
    if comm.rank == 0:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
