"""Role contracts (docs/protocol.md, "Roles"): what a participant in a scene role (``fluid``,
``solid``; the participant's name in the plan) must and may give the coupler and take from it.

A role declares its geometry (a structured grid, or a tetrahedral mesh) and its fields: the
outputs of ``advance`` it must supply (required) or may supply, and the inputs it accepts, each
a scalar or a 3-vector per row of the participant's location (grid cells or points, mesh
vertices) or a single value. These are the fields of paper 2.3, Steps 1-6: the fluid takes the
solid fraction and velocity on its grid (Steps 6, 1) and gives pressure and velocity; the solid
takes the wetted boundary's pressure or traction (Steps 2-3) and gives displacement and
velocity (Step 4).

The field names are constants here: the coupler and the participants use them, not literals.
:func:`check_geometry` and :func:`check_outputs` are the coupler's check of every reply;
:func:`conformance` is the kit a participant object passes (tests/coupler/protocol).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from coupler.protocol.errors import ParticipantFailure
from coupler.protocol.wire import Field
from transfer.errors import MeshError
from transfer.grid import StructuredGrid

# -- field names (Steps 1-6 of paper 2.3) ---------------------------------------------------
SOLID_FRACTION = "solid_fraction"  # Q0 volume fraction of the solid in each grid cell (Step 6 -> 1)
SOLID_VELOCITY = "solid_velocity"  # the solid's velocity on the grid (Step 6 -> 1)
INLET_PRESSURE = "inlet_pressure"  # a flow-rate control's inlet pressure (one value)
PRESSURE = "pressure"
VELOCITY = "velocity"
TRACTION = "traction"  # (-p I + tau) n on the wetted boundary (Steps 2-3)
DISPLACEMENT = "displacement"
VON_MISES = "von_mises"
IN_CONTACT = "in_contact"
CONTACT_PRESSURE = "contact_pressure"
GAP = "gap"
SLAVE = "slave"
MORTAR_WEIGHT = "mortar_weight"
# optional figures of an advance reply (``report_figures``: one number, in the header)
COARSE_FLOW_RATE = "coarse_flow_rate"  # a fluid's flow rate on its grid coarsened 2x across the gap [m^3/s]
# geometry arrays (docs/protocol.md, "Parts")
POINTS, CELLS = "points", "cells"
POINT_IDS, CELL_IDS, INPUT_IDS = "point_ids", "cell_ids", "input_ids"
INTERFACE_TRIANGLES = "interface_triangles"

#: where a field lives: one row per row of the participant's location, or one value
ROWS, SINGLE = "rows", "single"


@dataclass(frozen=True)
class FieldContract:
    """One field of a role: ``components`` 1 (scalar) or 3 (vector) per row (``at`` ROWS) or a
    single value (``at`` SINGLE); ``required`` for an output the role must always supply."""

    name: str
    components: int = 1
    at: str = ROWS
    required: bool = False

    @property
    def kind(self) -> str:
        return "scalar" if self.components == 1 else f"vector ({self.components})"

    def shape(self, rows: int) -> tuple[int, ...]:
        """The array shape this field must have for a participant of `rows` rows."""
        if self.at == SINGLE:
            return (1,)
        return (rows,) if self.components == 1 else (rows, self.components)


@dataclass(frozen=True)
class GeometryArray:
    """An array of a role's ``geometry`` reply: ``width`` columns (0: one id per row), given
    ``when`` "always", on "ranks" (each part of a participant on several ranks: its ids,
    docs/protocol.md "Parts") or when it "may"."""

    name: str
    width: int
    when: str

    @property
    def kind(self) -> str:
        return "ids (n,)" if self.width == 0 else f"(n, {self.width})"


@dataclass(frozen=True)
class Role:
    """A role's contract: its geometry (``grid`` or ``mesh``) and the arrays of its reply, the
    locations its fields may live at (the geometry header's ``location``; the first one the
    default) and its fields."""

    name: str
    geometry: str
    locations: tuple[str, ...]
    arrays: tuple[GeometryArray, ...]
    outputs: tuple[FieldContract, ...]
    inputs: tuple[FieldContract, ...]

    def output(self, name: str) -> FieldContract | None:
        return next((f for f in self.outputs if f.name == name), None)


ROLES: dict[str, Role] = {r.name: r for r in (
    Role("fluid", geometry="grid", locations=("cells", "points"),
         arrays=(GeometryArray(CELL_IDS, 0, "ranks"), GeometryArray(INPUT_IDS, 0, "may")),
         outputs=(FieldContract(PRESSURE, 1, required=True), FieldContract(VELOCITY, 3, required=True)),
         inputs=(FieldContract(SOLID_FRACTION, 1), FieldContract(SOLID_VELOCITY, 3),
                 FieldContract(INLET_PRESSURE, 1, SINGLE))),
    Role("solid", geometry="mesh", locations=("points",),
         arrays=(GeometryArray(POINTS, 3, "always"), GeometryArray(CELLS, 4, "always"),
                 GeometryArray(POINT_IDS, 0, "ranks"), GeometryArray(CELL_IDS, 0, "ranks"),
                 GeometryArray(INTERFACE_TRIANGLES, 3, "may")),
         outputs=(FieldContract(DISPLACEMENT, 3, required=True), FieldContract(VELOCITY, 3, required=True),
                  FieldContract(VON_MISES, 1), FieldContract(IN_CONTACT, 1), FieldContract(CONTACT_PRESSURE, 1),
                  FieldContract(GAP, 1), FieldContract(SLAVE, 1), FieldContract(MORTAR_WEIGHT, 1)),
         inputs=(FieldContract(PRESSURE, 1), FieldContract(TRACTION, 3))),
)}


class ContractError(ParticipantFailure):
    """A participant's reply breaks its role's contract: one line naming the participant, the
    role, the field and what is wrong."""

    def __init__(self, name: str, role: str, what: str):
        self.role, self.what = role, what
        super().__init__(name, f"participant {name!r} (role {role}): {what}")


def _grid_rows(name: str, role: str, grid, location: str) -> int:
    """The rows of a grid participant's fields: its cells or points (:class:`transfer.StructuredGrid`
    checks the grid)."""
    try:
        shape = np.asarray(grid["shape"])
        if not np.issubdtype(shape.dtype, np.integer):
            raise ValueError(f"shape must be integers, got {grid['shape']!r}")
        g = StructuredGrid(grid["origin"], grid["spacing"], shape, name="geometry 'grid'")
    except (KeyError, TypeError, ValueError, MeshError) as exc:
        raise ContractError(name, role, f"geometry 'grid' (origin, spacing, shape): {exc}") from None
    return g.num_points if location == "points" else g.num_cells


def check_geometry(name: str, header: Mapping, fields: Mapping) -> int | None:
    """Check participant `name`'s (whole) ``geometry`` reply against its role's contract (None:
    a participant of no role, e.g. a mesh file); return the rows its fields must have."""
    role = ROLES.get(name)
    if role is None:
        return None
    location = header.get("location", role.locations[0])
    if location not in role.locations:
        raise ContractError(name, role.name, f"geometry 'location' {location!r} is not one of {list(role.locations)}")
    if role.geometry == "grid" and "grid" not in header:
        raise ContractError(name, role.name, "geometry: missing 'grid' (a structured grid: origin, spacing, shape)")
    if role.geometry == "mesh" and header.get("cell_type") != "tetra":
        raise ContractError(name, role.name, f"geometry: cell_type {header.get('cell_type')!r}, expected 'tetra'")
    arrays = {k: np.asarray(getattr(f, "data", f)) for k, f in (fields or {}).items()}
    for a in role.arrays:
        if a.name not in arrays:
            if a.when == "always":
                raise ContractError(name, role.name, f"geometry: missing {a.name!r}")
            continue
        shape = arrays[a.name].shape
        if shape[1:] != ((a.width,) if a.width else ()) or len(shape) != (2 if a.width else 1):
            raise ContractError(name, role.name, f"geometry {a.name!r}: wrong shape {shape}, expected {a.kind}")
    if role.geometry == "grid":
        return _grid_rows(name, role.name, header["grid"], location)
    return len(arrays[POINTS])


def check_outputs(name: str, outputs: Mapping, rows: int | None) -> None:
    """Check participant `name`'s (whole) ``advance`` outputs against its role's contract: every
    required field present, every field one its role declares, each of its shape for `rows`
    rows (from :func:`check_geometry`). NaN and inf are refused by the wire (transfer.FieldError)."""
    role = ROLES.get(name)
    if role is None or rows is None:
        return
    for f in role.outputs:
        if f.required and f.name not in outputs:
            raise ContractError(name, role.name, f"advance output {f.name!r}: missing (required, {f.kind})")
    for key, value in outputs.items():
        f = role.output(key)
        if f is None:
            raise ContractError(name, role.name, f"advance output {key!r}: not a field of its role (it may supply "
                                                 f"{', '.join(o.name for o in role.outputs)})")
        shape = np.shape(getattr(value, "data", value))
        if shape != f.shape(rows):
            raise ContractError(name, role.name, f"advance output {key!r}: wrong shape {shape}, expected "
                                                 f"{f.shape(rows)} ({f.kind} per row of {rows})")


def check_announce(name: str, announced: Mapping) -> None:
    """Check participant `name`'s ``announce``: it provides every required output and accepts only
    inputs its role declares."""
    role = ROLES.get(name)
    if role is None:
        return
    provides, accepts = set(announced.get("provides", [])), set(announced.get("accepts", []))
    missing = [f.name for f in role.outputs if f.required and f.name not in provides]
    if missing:
        raise ContractError(name, role.name, f"announce 'provides': missing {', '.join(missing)}")
    unknown = sorted(accepts - {f.name for f in role.inputs})
    if unknown:
        raise ContractError(name, role.name, f"announce 'accepts': {', '.join(unknown)} not an input of its role")


def inputs_for(name: str, rows: int, accepted) -> dict[str, np.ndarray]:
    """Zero inputs of the right shape for every field of role `name` in `accepted` (the kit's advance)."""
    role = ROLES[name]
    return {f.name: np.zeros(f.shape(rows)) for f in role.inputs if f.name in accepted}


def conformance(name: str, participant, config: Mapping, inputs=None) -> dict:
    """The conformance kit: configure `participant` (an object of
    :class:`~coupler.protocol.participant.Participant`, one rank) in role `name` with `config`,
    check its announce, geometry and one ``advance`` against the role's contract; return the
    outputs. The advance gets zeros of the right shape for each field named in `inputs` (default:
    every input it announces). Raises :class:`ContractError` naming what is wrong."""
    announced = participant.announce()
    check_announce(name, announced)
    participant.configure(dict(config))
    header, fields = participant.geometry()
    rows = check_geometry(name, header, fields or {})
    given = inputs_for(name, rows, announced.get("accepts", []) if inputs is None else inputs)
    outputs = participant.advance(0, 0, 0.0, 1.0, {k: Field(k, v) for k, v in given.items()})
    check_outputs(name, outputs, rows)
    return outputs


def table() -> str:
    """The roles as the Markdown table of docs/protocol.md ("Roles"; a test keeps them equal)."""
    lines = ["| role | geometry | direction | field | kind | at | required |", "|" + " --- |" * 7]
    for role in ROLES.values():
        for a in role.arrays:
            lines.append(f"| {role.name} | {role.geometry} | geometry | `{a.name}` | {a.kind} | - | "
                         f"{ {'always': 'yes', 'ranks': 'on several ranks', 'may': 'no'}[a.when]} |")
        at = {ROWS: " or ".join(role.locations) if role.geometry == "grid" else "vertices", SINGLE: "one value"}
        for direction, fields in (("output", role.outputs), ("input", role.inputs)):
            for f in fields:
                lines.append(f"| {role.name} | {role.geometry} | {direction} | `{f.name}` | {f.kind} | {at[f.at]} | "
                             f"{'yes' if f.required else 'no'} |")
    return "\n".join(lines) + "\n"
