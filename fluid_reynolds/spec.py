"""The Reynolds fluid's configuration: the fluid part of the scene the flow rule fills
(:func:`coupler.plan.effects.flow.fluid_config`), as the 3D fluids get it::

    {"grid": {"origin", "spacing", "shape"}, "location": "cells", "mu": 1.0e-3,
     "inlet": ..., "outlet": ..., "walls": ..., "boundaries": {...},   # coupler/protocol/fluid_faces.py
     ...}                                  # the settings of fluid_reynolds/settings.py

Faces: a fixed pressure is a fixed pressure of the plane grid's edge there; a fixed inlet
velocity at xmin passes its x component through the open part of each inlet column; every
other condition (wall, slip, symmetry, empty) passes nothing. The faces across the fracture
(its two sides, inside the rock) are not the plane's."""

from __future__ import annotations

from dataclasses import dataclass

from coupler.protocol.fluid_faces import face_conditions
from transfer.grid import StructuredGrid

from .columns import Columns
from .reynolds import PLANE_FACES
from .settings import PARTICIPANT


@dataclass
class ReynoldsSpec:
    columns: Columns
    mu: float
    pressures: dict  # plane face -> fixed pressure [Pa]
    inlet_velocity: float | None  # the x velocity on xmin [m/s], or None
    closed: float  # the aperture [m] below which a plane cell is closed

    @classmethod
    def from_config(cls, config: dict) -> "ReynoldsSpec":
        if config.get("location", "cells") != "cells":
            raise ValueError(f"fluid_reynolds serves cell values only (location 'cells'), got "
                             f"{config.get('location')!r}")
        g = config.get("grid")
        if not isinstance(g, dict):
            raise ValueError("fluid config needs 'grid' = {origin, spacing, shape}")
        settings = PARTICIPANT.configuration(config)
        mu = float(config.get("mu", 1.0e-3))
        if mu <= 0:
            raise ValueError(f"mu must be positive, got {mu}")
        columns = Columns(StructuredGrid(g.get("origin"), g.get("spacing"), g.get("shape")), settings["resolution"])
        faces = face_conditions(config)
        pressures, inlet_velocity = {}, None
        for plane_face, face in zip(PLANE_FACES, columns.faces):
            condition = faces[face]
            if condition["kind"] == "pressure":
                pressures[plane_face] = float(condition["value"])
            elif condition["kind"] == "velocity" and face == "xmin":
                inlet_velocity = float(condition["value"][0])
            elif condition["kind"] == "velocity":
                raise ValueError(f"face {face}: the Reynolds fluid takes a fixed velocity on the inlet xmin only")
        if not pressures:
            raise ValueError("the Reynolds fluid needs a fixed pressure on at least one face (the outlet xmax)")
        return cls(columns, mu, pressures, inlet_velocity, settings["closed"] * columns.height)
