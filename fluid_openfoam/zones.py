"""The solid's velocity in the fluid (paper 2.3, Step 6) with stock OpenFOAM v1912: one
uniform velocity per solid body.

Stock v1912 has no per-cell target velocity for the penalization (``solidification``
drives ``U`` to zero). What it has is ``vectorSemiImplicitSource``: a source ``Su + Sp U``
uniform over a cell set. With ``Su = D_max U_s`` and ``Sp = 0`` on cells the penalization
already holds with ``-D_max U`` (implicit), the momentum balance there becomes
``D_max (U_s - U) = grad p - ...`` and ``U -> U_s`` up to ``1 / D_max`` (about 1e-4 of
the other rates). ``Sp < 0`` is not needed, and does not work in v1912: tried as the whole
penalization (``U ((D_max U_s) -D_max)`` with no porosity, D_max = 1e6 1/s, on the 1D piston
of tests/test_fluid_transient.py) pimpleFoam ran 50 unconverged PIMPLE iterations and
returned U ~ 1e4 m/s and p ~ 1e11 Pa after one step, against U = 0.1 m/s, p ~ 800 Pa.

A body is a connected set (face neighbours) of solid-centred cells (fraction >= 1/2, the
cells the penalization stops: :mod:`transfer.penalization`). Its velocity ``U_s`` is
the mean of the projected solid velocity over its *interface layer* (its cells with a
fluid-centred face neighbour), weighted by the solid fraction: the velocity of the
wetted wall, which is what the fluid must see (displacement flux, added mass). The body
then moves rigidly in the fluid. What is not represented: rotation and deformation inside
one body (a body whose interface layer moves non-uniformly gets the mean), and the
velocity of the partially filled fluid-centred cells next to the wall (their sub-cell wall
drag still pulls towards rest). A rigid body translating in the fluid is exact to the
penalization error. A body cut by the grid's boundary can move through that face only if
the face is open (a fixed-pressure face: the outlet, or ``{ pressure = p }`` in
``[flow] faces``); through any other face (wall, slip, symmetry, the fixed-velocity inlet)
incompressibility forbids it, and imposing it anyway fills the body with pressures of order
``D_max U_s h`` (measured on small_fracture with dynamics and slip faces inside the blocks:
8e5 Pa in the solid cells against 600 Pa of flow). So the velocity component normal to a
closed face the body touches is dropped (the body slides along it), and reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from transfer.grid import BOX_FACES


@dataclass
class BodySource:
    name: str            # cellSet and fvOption name
    cells: np.ndarray    # cell labels (x fastest)
    velocity: np.ndarray  # U_s (3,), m/s
    su: np.ndarray       # D_max U_s, m/s^2 (kinematic, per unit volume)
    dropped: dict        # closed face -> the velocity component normal to it that was dropped


def body_sources(fraction, velocity, shape, d_max: float, closed=()) -> list[BodySource]:
    """One :class:`BodySource` per solid body with a nonzero interface velocity; ``closed``
    names the grid faces no flow may cross (see the module doc). A body whose velocity was
    dropped entirely keeps a (zero) source, so that the drop is reported."""
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
        out.append(BodySource(f"solidBody{len(out)}", np.flatnonzero(flat == body), us, d_max * us, dropped))
    return out


def write_cell_set(path, name: str, cells) -> None:
    """An ASCII cellSet file (constant/polyMesh/sets/NAME)."""
    cells = np.asarray(cells, dtype=np.int64)
    head = ("FoamFile\n{\n    version     2.0;\n    format      ascii;\n    class       cellSet;\n"
            f'    location    "constant/polyMesh/sets";\n    object      {name};\n}}\n\n')
    with open(path, "w") as out:
        out.write(head + f"{cells.size}\n(\n")
        out.write("\n".join(map(str, cells.tolist())))
        out.write("\n)\n")
