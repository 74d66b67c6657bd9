"""``[check] kind = "uniaxial"``: a box under a uniform pressure p on one face, on rollers (one
face normal to each axis held in that axis): uniaxial stress sigma_kk = -p along the loaded
axis k, so u_k = -p (x_k - x0_k) / E and u_j = nu p (x_j - x0_j) / E across it, x0 the
rollers' planes; P1 elements reproduce it. E, nu, p and the faces come from the scene."""

from __future__ import annotations

import numpy as np

from coupler.checks.expression import compare
from transfer.grid import BOX_FACES

KIND = "uniaxial"
DESCRIPTION = "a box on rollers under a pressure on one face: the uniaxial-stress displacement"
DISTRIBUTED = True
KEYS = {"tolerance": "largest relative error accepted (of the displacement, over all vertices)"}


def _face(scene, table, load) -> str:
    """The box face a load acts on (its boundary is a box face, not a named subset of one)."""
    if scene.solid.box is None or scene.solid.boundaries.get(load.boundary) not in BOX_FACES:
        raise table.error("kind", f"'uniaxial' needs a box (the [geometry.solid] box keys) whose loads act "
                                  f"on whole faces ({', '.join(BOX_FACES)}); {load.type} load on "
                                  f"{load.boundary!r}")
    return scene.solid.boundaries[load.boundary]


def parse(table, scene) -> dict:
    pressures = [load for load in scene.loads if load.type != "dirichlet"]
    if len(pressures) != 1 or pressures[0].type != "pressure":
        raise table.error("kind", f"'uniaxial' needs exactly one load besides the rollers, a pressure on a face; "
                                  f"got {[load.type for load in pressures]}")
    face = _face(scene, table, pressures[0])
    box = scene.solid.box
    planes = [None, None, None]  # x0 of each axis: the plane of the face holding that component
    for load in scene.loads:
        if load.type != "dirichlet":
            continue
        held = _face(scene, table, load)
        axis = "xyz".index(held[0])
        if load.value != 0.0 or load.components != [held[0]]:
            raise table.error("kind", f"'uniaxial' needs rollers: dirichlet loads holding the normal component "
                                      f"(value 0) of a face; {load.boundary!r} holds {load.components} at "
                                      f"{load.value:g}")
        planes[axis] = box["lower" if held.endswith("min") else "upper"][axis]
    if None in planes:
        missing = [c for c, plane in zip("xyz", planes) if plane is None]
        raise table.error("kind", f"'uniaxial' needs a roller normal to every axis; none holds {missing}")
    return {"axis": "xyz".index(face[0]), "pressure": float(pressures[0].value), "planes": planes,
            "tolerance": table.number("tolerance", positive=True)}


def evaluate(settings, scene, result) -> dict:
    E, nu, p = scene.material["E"], scene.material["nu"], settings["pressure"]
    strain = [nu * p] * 3  # times 1 / E, applied last
    strain[settings["axis"]] = -p
    exact = {axis: (lambda x, axis=axis: strain[axis] * (x[:, axis] - settings["planes"][axis]) / E)
             for axis in range(3)}
    points, fields = result.rows("solid")
    report = compare(points, fields["displacement"], exact, np.ones(len(points), bool),
                     settings["tolerance"], f"{scene.path}: [check]", result.sums)
    return {**report, "stress": -p, "axis": "xyz"[settings["axis"]]}


def describe(report: dict) -> str:
    return (f"uniaxial stress {report['stress']:g} Pa along {report['axis']}: displacement error "
            f"{report['error']:.3e} relative on {report['vertices']} vertices")
