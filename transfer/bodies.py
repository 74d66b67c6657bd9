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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .grid import BOX_FACES


@dataclass
class Body:
    cells: np.ndarray    # cell labels (x fastest)
    velocity: np.ndarray  # U_s (3,), m/s
    dropped: dict        # closed face -> the velocity component normal to it that was dropped


def rigid_bodies(fraction, velocity, shape, closed=()) -> list[Body]:
    """One :class:`Body` per solid body with a nonzero interface velocity; ``closed`` names
    the grid faces no flow may cross (see the module doc). A body whose velocity was dropped
    entirely is kept (at rest), so that the drop is reported."""
    nx, ny, nz = (int(s) for s in shape)
    f = np.asarray(fraction, dtype=float).reshape(nz, ny, nx)
    v = np.asarray(velocity, dtype=float).reshape(nz, ny, nx, 3)
    solid = f >= 0.5
    labels, count = ndimage.label(solid)  # 6-connectivity (face neighbours)
    layer = solid & ndimage.binary_dilation(~solid, structure=ndimage.generate_binary_structure(3, 1),
                                            border_value=0)
    out = []
    flat = labels.reshape(-1)
    for body in range(1, count + 1):
        mine = labels == body
        where = mine & layer
        if not where.any():  # a body filling the grid: no wall to move
            continue
        w = f[where]
        us = (w[:, None] * v[where]).sum(axis=0) / w.sum()
        dropped = {}
        for face in closed:
            axis, side = BOX_FACES.index(face) // 2, BOX_FACES.index(face) % 2
            edge = np.take(mine, -1 if side else 0, axis=2 - axis)  # the body's cells on that face
            if edge.any() and us[axis] != 0.0:
                dropped[face] = float(us[axis])
                us[axis] = 0.0
        if not np.any(us) and not dropped:
            continue
        out.append(Body(np.flatnonzero(flat == body), us, dropped))
    return out


def rigid_velocity(bodies: list[Body], n_cells: int) -> np.ndarray:
    """(n_cells, 3): each body's velocity in its cells, zero elsewhere."""
    out = np.zeros((n_cells, 3))
    for body in bodies:
        out[body.cells] = body.velocity
    return out
