"""The boundary conditions of a fluid on the six faces of its grid, as the flow rule
(:func:`coupler.plan.effects.flow.fluid_config`) configures every fluid participant::

    {"inlet":  {"velocity": [1, 0, 0]}   # at xmin: fixed velocity (m/s)
               or {"pressure": 1.0e3},   #          fixed pressure (Pa)
     "outlet": {"pressure": 0.0},        # at xmax: fixed pressure (Pa)
     "walls": "wall",                    # every other face (default no-slip wall)
     "boundaries": {"zmin": "empty", "zmax": "empty"}}   # per-face override

A face condition is ``"wall"`` (no slip), ``"slip"``, ``"symmetry"``, ``"empty"`` (2D: both
faces of the direction with one cell), ``{"velocity": [u, v, w]}`` or ``{"pressure": p}``;
:func:`face_conditions` gives each face ``{"kind": ..., "value": ...}``.
"""

from __future__ import annotations

import numpy as np

from transfer.grid import BOX_FACES


def _face_condition(spec) -> dict:
    """Normalize a face condition to {"kind": wall|slip|symmetry|empty|velocity|pressure, "value"}."""
    if isinstance(spec, str):
        if spec not in ("wall", "slip", "symmetry", "empty"):
            raise ValueError(f"unknown face condition {spec!r} (wall, slip, symmetry, empty, "
                             "{'velocity': [u,v,w]}, {'pressure': p})")
        return {"kind": spec}
    if isinstance(spec, dict) and len(spec) == 1 and "velocity" in spec:
        v = np.asarray(spec["velocity"], dtype=float).reshape(-1)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"velocity must be 3 finite numbers, got {spec!r}")
        return {"kind": "velocity", "value": v}
    if isinstance(spec, dict) and len(spec) == 1 and "pressure" in spec:
        p = float(spec["pressure"])
        if not np.isfinite(p):
            raise ValueError(f"pressure must be finite, got {spec!r}")
        return {"kind": "pressure", "value": p}
    raise ValueError(f"bad face condition {spec!r}")


def face_conditions(config: dict) -> dict[str, dict]:
    """Condition per box face from the fluid config (see module doc)."""
    walls = config.get("walls", "wall")
    out = {f: _face_condition(walls) for f in BOX_FACES}
    out["xmin"] = _face_condition(config.get("inlet", {"velocity": [1.0, 0.0, 0.0]}))
    out["xmax"] = _face_condition(config.get("outlet", {"pressure": 0.0}))
    for face, spec in (config.get("boundaries") or {}).items():
        if face not in BOX_FACES:
            raise ValueError(f"unknown face {face!r} in boundaries (faces: {', '.join(BOX_FACES)})")
        out[face] = _face_condition(spec)
    return out


def closed_faces(faces: dict) -> list[str]:
    """The grid faces no flow may cross (every face but the fixed-pressure ones)."""
    return [f for f, c in faces.items() if c["kind"] != "pressure"]


def dropped_velocity(face: str, value: float) -> str:
    """The warning of a solid body's velocity dropped at the closed grid face ``face``
    (:func:`transfer.bodies.rigid_bodies`)."""
    hint = "[flow] inlet_pressure" if face == "xmin" else f"[flow] faces = {{ {face} = {{ pressure = p }} }}"
    return (f"a solid body touches the closed grid face {face}: its velocity normal to it ({value:.3g} m/s) is "
            f"dropped; make the face open ({hint}) to let the body move through it")
