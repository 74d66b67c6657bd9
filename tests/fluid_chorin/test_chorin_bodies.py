"""The Chorin fluid's solid velocity models (``solid_velocity``: cells, bodies, none) and the
transient open face: a rigid block under a squeezed channel with open ends, the added-mass
case of cases/added_mass_heavy on the fluid alone."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fluid_chorin.solver import ChorinSolver
from fluid_chorin.spec import ChorinSpec

#: cases/added_mass_heavy's grid: 20 x 4 x 6 cells of 5 mm, open ends and an open base
SHAPE, H, DT = (20, 4, 6), 5.0e-3, 5.0e-5


def block_under_channel(**settings) -> ChorinSolver:
    """The channel's fluid at rest, with the pressures of cases/added_mass_heavy (1.1e4 Pa in,
    1e4 Pa out and under the block)."""
    config = {"grid": {"origin": [0, 0, 0], "spacing": [H] * 3, "shape": list(SHAPE)},
              "inlet": {"pressure": 1.1e4}, "outlet": {"pressure": 1.0e4}, "walls": "wall",
              "boundaries": {"ymin": "symmetry", "ymax": "symmetry", "zmin": {"pressure": 1.0e4}},
              "rho": 1000.0, "mu": 1.0e-3, "transient": True, "dt": DT, "tolerance": 1e-10, **settings}
    return ChorinSolver(ChorinSpec.from_config(config))


def block():
    """Solid fractions of the block (its top 0.7 of a cell into the fourth layer) and a velocity
    that bends it: downwards, faster at the ends of the channel than in its middle, growing from
    the base; in the solid-centred top layer 0.999 mm/s mean."""
    nx, ny, nz = SHAPE
    f = np.zeros((nz, ny, nx))
    f[:3], f[3] = 1.0, 0.7
    x = (np.arange(nx) + 0.5) / nx
    v = np.zeros((nz, ny, nx, 3))
    v[..., 2] = -(np.arange(nz) / 3.0)[:, None, None] * (0.75 + 3.0 * (x - 0.5) ** 2)[None, None, :] * 1e-3
    v[4:] = 0.0
    return f.ravel(), v.reshape(-1, 3)


def mean_velocity(v) -> float:
    """The z-velocity of the block's wetted (top) layer, the mean over its cells."""
    return float(v.reshape(6, 4, 20, 3)[3, ..., 2].mean())


def normal_faces(solver, layer):
    """z-velocity targets on the horizontal faces at the top of cell layer ``layer``."""
    return solver.target[2][layer + 1]


def test_bodies_move_the_block_rigidly_with_its_wetted_layers_mean_velocity(caplog):
    f, v = block()
    top = v.reshape(6, 4, 20, 3)[3, ..., 2]
    cells = block_under_channel()  # the default: per cell
    cells.set_solid(f, v)
    assert normal_faces(cells, 3) == pytest.approx(np.broadcast_to(top, (4, 20)))  # the top bends
    assert np.ptp(normal_faces(cells, 3)) > 0.5e-3
    bodies = block_under_channel(solid_velocity="bodies")
    with caplog.at_level(logging.WARNING, logger="varcouple.fluid_chorin"):
        bodies.set_solid(f, v)
    mean = mean_velocity(v)
    assert mean == pytest.approx(-0.999375e-3, rel=1e-12)
    for layer in range(4):  # every face of the block and its top face: the wetted layer's mean
        assert normal_faces(bodies, layer) == pytest.approx(np.full((4, 20), mean), rel=1e-12)
    assert np.abs(bodies.target[0]).max() == 0.0 and np.abs(bodies.source).max() < 1e-12  # rigid: no dilatation
    assert not caplog.records  # every face the block touches is open or tangential to its motion
    none = block_under_channel(solid_velocity="none")
    none.set_solid(f, v)
    assert all(np.abs(t).max() == 0.0 for t in none.target)


def test_a_body_on_a_closed_face_slides_along_it_and_the_drop_is_named(caplog):
    """A closed base (a wall): the block's normal velocity there is dropped, with one warning."""
    f, v = block()
    solver = block_under_channel(solid_velocity="bodies", boundaries={"ymin": "symmetry", "ymax": "symmetry"})
    with caplog.at_level(logging.WARNING, logger="varcouple.fluid_chorin"):
        solver.set_solid(f, v)
        solver.set_solid(f, v)
    assert all(np.abs(t).max() == 0.0 for t in solver.target)
    assert [r.getMessage() for r in caplog.records] == [
        "a solid body touches the closed grid face zmin: its velocity normal to it (-0.000999 m/s) is dropped; make the "
        "face open ([flow] faces = { zmin = { pressure = p } }) to let the body move through it"]


def test_a_constant_acceleration_gives_the_same_added_mass_pressure_every_step():
    """The block moved rigidly with a velocity growing by the same amount every step: the channel's
    pressure (its added mass) is the same in every step. Measured: within 1e-3 of the first step's
    (OpenFOAM's pimpleFoam on the same inputs: within 1.2e-3); with the open faces' time derivative
    taken from the inner face's u^n it drifted by 2.2 % per step."""
    f, v = block()
    solver = block_under_channel(solid_velocity="bodies")
    above = []
    for k in range(4):
        solver.set_solid(f, (k + 1) * v)
        run = solver.transient(k * DT, DT)
        assert run.converged
        above.append(solver.cell_pressure().reshape(6, 4, 20)[4].mean() - 1.0e4)
    # less the mean of the channel's linear pressure drop (500 Pa), over the acceleration (about 20 m/s^2):
    # measured 85 kg/m^2, the lubrication estimate rho_f L^2 / (12 h) is 72
    assert (500.0 - above[0]) / (-mean_velocity(v) / DT) == pytest.approx(72.0, rel=0.2)
    assert np.abs(np.array(above) / above[0] - 1).max() < 2e-3, above
