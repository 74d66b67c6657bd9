"""Solid bodies on a fluid grid, each moving rigidly with the velocity of its wetted wall
(paper 2.3, Step 6, in the rigid-body model both grid fluids can apply).

A body is a connected set (face neighbours) of solid-centred cells (fraction >= 1/2, the
cells the penalization stops: :mod:`transfer.penalization`). Its velocity ``U_s`` is the
mean of the projected solid velocity over its *interface layer* (its cells with a
fluid-centred face neighbour), weighted by the solid fraction: the velocity of the wetted
wall, which is what the fluid must see (displacement flux, added mass). Not represented:
rotation and deformation inside one body (a body whose interface layer moves non-uniformly
gets the mean), and the velocity of the partially filled fluid-centred cells next to the
wall (their sub-cell wall drag still pulls towards rest). A body cut by the grid's boundary
can move through that face only if the face is open (a fixed pressure); through any other
face (wall, slip, symmetry, a fixed-velocity inlet) incompressibility forbids it, and
imposing it anyway fills the body with pressures of order ``D_max U_s h`` (measured on
small_fracture with dynamics and slip faces inside the blocks: 8e5 Pa in the solid cells
against 600 Pa of flow). So the velocity component normal to a closed face the body
touches is dropped (the body slides along it), and reported.

On MPI ranks each holding a box of the grid (a fluid's slab or processor) a body may cross the
boxes: each rank labels its box (:func:`transfer.labels.label_boxes`: the labels of the whole
grid, joined across the boxes' faces), sums each body's weighted velocity, weights and contacts
with closed faces over its own cells, reading one layer of face neighbours beyond its box (the
interface layer), and the sums are gathered and added in rank order, so every rank has the same
bodies, velocities and drops; nothing of the whole grid is held on one rank.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .grid import BOX_FACES, box_cells
from .labels import box_bounds, label_boxes

CROSS = ndimage.generate_binary_structure(3, 1)  # face neighbours


@dataclass
class Body:
    cells: np.ndarray    # cell labels (x fastest); on ranks those in this rank's box
    velocity: np.ndarray  # U_s (3,), m/s
    dropped: dict        # closed face -> the velocity component normal to it that was dropped


def _rows(ids, cells) -> tuple[np.ndarray, np.ndarray]:
    """The row of ``ids`` (sorted grid cells) of each of ``cells``, and whether ``ids`` holds it."""
    if len(ids) == 0:
        return np.zeros(cells.shape, np.int64), np.zeros(cells.shape, bool)
    rows = np.minimum(np.searchsorted(ids, cells), len(ids) - 1)
    return rows, ids[rows] == cells


def rigid_bodies(fraction, velocity, shape, closed=(), box=None, ids=None, comm=None) -> list[Body]:
    """One :class:`Body` per solid body with a nonzero interface velocity; ``closed`` names
    the grid faces no flow may cross (see the module doc). A body whose velocity was dropped
    entirely is kept (at rest), so that the drop is reported. ``fraction`` (n,) and ``velocity``
    (n, 3) are the rows of the grid cells ``ids`` (sorted; None: the whole grid). On the ranks
    of ``comm`` (collective) each gives its ``box`` ``(lower, upper)`` of a tiling of the grid
    and rows that hold the box's cells and their face neighbours; every rank gets the same
    bodies, each with its cells in the box (module doc). ``comm=None``: the box is the grid."""
    shape = tuple(int(s) for s in shape)
    lower, upper = box_bounds(shape, box)
    ids = np.arange(int(np.prod(shape))) if ids is None else np.asarray(ids, np.int64).reshape(-1)
    grown = np.maximum(lower - 1, 0), np.minimum(upper + 1, shape)  # the face neighbours' layer
    around = box_cells(*grown, shape)  # the grid cells of the grown box, (z, y, x)
    rows, found = _rows(ids, around)
    f = np.zeros(around.shape)  # zero (fluid) at the cells ids lacks
    f[found] = np.asarray(fraction, dtype=float).reshape(-1)[rows[found]]
    inner = tuple(slice(lo - g, hi - g) for lo, hi, g in zip(lower[::-1], upper[::-1], grown[0][::-1]))
    needed = np.zeros(f.shape, bool)
    needed[inner] = True
    missing = int(np.count_nonzero(ndimage.binary_dilation(needed, structure=CROSS) & ~found))
    solid = f >= 0.5
    layer = (solid & ndimage.binary_dilation(~solid, structure=CROSS, border_value=0))[inner]
    f, solid, cells, rows, found = f[inner], solid[inner], around[inner], rows[inner], found[inner]
    v = np.zeros(f.shape + (3,))
    v[found] = np.asarray(velocity, dtype=float).reshape(-1, 3)[rows[found]]
    labels, count = label_boxes(solid, shape, (lower, upper), comm)
    edges = [(axis, side, (upper if side else lower)[axis] == (shape[axis] if side else 0))
             for axis, side in (divmod(BOX_FACES.index(face), 2) for face in closed)]
    present, sums, members = [], [], {}
    for body, box_of in enumerate(ndimage.find_objects(labels, count), start=1):
        if box_of is None:
            continue
        mine = labels[box_of] == body
        where = mine & layer[box_of]
        w = f[box_of][where]
        touch = [on and (box_of[2 - axis].stop == labels.shape[2 - axis] if side else box_of[2 - axis].start == 0)
                 for axis, side, on in edges]  # its cells on that closed face of the grid
        present.append(body - 1)
        sums.append([*(w[:, None] * v[box_of][where]).sum(axis=0), w.sum(), *touch])
        members[body] = cells[box_of][mine]
    part = (missing, np.asarray(present, np.int64), np.asarray(sums, float).reshape(len(present), 4 + len(closed)))
    parts = [part] if comm is None or comm.Get_size() == 1 else comm.allgather(part)
    short = [f"rank {r} misses {m}" for r, (m, _, _) in enumerate(parts) if m]
    if short:
        raise ValueError(f"rigid bodies: the rows given lack cells of the box or of their face neighbours "
                         f"({', '.join(short)})")
    total = np.zeros((count, 4 + len(closed)))
    for _, rows, sums in parts:  # in rank order: the same sums on every rank
        total[rows] += sums
    out = []
    for body in range(1, count + 1):
        s, weight, touches = total[body - 1, :3], total[body - 1, 3], total[body - 1, 4:]
        if weight == 0:  # a body filling the grid: no wall to move
            continue
        us = s / weight
        dropped = {}
        for face, (axis, _, _), touch in zip(closed, edges, touches):
            if touch and us[axis] != 0.0:
                dropped[face] = float(us[axis])
                us[axis] = 0.0
        if not np.any(us) and not dropped:
            continue
        out.append(Body(members.get(body, np.zeros(0, np.int64)), us, dropped))
    return out


def rigid_velocity(bodies: list[Body], ids) -> np.ndarray:
    """(len(ids), 3): the velocity of the body holding each of the grid cells ``ids`` (sorted,
    holding every body's cells), zero elsewhere."""
    ids = np.asarray(ids, np.int64)
    out = np.zeros((len(ids), 3))
    for body in bodies:
        out[np.searchsorted(ids, body.cells)] = body.velocity
    return out
