"""Scenes of coupled cases: geometry, materials, loads, effects, solvers, coupling, outputs.

A coupled scene (``cases/NAME/scene.toml`` with a ``[physics]`` table) is
validated as a whole before anything runs; every error names the scene file,
the table and key, and the reason (``<scene.toml>: [loads.3] boundary: ...``).
cases/README.md documents every key. :mod:`coupler.plan` turns a scene into
the participants to start and the fields that cross.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from coupler import checks
from coupler.errors import SceneError
from coupler.protocol.transport import check_endpoint
from coupler.protocol.settings import REQUIRED
from coupler.scene.participants import Solver, read_solver
from coupler.scene.tables import Table, in_case, output_directory
from coupler.protocol.expressions import check_expression
from transfer.generators import GENERATORS, notes, parameters
from transfer.grid import BOX_FACES

LOAD_TYPES = ("dirichlet", "pressure", "traction", "body_force", "fluid_pressure", "platen")
#: loads whose value may be a list, one value per step
STEPPED_LOADS = ("dirichlet", "pressure", "fluid_pressure")
ACCELERATIONS = ("constant", "aitken", "iqn-ils")
#: [coupling] traction: the fluid's pressure only, or its full stress with the viscous part (coupler/viscous.py)
TRACTIONS = ("pressure", "full")

#: environment variable giving the default of ``[output] pictures`` (the tests set it to 0)
PICTURES_VAR = "VARCOUPLE_PICTURES"


def pictures_default() -> bool:
    return os.environ.get(PICTURES_VAR, "1").strip().lower() not in ("0", "false", "no", "off")


@dataclass
class SolidGeometry:
    mesh: Path | None  # a mesh file, or None for the box or a generator
    box: dict | None  # lower, upper, shape, jitter, seed
    boundaries: dict[str, str | int]  # name -> expression on facet midpoints, box face, or file/generator tag
    generator: dict | None = None  # {"name": ..., "parameters": {...}} (transfer.generators), defaults filled in
    notes: tuple[str, ...] = ()  # what the generator did to its input that the user should know (its ``notes``)


@dataclass
class FluidGeometry:
    origin: list[float]
    spacing: list[float]
    shape: list[int]


@dataclass
class Load:
    type: str
    boundary: str | None
    value: object  # float, [3 floats], or one float per step (a list: STEPPED_LOADS); platen: the stresses
    components: list[str] = field(default_factory=lambda: ["x", "y", "z"])
    settings: dict = field(default_factory=dict)  # platen: tolerance, area, max_iterations

    @property
    def per_step(self) -> bool:
        """One value per step (a platen's stresses, or a list value)."""
        return self.type == "platen" or (self.type in STEPPED_LOADS and isinstance(self.value, list))


@dataclass
class CoupledScene:
    path: Path
    case_dir: Path
    description: str
    effects: list[str]
    solid: SolidGeometry
    fluid: FluidGeometry | None
    material: dict  # E, nu, density
    fluid_material: dict  # density, viscosity (water if the scene gives none)
    loads: list[Load]
    solvers: dict[str, Solver]  # role ("solid", "fluid") -> its [solvers.X], validated through its participant
    time: dict  # dt, steps
    coupling: dict
    messaging: dict
    output_dir: Path
    output: dict
    check: dict | None = None  # [check]: {"kind": ..., **the kind's settings} (coupler/checks)
    resources: dict = field(default_factory=lambda: {"memory_limit": None, "check_memory": True})
    effect_settings: dict = field(default_factory=dict)  # effect -> what its rule read of its own tables

    @property
    def flow(self) -> dict | None:
        """The fluid's boundary conditions ([flow], effect 'flow')."""
        return self.effect_settings.get("flow")

    @property
    def contact(self) -> dict | None:
        """The contact faces and solver ([contact], effect 'contact')."""
        return self.effect_settings.get("contact")

    def error(self, table: str, key: str, reason: str) -> SceneError:
        return SceneError(f"{self.path}: [{table}] {key}: {reason}")


TABLES = {
    "case": {"description": "one line on what the case shows"},
    "physics": {"effects": "list of effects (coupler/plan/effects: one module each)"},
    "geometry": {"solid": "table: the rock mesh", "fluid": "table: the structured fluid grid"},
    "materials": {"solid": "table: E, nu, density of the rock", "fluid": "table: density, viscosity"},
    "loads": {},
    "solvers": {"solid": "table: the solid participant", "fluid": "table: the fluid participant"},
    "time": {"dt": "time step [s]", "steps": "number of time steps"},
    "coupling": {"acceleration": f"one of {', '.join(ACCELERATIONS)}", "relaxation": "initial relaxation",
                 "tolerance": "relative interface residual (mass-weighted L2)",
                 "max_iterations": "per time step", "reuse": "IQN-ILS: past time windows reused",
                 "columns": "IQN-ILS: at most this many secant columns, newest first (default 100)",
                 "interface": "the solid boundary (or list of boundaries) the fluid pressure acts on (flow)",
                 "deformation": "true: the fluid sees the deformed solid (two-way); false: the undeformed one",
                 "traction": "what of the fluid's stress loads the rock: 'pressure' (default, -p n) or 'full' "
                             "((-p I + tau) n with the viscous wall shear)",
                 "ranks": "MPI ranks of the coupler itself (default 1; mpirun -n P varcouple run gives P)"},
    "messaging": {"mode": "zenoh mode: peer (default) or client", "connect": "zenoh endpoints to connect to",
                  "timeout": "seconds to wait for a participant's answer"},
    "resources": {"memory_limit": "memory this run may use [bytes] (default: what the machine has available)",
                  "check_memory": "refuse a scene whose estimated memory exceeds what is available (default "
                                  "true; false runs it anyway)"},
    "output": {"directory": "output directory inside the case, relative to it (default 'results'; the command "
                            "line's --output DIR may be anywhere)",
               "every": "write fields every N steps (default 1)",
               "pictures": "render PNG pictures of what the scene simulated (default true; the environment "
                           "variable VARCOUPLE_PICTURES=0 makes false the default)"},
    "check": {"kind": "the known solution compared with the result (coupler/checks: one module per kind)"},
}
SOLID_KEYS = {"mesh": "mesh file (any format meshio reads) inside the case, relative to it",
              "generator": "a geometry generator of transfer.generators (its faces are named boundaries)",
              "parameters": "table: the generator's parameters",
              "lower": "box generator: lower corner", "upper": "box generator: upper corner",
              "shape": "box generator: cells per axis", "jitter": "box generator: random vertex shift",
              "seed": "box generator: random seed", "boundaries": "table: name -> boundary"}
FLUID_KEYS = {"origin": "grid origin", "spacing": "grid spacing", "shape": "cells per axis",
              "lower": "grid lower corner (instead of origin/spacing)", "upper": "grid upper corner",
              "generator": "the grid made by the solid's generator for it (its name), instead of the keys above"}
#: how a platen finds its displacement (:class:`solid_fenicsx.platen.Platen`)
PLATEN_METHODS = ("search", "constraint")
LOAD_KEYS = {"type": f"one of {', '.join(LOAD_TYPES)}", "boundary": "a named boundary",
             "value": "number (pressure, fixed value) or [x, y, z] (traction, body force); dirichlet, pressure, "
                      "fluid_pressure: or a list of numbers, one per step",
             "components": "dirichlet: constrained components, subset of ['x', 'y', 'z']",
             "stress": "platen: the target mean normal stress of each step [Pa], a list",
             "tolerance": "platen: relative tolerance on each target stress (default 1e-3)",
             "area": "platen: the area the mean stress is taken over [m^2] (default: the boundary's, projected)",
             "max_iterations": "platen: solves per step to find the platen's displacement (default 20)",
             "method": "platen: 'search' (default: secant steps of full solves) or 'constraint' (with contact: "
                       "the displacement one more unknown of a single contact solve, its mean force the "
                       "constraint)"}

def parse(path: Path, case_dir: Path, data: dict, output: str | Path | None = None) -> CoupledScene:
    """Validate the tables of a coupled scene (already read from TOML): the tables every scene
    has here, then each effect's own tables through its rule (:mod:`coupler.plan.effects`)."""
    from coupler.plan.effects import RULES

    owned = {table: name for name, rule in RULES.items() for table in getattr(rule, "TABLES", {})}
    for name in data:
        if name not in TABLES and name not in owned:
            known = ", ".join(f"[{t}]" for t in [*TABLES, *owned])
            raise SceneError(f"{path}: unknown table [{name}]; known tables: {known}")
    case = Table(path, "case", data.get("case", {}), TABLES["case"])
    physics = Table(path, "physics", data["physics"], TABLES["physics"])
    effects = physics.strings("effects", choices=list(RULES))
    if not effects:
        raise physics.error("effects", "must name at least one effect")
    for name in effects:  # what each effect builds on (contact on an elastic solid, ...)
        for need in getattr(RULES[name], "NEEDS", ()):
            if need not in effects:
                raise physics.error("effects", f"{name!r} needs {need!r} ({RULES[need].DESCRIPTION}); got {effects!r}")
    roles = {role for name in effects for role in getattr(RULES[name], "ROLES", ())}
    domains = {domain for name in effects for domain in getattr(RULES[name], "DOMAINS", ())}

    geometry = Table(path, "geometry", data.get("geometry", {}), TABLES["geometry"])
    solid = None
    if "solid" in domains:
        if "solid" not in geometry.data:
            raise geometry.error("solid", "missing (the rock: a mesh file, a box or a generator)")
        solid = _solid_geometry(path, case_dir, geometry.data["solid"])
    elif "solid" in geometry.data:
        raise geometry.error("solid", f"no effect of {effects!r} has a solid")
    fluid = _fluid_geometry(path, geometry.data["fluid"], solid) if "fluid" in geometry.data else None

    materials = Table(path, "materials", data.get("materials", {}), TABLES["materials"])
    material = {}
    if "solid" in roles:  # a deforming solid
        if "solid" not in materials.data:
            raise materials.error("solid", "missing (E, nu, density of the rock)")
        rock = Table(path, "materials.solid", materials.data["solid"],
                     {"E": "Young's modulus [Pa]", "nu": "Poisson ratio", "density": "[kg/m^3]"})
        material = {"E": rock.number("E", positive=True), "nu": rock.number("nu", minimum=-0.99, maximum=0.4999999),
                    "density": rock.number("density", default=2600.0, positive=True)}
    elif "solid" in materials.data:
        raise materials.error("solid", f"the material of a deforming solid, but no effect of {effects!r} deforms "
                                       f"one (a fixed solid needs none)")
    water = Table(path, "materials.fluid", materials.data.get("fluid", {}),  # water unless the scene says
                  {"density": "[kg/m^3]", "viscosity": "dynamic viscosity [Pa s]"})
    fluid_material = {"density": water.number("density", default=1000.0, positive=True),
                      "viscosity": water.number("viscosity", default=1e-3, positive=True)}

    if "solid" in roles:
        loads = _loads(path, data.get("loads", []), solid, effects)
    elif data.get("loads"):
        raise SceneError(f"{path}: [[loads]]: loads act on a deforming solid, but no effect of {effects!r} "
                         f"deforms one")
    else:
        loads = []
    per_step = {len(load.value) for load in loads if load.per_step}

    solvers = Table(path, "solvers", data.get("solvers", {}), TABLES["solvers"])
    solver_cfg = {}
    if "solid" in roles:
        solver_cfg["solid"] = read_solver(path, "solid", solvers.data.get("solid", {}))
    elif "solid" in solvers.data:
        raise solvers.error("solid", f"no effect of {effects!r} needs a solid participant (a fixed solid is "
                                     f"served by the coupler)")
    if any("fluid" in getattr(RULES[e], "ROLES", ()) for e in effects):
        if fluid is None:
            raise geometry.error("fluid", "missing: the scene asks for 'flow' but has no fluid domain (a grid)")
        solver_cfg["fluid"] = read_solver(path, "fluid", solvers.data.get("fluid", {}))

    time = Table(path, "time", data.get("time", {}), TABLES["time"])
    stepped = any(getattr(RULES[e], "TIME_STEPS", False) for e in effects)  # dynamics, flow: dt and steps given
    time_cfg = {"dt": time.number("dt", default=REQUIRED if stepped else 1.0, positive=True),
                "steps": time.integer("steps", default=REQUIRED if stepped else max(per_step, default=1))}
    _check_steps(path, loads, time_cfg["steps"], "steps" in time.data)

    coupling = Table(path, "coupling", data.get("coupling", {}), TABLES["coupling"])
    coupling_cfg = {"acceleration": coupling.string("acceleration", "iqn-ils", ACCELERATIONS),
                    "relaxation": coupling.number("relaxation", 0.5, minimum=1e-6, maximum=1.0),
                    "tolerance": coupling.number("tolerance", 1e-6, positive=True),
                    "max_iterations": coupling.integer("max_iterations", 50),
                    "reuse": coupling.integer("reuse", 8, minimum=0),
                    "columns": coupling.integer("columns", 100),
                    "interface": _interface(coupling),
                    "deformation": coupling.boolean("deformation", True),
                    "traction": coupling.string("traction", "pressure", TRACTIONS),
                    "ranks": coupling.integer("ranks", 1)}
    if coupling_cfg["traction"] == "full" and "flow" not in effects:
        raise coupling.error("traction", "'full' (the viscous stress of a flow) needs the effect 'flow'")
    solid_kind = solver_cfg["solid"].kind if "solid" in solver_cfg else "a fixed solid"
    if coupling_cfg["traction"] == "full" and solid_kind != "solid_fenicsx":
        raise coupling.error("traction", f"'full' needs a solid with a wetted surface (solid_fenicsx), got "
                                         f"{solid_kind!r}")
    messaging = Table(path, "messaging", data.get("messaging", {}), TABLES["messaging"])
    messaging_cfg = {"mode": messaging.string("mode", "peer", ("peer", "client")),
                     "connect": messaging.strings("connect", []),
                     "timeout": messaging.number("timeout", 300.0, positive=True)}
    for endpoint in messaging_cfg["connect"]:
        try:
            check_endpoint(endpoint)
        except ValueError as exc:
            raise messaging.error("connect", str(exc)) from None
    if messaging_cfg["mode"] == "client" and not messaging_cfg["connect"]:
        raise messaging.error("connect", "client mode needs the zenoh router(s) to connect to, e.g. "
                                         "connect = [\"tcp/192.168.1.10:7447\"]")

    res = Table(path, "resources", data.get("resources", {}), TABLES["resources"])
    resources = {"memory_limit": res.number("memory_limit", None, positive=True),
                 "check_memory": res.boolean("check_memory", True)}

    out = Table(path, "output", data.get("output", {}), TABLES["output"])
    output_dir = output_directory(case_dir, out, output)
    scene = CoupledScene(path=path, case_dir=case_dir, description=case.string("description", None) or "",
                        effects=effects, solid=solid, fluid=fluid, material=material,
                        fluid_material=fluid_material, loads=loads, solvers=solver_cfg, time=time_cfg,
                        coupling=coupling_cfg, messaging=messaging_cfg, output_dir=output_dir,
                        output={"every": out.integer("every", 1),
                                "pictures": out.boolean("pictures", pictures_default())},
                        resources=resources)
    for table, name in owned.items():
        if table in data and name not in effects:
            raise SceneError(f"{path}: [{table}]: needs the effect {name!r} in [physics] effects")
    for name, rule in RULES.items():  # in the rules' order: a rule may read what an earlier one parsed
        if name in effects and hasattr(rule, "parse"):
            rule.parse(scene, data)
    for role, solver in solver_cfg.items():  # what a participant cannot run, in its own words
        reason = solver.spec.refuses(scene) if solver.spec.refuses else None
        if reason:
            raise SceneError(f"{path}: [solvers.{role}] participant = {solver.kind!r}: {reason}")
    if "check" in data:  # last: a check kind takes its parameters from the validated scene
        scene.check = checks.parse(path, data["check"], scene)
    return scene


def _interface(coupling: Table):
    """[coupling] interface: one boundary name, or a non-empty list of names (e.g. both faces
    of a fracture)."""
    value = coupling.data.get("interface")
    if isinstance(value, list):
        if not value:
            raise coupling.error("interface", "an empty list: name at least one boundary")
        return coupling.strings("interface")
    return coupling.string("interface", None)


def _solid_geometry(path, case_dir, data) -> SolidGeometry:
    t = Table(path, "geometry.solid", data, SOLID_KEYS)
    mesh = t.string("mesh", None)
    box = None
    box_keys = [k for k in ("lower", "upper", "shape", "jitter", "seed") if k in t.data]
    if "parameters" in t.data and "generator" not in t.data:
        raise t.error("parameters", "parameters of no generator: give [geometry.solid] generator = \"NAME\"")
    if "generator" in t.data:
        if mesh is not None or box_keys:
            raise t.error("generator", "give one of a mesh file, the box keys (lower, upper, shape) or a generator")
        generator = _generator(t, case_dir)
        faces = dict(getattr(GENERATORS[generator["name"]], "FACES", {}))
        return SolidGeometry(mesh=None, box=None, boundaries={**faces, **_boundaries(path, t, None, faces)},
                             generator=generator, notes=tuple(notes(generator["name"], generator["parameters"])))
    if mesh is not None:
        if box_keys:
            raise t.error("mesh", "give either a mesh file or the box keys (lower, upper, shape), not both")
        mesh = t.file("mesh", case_dir)
        if mesh.suffix.lower() == ".xdmf":  # dolfinx reads the .h5 of its name beside it
            in_case(case_dir, str(Path(t.string("mesh")).with_suffix(".h5")), t.where("mesh"))
    else:
        if "lower" not in t.data and "upper" not in t.data:
            raise t.error("mesh", "missing: give a mesh file, or a box with lower, upper and shape")
        lower, upper = t.point("lower"), t.point("upper")
        if any(u <= lo for lo, u in zip(lower, upper)):
            raise t.error("upper", f"must exceed lower in every coordinate, got {lower} .. {upper}")
        shape = t.shape("shape")
        box = {"lower": lower, "upper": upper, "shape": shape,
               "jitter": t.number("jitter", 0.0, minimum=0.0, maximum=0.24), "seed": t.integer("seed", 0, minimum=0)}
    boundaries = _boundaries(path, t, box, {})
    if box is not None:  # the box's faces first: a named boundary takes its facets from them (a facet has one tag)
        boundaries = {**{face: face for face in BOX_FACES if face not in boundaries}, **boundaries}
    return SolidGeometry(mesh=mesh, box=box, boundaries=boundaries)


def _generator(t: Table, case_dir) -> dict:
    """``[geometry.solid] generator`` and its checked ``parameters`` (transfer.generators); the
    parameters its module lists in ``FILES`` name files relative to the case directory, inside it."""
    name = t.string("generator", choices=tuple(GENERATORS))
    values = t.data.get("parameters", {})
    if not isinstance(values, dict):
        raise t.error("parameters", f"must be a table of the generator's parameters, got {values!r}")
    files = getattr(GENERATORS[name], "FILES", ())
    values = {k: str(in_case(case_dir, v, f"{t.path}: [geometry.solid.parameters] {k}").resolve())
              if k in files and isinstance(v, str) and v else v for k, v in values.items()}
    try:
        return {"name": name, "parameters": parameters(name, values)}
    except ValueError as exc:
        raise SceneError(f"{t.path}: [geometry.solid.parameters] {exc}") from None


def _boundaries(path, t: Table, box, faces: dict) -> dict:
    """[geometry.solid.boundaries]: name -> box face, expression or tag; a generator's
    face names (`faces`) are taken."""
    boundaries = {}
    b = t.data.get("boundaries", {})
    if not isinstance(b, dict):
        raise t.error("boundaries", f"must be a table name -> boundary, got {b!r}")
    for name, spec in b.items():
        where = f"{path}: [geometry.solid.boundaries] {name}"
        if isinstance(spec, bool) or not isinstance(spec, (str, int)):
            raise SceneError(f"{where}: must be a box face ({', '.join(BOX_FACES)}), an expression in x, y, z "
                             f"true on the boundary's facets, or a tag number of the mesh file; got {spec!r}")
        if isinstance(spec, str) and spec not in BOX_FACES:
            check_expression(spec, where)
        if isinstance(spec, int) and box is not None:
            raise SceneError(f"{where}: tag numbers need a mesh file; the box has faces {', '.join(BOX_FACES)}")
        if name in faces:
            raise SceneError(f"{where}: the generator names a face {name!r} already; choose another name")
        boundaries[name] = spec
    return boundaries


def _fluid_geometry(path, data, solid: SolidGeometry | None) -> FluidGeometry:
    t = Table(path, "geometry.fluid", data, FLUID_KEYS)
    if "generator" in t.data:  # the grid a solid generator made for its geometry (an immersed-boundary study)
        name = t.string("generator")
        made = solid.generator if solid is not None else None
        if made is None or made["name"] != name:
            solid_is = f"[geometry.solid] generator is {made['name']!r}" if made else "the solid is not generated"
            raise t.error("generator", f"{name!r}: the grid comes from the solid's generator, and {solid_is}")
        if not hasattr(GENERATORS[name], "grid"):
            raise t.error("generator", f"generator {name!r} makes no fluid grid; give origin, spacing and shape")
        if len(t.data) > 1:
            other = next(k for k in t.data if k != "generator")
            raise t.error(other, f"the grid comes from generator {name!r}; give no other key")
        g = GENERATORS[name].grid(made["parameters"])
        return FluidGeometry(g["origin"], g["spacing"], g["shape"])
    shape = t.shape("shape")
    if "lower" in t.data or "upper" in t.data:
        lower, upper = t.point("lower"), t.point("upper")
        if any(u <= lo for lo, u in zip(lower, upper)):
            raise t.error("upper", f"must exceed lower in every coordinate, got {lower} .. {upper}")
        return FluidGeometry(lower, [(u - lo) / n for lo, u, n in zip(lower, upper, shape)], shape)
    spacing = t.point("spacing")
    if any(h <= 0 for h in spacing):
        raise t.error("spacing", f"must be positive, got {spacing}")
    return FluidGeometry(t.point("origin"), spacing, shape)


def _loads(path, data, solid: SolidGeometry, effects) -> list[Load]:
    if not isinstance(data, list):
        raise SceneError(f"{path}: loads must be an array of tables ([[loads]]), got {data!r}")
    loads = []
    for i, entry in enumerate(data, start=1):
        t = Table(path, f"loads.{i}", entry, LOAD_KEYS)
        kind = t.string("type", choices=LOAD_TYPES)
        boundary = None
        if kind != "body_force":
            boundary = t.string("boundary")
            if boundary not in solid.boundaries:
                raise t.error("boundary", f"unknown boundary {boundary!r}; named boundaries: "
                                          f"{', '.join(solid.boundaries) or 'none'}")
        elif "boundary" in t.data:
            raise t.error("boundary", "a body force acts on the volume, not on a boundary")
        settings = {}
        for key in ("stress", "tolerance", "area", "max_iterations", "method"):
            if key in t.data and kind != "platen":
                raise t.error(key, "only platen loads have it")
        if kind == "platen":
            if "value" in t.data:
                raise t.error("value", "a platen is stress-controlled: give stress = [...], one per step")
            if "dynamics" in effects:
                raise t.error("type", "a platen (stress-controlled load steps) is static: not with 'dynamics'")
            value = _per_step(t, "stress")
            if min(value) < 0:
                raise t.error("stress", f"mean normal stresses are compressive, >= 0; got {value!r}")
            settings = {"tolerance": t.number("tolerance", 1e-3, positive=True, maximum=0.5),
                        "max_iterations": t.integer("max_iterations", 20),
                        "method": t.string("method", "search", choices=PLATEN_METHODS)}
            if settings["method"] == "constraint" and "contact" not in effects:
                raise t.error("method", "'constraint' makes the displacement an unknown of the contact problem: "
                                        "it needs the 'contact' effect")
            if "area" in t.data:
                settings["area"] = t.number("area", positive=True)
        elif kind in ("traction", "body_force"):
            value = t.vector("value")
        elif kind in STEPPED_LOADS and isinstance(t.data.get("value"), list):
            value = _per_step(t, "value")
        elif kind == "dirichlet":
            value = t.number("value", 0.0)
        else:
            value = t.number("value")
        components = ["x", "y", "z"]
        if kind == "dirichlet":
            components = t.strings("components", components, choices=["x", "y", "z"])
        elif "components" in t.data:
            raise t.error("components", "only dirichlet loads constrain components")
        if kind == "fluid_pressure" and "fluid_pressure" not in effects:
            raise t.error("type", "a fluid_pressure load needs the effect 'fluid_pressure' in [physics] effects")
        loads.append(Load(kind, boundary, value, components, settings))
    if sum(load.type == "platen" for load in loads) > 1:
        raise SceneError(f"{path}: [[loads]]: more than one platen; the solid has one stress-controlled platen")
    if "fluid_pressure" in effects and not any(load.type == "fluid_pressure" for load in loads):
        raise SceneError(f"{path}: [physics] effects: 'fluid_pressure' asks for a [[loads]] entry with "
                         f"type = \"fluid_pressure\" (the pressure and the fracture faces it acts on)")
    if not any(load.type in ("dirichlet", "platen") for load in loads):
        raise SceneError(f"{path}: [[loads]]: no dirichlet load: the rock needs supports against rigid motion")
    return loads


def _per_step(t: Table, key: str) -> list[float]:
    """A non-empty list of finite numbers, one per step (repeats allowed)."""
    value = t.data.get(key)
    if (not isinstance(value, list) or not value
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value)):
        raise t.error(key, f"must be a non-empty list of finite numbers, one per step, got {value!r}")
    return [float(v) for v in value]


def _check_steps(path, loads: list[Load], steps: int, given: bool) -> None:
    """Every per-step load has one value per step ([time] steps, or the longest list)."""
    for i, load in enumerate(loads, start=1):
        if load.per_step and len(load.value) != steps:
            key = "stress" if load.type == "platen" else "value"
            origin = "[time] steps is" if given else "another load has"
            raise SceneError(f"{path}: [loads.{i}] {key}: {len(load.value)} values, one per step, but {origin} "
                             f"{steps} step{'s' * (steps > 1)}")

