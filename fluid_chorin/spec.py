"""The Chorin fluid's configuration (the fluid's part of the scene, JSON)::

    {"grid": {"origin": [x, y, z], "spacing": [hx, hy, hz], "shape": [nx, ny, nz]},
     "location": "cells",
     "rho": 1000.0, "mu": 1.0e-3,          # kg/m^3, Pa s
     "inlet": ..., "outlet": ..., "walls": ..., "boundaries": {...},   # coupler/protocol/fluid_faces.py
     "transient": false, "dt": 1.0,
     ...}                                  # the settings of fluid_chorin/settings.py

The settings (penalization, drag, max_iterations, tolerance, cfl, poisson, substeps, ...), their
meaning, defaults and bounds: :data:`fluid_chorin.settings.PARTICIPANT`, which also checks them
here. The flow rule (:func:`coupler.plan.effects.flow.fluid_config`) fills these keys from the scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coupler.protocol.fluid_faces import face_conditions
from transfer.grid import BOX_FACES, StructuredGrid
from transfer.penalization import default_drag

from .settings import PARTICIPANT


@dataclass
class ChorinSpec:
    grid: StructuredGrid
    faces: dict
    rho: float
    mu: float
    penalization: str
    penalization_exponent: float
    drag: float | None
    max_iterations: int
    tolerance: float
    cfl: float
    transient: bool
    dt: float
    substeps: int
    outer_correctors: int
    poisson: str
    solid_velocity: str
    slab_axis: str
    steady: str
    newton_iterations: int
    error_estimate: bool

    @property
    def nu(self) -> float:
        return self.mu / self.rho

    def drag_value(self) -> float:
        """The maximum drag D_max [1/s]: as given, else :func:`default_drag` (as the OpenFOAM fluid)."""
        if self.drag is not None:
            return float(self.drag)
        u_ref = max((float(np.linalg.norm(c["value"])) for c in self.faces.values() if c["kind"] == "velocity"),
                    default=0.0)
        rate = self.substeps / self.dt if self.transient else 0.0
        return default_drag(self.nu, float(self.grid.spacing.min()), u_ref, rate)

    @classmethod
    def from_config(cls, config: dict) -> "ChorinSpec":
        if config.get("location", "cells") != "cells":
            raise ValueError(f"fluid_chorin serves cell values only (location 'cells'), got {config.get('location')!r}")
        g = config.get("grid")
        if not isinstance(g, dict):
            raise ValueError("fluid config needs 'grid' = {origin, spacing, shape}")
        grid = StructuredGrid(g.get("origin"), g.get("spacing"), g.get("shape"))
        faces = face_conditions(config)
        settings = PARTICIPANT.configuration(config)
        spec = cls(grid, faces, rho=float(config.get("rho", 1000.0)), mu=float(config.get("mu", 1.0e-3)),
                   transient=bool(config.get("transient", False)), dt=float(config.get("dt", 1.0)), **settings)
        spec.check()
        return spec

    def check(self) -> None:
        if self.rho <= 0 or self.mu <= 0:
            raise ValueError(f"rho and mu must be positive, got {self.rho}, {self.mu}")
        if self.dt <= 0:
            raise ValueError(f"dt must be positive, got {self.dt}")
        for d, (a, b) in enumerate(zip(BOX_FACES[::2], BOX_FACES[1::2])):
            ea, eb = self.faces[a]["kind"] == "empty", self.faces[b]["kind"] == "empty"
            if ea != eb or (ea and self.grid.shape[d] != 1):
                raise ValueError(f"'empty' needs both {a} and {b} and one cell in that direction")
            for face in (a, b):
                if self.faces[face]["kind"] == "pressure" and self.grid.shape[d] < 2:
                    raise ValueError(f"a fixed-pressure face ({face}) needs at least 2 cells along "
                                     f"{'xyz'[d]}, got {self.grid.shape[d]}")
