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

The bodies and their velocities (the wetted wall's mean, the component normal to a closed grid
face dropped) are :func:`transfer.bodies.rigid_bodies`, which the Chorin fluid applies too
(``solid_velocity = "bodies"``). A rigid body translating in the fluid is exact to the
penalization error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from transfer.bodies import rigid_bodies


@dataclass
class BodySource:
    name: str            # cellSet and fvOption name
    cells: np.ndarray    # cell labels (x fastest); on ranks those of this rank's box
    velocity: np.ndarray  # U_s (3,), m/s
    su: np.ndarray       # D_max U_s, m/s^2 (kinematic, per unit volume)
    dropped: dict        # closed face -> the velocity component normal to it that was dropped


def body_sources(fraction, velocity, shape, d_max: float, closed=(), **ranks) -> list[BodySource]:
    """One :class:`BodySource` per body of :func:`transfer.bodies.rigid_bodies` (a nonzero
    interface velocity, or one dropped at a closed face: a zero source, so that the drop is
    reported); ``ranks``: its ``box``, ``ids`` and ``comm`` on the ranks of a decomposed case
    (every rank the same sources, each with its box's cells)."""
    return [BodySource(f"solidBody{i}", b.cells, b.velocity, d_max * b.velocity, b.dropped)
            for i, b in enumerate(rigid_bodies(fraction, velocity, shape, closed, **ranks))]


def write_cell_set(path, name: str, cells) -> None:
    """An ASCII cellSet file (constant/polyMesh/sets/NAME)."""
    cells = np.asarray(cells, dtype=np.int64)
    head = ("FoamFile\n{\n    version     2.0;\n    format      ascii;\n    class       cellSet;\n"
            f'    location    "constant/polyMesh/sets";\n    object      {name};\n}}\n\n')
    with open(path, "w") as out:
        out.write(head + f"{cells.size}\n(\n")
        out.write("\n".join(map(str, cells.tolist())))
        out.write("\n)\n")
