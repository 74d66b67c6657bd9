"""Scenes of coupled cases: geometry, materials, loads, effects, solvers, coupling, outputs.

A coupled scene (``cases/NAME/scene.toml`` with a ``[physics]`` table) is
validated as a whole before anything runs; every error names the scene file,
the table and key, and the reason (``<scene.toml>: [loads.3] boundary: ...``).
cases/README.md documents every key. :mod:`coupler.plan` turns a scene into
the participants to start and the fields that cross.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from coupler.errors import SceneError
from coupler.protocol.transport import check_endpoint
from coupler.scene.tables import _REQUIRED, Table, output_directory
from coupler.protocol.expressions import check_expression

#: effects a scene may ask for
EFFECTS = {
    "elasticity": "linear elastic deformation of the rock (solid participant)",
    "dynamics": "inertia: elastodynamics with time steps (paper eq. 13)",
    "fluid_pressure": "a static fluid pressure on fracture faces, applied as a load (no fluid solver)",
    "flow": "fluid flow on a structured grid, coupled to the solid (fluid participant, paper 2.3)",
    "contact": "contact between fracture faces (mortar coupling, paper 2.2)",
}
#: nonsmooth solvers of [contact] solver (nonsmooth.solvers)
CONTACT_SOLVERS = ("active_set", "snes_vi", "multilevel")
#: participant kinds -> the module started as ``python -m MODULE``
SOLID_PARTICIPANTS = {"solid_fenicsx": "solid_fenicsx", "spring_solid": "coupler.standins"}
FLUID_PARTICIPANTS = {"openfoam": "fluid_openfoam", "replay_fluid": "coupler.standins"}
LOAD_TYPES = ("dirichlet", "pressure", "traction", "body_force", "fluid_pressure")
ACCELERATIONS = ("constant", "aitken", "iqn-ils")
#: [coupling] traction: the fluid's pressure only, or its full stress with the viscous part (coupler/viscous.py)
TRACTIONS = ("pressure", "full")
BOX_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
#: conditions of the fluid grid's side faces ([flow] walls, faces); xmin is the inlet, xmax the outlet
FACE_CONDITIONS = ("wall", "slip", "symmetry", "empty")
#: how the openfoam participant turns solid fractions into drag (fluid_openfoam/penalization.py)
PENALIZATIONS = ("wall", "linear", "power")
#: decomposePar methods of a parallel openfoam fluid (fluid_openfoam/parallel.py)
DECOMPOSITIONS = ("simple",)  # scotch: only a dummy library in Debian's OpenFOAM v1912

@dataclass
class SolidGeometry:
    mesh: Path | None  # a mesh file, or None for the box generator
    box: dict | None  # lower, upper, shape, jitter, seed
    boundaries: dict[str, str | int]  # name -> expression on facet midpoints, box face, or file tag


@dataclass
class FluidGeometry:
    origin: list[float]
    spacing: list[float]
    shape: list[int]


@dataclass
class Load:
    type: str
    boundary: str | None
    value: object  # float, [3 floats]
    components: list[str] = field(default_factory=lambda: ["x", "y", "z"])


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
    solvers: dict  # "solid": {...}, "fluid": {...}
    time: dict  # dt, steps
    coupling: dict
    messaging: dict
    output_dir: Path
    output: dict
    check: dict | None = None  # expected displacement: {"x"|"y"|"z": expr, "where": expr, "tolerance": float}
    flow: dict | None = None  # fluid boundary conditions: inlet, outlet, walls, faces ([flow])
    contact: dict | None = None  # [contact]: slave, master, solver, tolerances (effect 'contact')
    resources: dict = field(default_factory=lambda: {"memory_limit": None, "check_memory": True})

    def error(self, table: str, key: str, reason: str) -> SceneError:
        return SceneError(f"{self.path}: [{table}] {key}: {reason}")


TABLES = {
    "case": {"description": "one line on what the case shows"},
    "physics": {"effects": f"list of effects: {', '.join(EFFECTS)}"},
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
                             "((-p I + tau) n with the viscous wall shear)"},
    "messaging": {"mode": "zenoh mode: peer (default) or client", "connect": "zenoh endpoints to connect to",
                  "timeout": "seconds to wait for a participant's answer"},
    "flow": {"inlet_velocity": "fixed inlet velocity [u, v, w] on the grid face xmin [m/s]",
             "inlet_pressure": "fixed inlet pressure on the grid face xmin [Pa]",
             "outlet_pressure": "fixed outlet pressure on the grid face xmax [Pa] (default 0)",
             "walls": f"condition of the other grid faces: one of {', '.join(FACE_CONDITIONS)} (default wall)",
             "faces": "table: face (ymin ... zmax) -> condition ({ pressure = p } for an open face), "
                      "overriding walls"},
    "contact": {"slave": "the boundary carrying the contact pressure (dual basis; the finer or curved side)",
                "master": "the opposite boundary (another body of the same mesh)",
                "solver": f"nonsmooth solver, one of {', '.join(CONTACT_SOLVERS)} (default active_set)",
                "tolerance": "active_set: scaled KKT residual (default 1e-10); snes_vi: relative residual; "
                             "multilevel: step length [m]",
                "max_iterations": "nonsmooth iterations per load step (default 100)",
                "search_distance": "how far along the slave normal the master is looked for [m] (default: "
                                   "half the slave's mean edge); at least the largest gap that may close",
                "max_normal_angle": "largest angle between paired slave and master faces [deg] (default 45)"},
    "resources": {"memory_limit": "memory this run may use [bytes] (default: what the machine has available)",
                  "check_memory": "refuse a scene whose estimated memory exceeds what is available (default "
                                  "true; false runs it anyway)"},
    "output": {"directory": "output directory, relative to the case (default 'results')",
               "every": "write fields every N steps (default 1)"},
    "check": {"x": "expected x displacement (expression in x, y, z)", "y": "expected y displacement",
              "z": "expected z displacement", "where": "expression selecting the vertices compared (default all)",
              "tolerance": "largest relative error accepted"},
}
SOLID_KEYS = {"mesh": "mesh file (any format meshio reads), relative to the case",
              "lower": "box generator: lower corner", "upper": "box generator: upper corner",
              "shape": "box generator: cells per axis", "jitter": "box generator: random vertex shift",
              "seed": "box generator: random seed", "boundaries": "table: name -> boundary"}
FLUID_KEYS = {"origin": "grid origin", "spacing": "grid spacing", "shape": "cells per axis",
              "lower": "grid lower corner (instead of origin/spacing)", "upper": "grid upper corner"}
LOAD_KEYS = {"type": f"one of {', '.join(LOAD_TYPES)}", "boundary": "a named boundary",
             "value": "number (pressure, fixed value) or [x, y, z] (traction, body force)",
             "components": "dirichlet: constrained components, subset of ['x', 'y', 'z']"}
SOLVER_KEYS = {"participant": "which participant runs this part", "ranks": "MPI ranks (default 1)",
               "degree": "polynomial degree (solid: 1 or 2)", "linear_solver": "cg (CG + GAMG) or lu",
               "rtol": "relative tolerance of the linear solver", "stiffness": "spring_solid: spring stiffness",
               "pressure": "replay_fluid: uniform pressure served",
               "feedback": "replay_fluid: pressure drop per unit mean solid velocity [Pa s/m]",
               "unconverged": "replay_fluid: time steps in which it reports an unconverged solve (for tests)",
               "penalization": f"openfoam: solid fractions -> drag, one of {', '.join(PENALIZATIONS)}",
               "penalization_exponent": "openfoam: exponent of penalization 'power'",
               "drag": "openfoam: maximum penalization drag [1/s] (default 1e4 x the fastest cell rate)",
               "decomposition": f"openfoam with ranks > 1: decomposePar method, one of {', '.join(DECOMPOSITIONS)}",
               "max_iterations": "openfoam: simpleFoam iterations per coupling iteration (default 2000); "
                                 "solid_fenicsx: Krylov iterations per solve (default 1000)",
               "tolerance": "openfoam: simpleFoam (PIMPLE with dynamics) residual tolerance (p and U)",
               "substeps": "openfoam with dynamics: pimpleFoam time steps per coupling step (default 1)",
               "outer_correctors": "openfoam with dynamics: PIMPLE outer iterations per time step at most (default 50)",
               "solid_velocity": "openfoam: 'bodies' (each solid body moves rigidly with its wetted layer's mean "
                                 "velocity, default) or 'none' (penalized towards rest)",
               "allow_unconverged": "accept this participant's unconverged inner solves on purpose (e.g. a "
                                    "deliberately capped steady solve; default false: the run stops with "
                                    "status not_converged); summary.json lists what was accepted",
               "keep_case": "openfoam: keep the OpenFOAM case in <output>/logs/fluid_case for inspection "
                            "(default false: a temporary directory, removed when the run ends)"}


def parse(path: Path, case_dir: Path, data: dict, output: str | Path | None = None) -> CoupledScene:
    """Validate the tables of a coupled scene (already read from TOML)."""
    for name in data:
        if name not in TABLES:
            raise SceneError(f"{path}: unknown table [{name}]; known tables: {', '.join(f'[{t}]' for t in TABLES)}")
    case = Table(path, "case", data.get("case", {}), TABLES["case"])
    physics = Table(path, "physics", data["physics"], TABLES["physics"])
    effects = physics.strings("effects", choices=list(EFFECTS))
    if not effects:
        raise physics.error("effects", "must name at least one effect")
    if "elasticity" not in effects:
        raise physics.error("effects", "every coupled scene needs 'elasticity' (the rock); "
                                       f"got {effects!r}")

    geometry = Table(path, "geometry", data.get("geometry", {}), TABLES["geometry"])
    if "solid" not in geometry.data:
        raise geometry.error("solid", "missing (the rock: a mesh file or a box)")
    solid = _solid_geometry(path, case_dir, geometry.data["solid"])
    fluid = None
    if "fluid" in geometry.data:
        fluid = _fluid_geometry(path, geometry.data["fluid"])
    if "flow" in effects and fluid is None:
        raise geometry.error("fluid", "missing: the scene asks for 'flow' but has no fluid domain (a grid)")

    materials = Table(path, "materials", data.get("materials", {}), TABLES["materials"])
    if "solid" not in materials.data:
        raise materials.error("solid", "missing (E, nu, density of the rock)")
    rock = Table(path, "materials.solid", materials.data["solid"],
                 {"E": "Young's modulus [Pa]", "nu": "Poisson ratio", "density": "[kg/m^3]"})
    material = {"E": rock.number("E", positive=True), "nu": rock.number("nu", minimum=-0.99, maximum=0.4999999),
                "density": rock.number("density", default=2600.0, positive=True)}
    water = Table(path, "materials.fluid", materials.data.get("fluid", {}),  # water unless the scene says
                  {"density": "[kg/m^3]", "viscosity": "dynamic viscosity [Pa s]"})
    fluid_material = {"density": water.number("density", default=1000.0, positive=True),
                      "viscosity": water.number("viscosity", default=1e-3, positive=True)}

    loads = _loads(path, data.get("loads", []), solid, effects)

    solvers = Table(path, "solvers", data.get("solvers", {}), TABLES["solvers"])
    solver_cfg = {"solid": _solver(path, "solid", solvers.data.get("solid", {}), SOLID_PARTICIPANTS, "solid_fenicsx")}
    if "flow" in effects:
        solver_cfg["fluid"] = _solver(path, "fluid", solvers.data.get("fluid", {}), FLUID_PARTICIPANTS, "openfoam")

    time = Table(path, "time", data.get("time", {}), TABLES["time"])
    dynamic = "dynamics" in effects or "flow" in effects
    time_cfg = {"dt": time.number("dt", default=_REQUIRED if dynamic else 1.0, positive=True),
                "steps": time.integer("steps", default=_REQUIRED if dynamic else 1)}

    coupling = Table(path, "coupling", data.get("coupling", {}), TABLES["coupling"])
    coupling_cfg = {"acceleration": coupling.string("acceleration", "iqn-ils", ACCELERATIONS),
                    "relaxation": coupling.number("relaxation", 0.5, minimum=1e-6, maximum=1.0),
                    "tolerance": coupling.number("tolerance", 1e-6, positive=True),
                    "max_iterations": coupling.integer("max_iterations", 50),
                    "reuse": coupling.integer("reuse", 8, minimum=0),
                    "columns": coupling.integer("columns", 100),
                    "interface": _interface(coupling),
                    "deformation": coupling.boolean("deformation", True),
                    "traction": coupling.string("traction", "pressure", TRACTIONS)}
    if coupling_cfg["traction"] == "full" and "flow" not in effects:
        raise coupling.error("traction", "'full' (the viscous stress of a flow) needs the effect 'flow'")
    if coupling_cfg["traction"] == "full" and solver_cfg["solid"]["participant"] != "solid_fenicsx":
        raise coupling.error("traction", "'full' needs a solid with a wetted surface (solid_fenicsx), got "
                                         f"{solver_cfg['solid']['participant']!r}")
    if "flow" in effects:
        if coupling_cfg["interface"] is None:
            raise coupling.error("interface", "missing: the solid boundary the fluid pressure acts on")
        names = [coupling_cfg["interface"]] if isinstance(coupling_cfg["interface"], str) else coupling_cfg["interface"]
        for name in names:
            if name not in solid.boundaries:
                raise coupling.error("interface", f"unknown boundary {name!r}; named boundaries: "
                                                  f"{', '.join(solid.boundaries)}")

    flow = _flow(path, data["flow"], fluid, effects) if "flow" in data else None
    if flow is None and "flow" in effects and solver_cfg["fluid"]["participant"] == "openfoam":
        raise SceneError(f"{path}: [flow] inlet_velocity: missing: the openfoam fluid needs a [flow] table with "
                         f"inlet_velocity = [u, v, w] or inlet_pressure = p (Pa)")

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

    check = None
    if "check" in data:
        t = Table(path, "check", data["check"], TABLES["check"])
        check = {c: t.string(c, None) for c in ("x", "y", "z", "where") if c in t.data}
        for key, expression in check.items():
            check_expression(expression, t.where(key))
        if not set(check) & {"x", "y", "z"}:
            raise t.error("z", "give the expected displacement of at least one component (x, y or z)")
        check["tolerance"] = t.number("tolerance", positive=True)

    contact = _contact(path, data.get("contact"), solid, effects, solver_cfg["solid"])

    res = Table(path, "resources", data.get("resources", {}), TABLES["resources"])
    resources = {"memory_limit": res.number("memory_limit", None, positive=True),
                 "check_memory": res.boolean("check_memory", True)}

    out = Table(path, "output", data.get("output", {}), TABLES["output"])
    output_dir = output_directory(case_dir, out, output)
    return CoupledScene(path=path, case_dir=case_dir, description=case.string("description", None) or "",
                        effects=effects, solid=solid, fluid=fluid, material=material,
                        fluid_material=fluid_material, loads=loads, solvers=solver_cfg, time=time_cfg,
                        coupling=coupling_cfg, messaging=messaging_cfg, output_dir=output_dir,
                        output={"every": out.integer("every", 1)}, check=check, flow=flow,
                        contact=contact, resources=resources)


def _contact(path, data, solid: SolidGeometry, effects, solid_solver: dict) -> dict | None:
    """[contact]: the two contact boundaries and the nonsmooth solver (effect 'contact')."""
    if data is None:
        if "contact" in effects:
            raise SceneError(f"{path}: [contact] slave: missing: the effect 'contact' needs a [contact] table "
                             f"with slave and master boundaries")
        return None
    t = Table(path, "contact", data, TABLES["contact"])
    if "contact" not in effects:
        raise t.error("slave", "a [contact] table needs the effect 'contact' in [physics] effects")
    for other in ("flow", "dynamics"):
        if other in effects:
            raise SceneError(f"{path}: [physics] effects: 'contact' with '{other}' is not supported "
                             f"(contact is static: load steps over [time] steps)")
    if solid_solver["participant"] != "solid_fenicsx" or solid_solver["ranks"] != 1 or solid_solver["degree"] != 1:
        raise SceneError(f"{path}: [solvers.solid]: contact needs participant solid_fenicsx, ranks = 1, degree = 1")
    cfg = {"slave": t.string("slave"), "master": t.string("master"),
           "solver": t.string("solver", "active_set", CONTACT_SOLVERS),
           "tolerance": t.number("tolerance", 1e-10, positive=True),
           "max_iterations": t.integer("max_iterations", 100),
           "search_distance": t.number("search_distance", None, positive=True),
           "max_normal_angle": t.number("max_normal_angle", 45.0, positive=True, maximum=90.0)}
    for key in ("slave", "master"):
        if cfg[key] not in solid.boundaries:
            raise t.error(key, f"unknown boundary {cfg[key]!r}; named boundaries: {', '.join(solid.boundaries)}")
    if cfg["slave"] == cfg["master"]:
        raise t.error("master", f"the same boundary as slave ({cfg['slave']!r}): contact is between two bodies")
    return cfg


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
    if mesh is not None:
        if any(k in t.data for k in ("lower", "upper", "shape", "jitter", "seed")):
            raise t.error("mesh", "give either a mesh file or the box keys (lower, upper, shape), not both")
        mesh = t.file("mesh", case_dir)
    else:
        if "lower" not in t.data and "upper" not in t.data:
            raise t.error("mesh", "missing: give a mesh file, or a box with lower, upper and shape")
        lower, upper = t.vector("lower"), t.vector("upper")
        if any(u <= lo for lo, u in zip(lower, upper)):
            raise t.error("upper", f"must exceed lower in every coordinate, got {lower} .. {upper}")
        shape = t.shape("shape")
        box = {"lower": lower, "upper": upper, "shape": shape,
               "jitter": t.number("jitter", 0.0, minimum=0.0, maximum=0.24), "seed": t.integer("seed", 0, minimum=0)}
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
        boundaries[name] = spec
    if box is not None:  # the box's faces first: a named boundary takes its facets from them (a facet has one tag)
        boundaries = {**{face: face for face in BOX_FACES if face not in boundaries}, **boundaries}
    return SolidGeometry(mesh=mesh, box=box, boundaries=boundaries)


def _fluid_geometry(path, data) -> FluidGeometry:
    t = Table(path, "geometry.fluid", data, FLUID_KEYS)
    shape = t.shape("shape")
    if "lower" in t.data or "upper" in t.data:
        lower, upper = t.vector("lower"), t.vector("upper")
        if any(u <= lo for lo, u in zip(lower, upper)):
            raise t.error("upper", f"must exceed lower in every coordinate, got {lower} .. {upper}")
        return FluidGeometry(lower, [(u - lo) / n for lo, u, n in zip(lower, upper, shape)], shape)
    spacing = t.vector("spacing")
    if any(h <= 0 for h in spacing):
        raise t.error("spacing", f"must be positive, got {spacing}")
    return FluidGeometry(t.vector("origin"), spacing, shape)


def _flow(path, data, fluid: FluidGeometry | None, effects) -> dict:
    """The fluid's boundary conditions on the faces of its grid ([flow])."""
    t = Table(path, "flow", data, TABLES["flow"])
    if "flow" not in effects:
        raise SceneError(f"{path}: [flow]: fluid boundary conditions need the effect 'flow' in [physics] effects")
    if ("inlet_velocity" in t.data) == ("inlet_pressure" in t.data):
        raise t.error("inlet_velocity", "give exactly one of inlet_velocity = [u, v, w] (m/s) or "
                                        "inlet_pressure = p (Pa)")
    if "inlet_velocity" in t.data:
        inlet = {"velocity": t.vector("inlet_velocity")}
    else:
        inlet = {"pressure": t.number("inlet_pressure")}
    outlet = {"pressure": t.number("outlet_pressure", 0.0)}
    walls = t.string("walls", "wall", FACE_CONDITIONS)
    faces_data = t.data.get("faces", {})
    if not isinstance(faces_data, dict):
        raise t.error("faces", f"must be a table face -> condition, got {faces_data!r}")
    sides = BOX_FACES[2:]
    faces = {}
    for face, condition in faces_data.items():
        where = f"{path}: [flow.faces] {face}"
        if face in ("xmin", "xmax"):
            raise SceneError(f"{where}: xmin is the inlet and xmax the outlet (inlet_*, outlet_pressure); "
                             f"faces sets {', '.join(sides)}")
        if face not in sides:
            raise SceneError(f"{where}: unknown face; use one of {', '.join(sides)}")
        if isinstance(condition, dict):  # an open face: { pressure = p } (Pa), e.g. where a moving body leaves the grid
            if set(condition) != {"pressure"} or isinstance(condition["pressure"], bool) \
                    or not isinstance(condition["pressure"], (int, float)) or not math.isfinite(condition["pressure"]):
                raise SceneError(f"{where}: a table condition is {{ pressure = p }} (Pa, finite), got {condition!r}")
            faces[face] = {"pressure": float(condition["pressure"])}
            continue
        if condition not in FACE_CONDITIONS:
            raise SceneError(f"{where}: unknown condition {condition!r}; use one of "
                             f"{', '.join(map(repr, FACE_CONDITIONS))} or {{ pressure = p }}")
        faces[face] = condition
    for axis, (lo, hi) in ((1, ("ymin", "ymax")), (2, ("zmin", "zmax"))):
        a, b = faces.get(lo, walls), faces.get(hi, walls)
        if (a == "empty") != (b == "empty"):
            raise t.error("faces", f"'empty' (2D) needs both {lo} and {hi}, got {lo} = {a!r}, {hi} = {b!r}")
        if a == "empty" and fluid is not None and fluid.shape[axis] != 1:
            raise t.error("faces", f"'empty' on {lo} and {hi} needs one cell along {'xyz'[axis]} in "
                                   f"[geometry.fluid] shape, got {fluid.shape[axis]}")
    return {"inlet": inlet, "outlet": outlet, "walls": walls, "faces": faces}


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
        if kind in ("traction", "body_force"):
            value = t.vector("value")
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
        loads.append(Load(kind, boundary, value, components))
    if "fluid_pressure" in effects and not any(load.type == "fluid_pressure" for load in loads):
        raise SceneError(f"{path}: [physics] effects: 'fluid_pressure' asks for a [[loads]] entry with "
                         f"type = \"fluid_pressure\" (the pressure and the fracture faces it acts on)")
    if not any(load.type == "dirichlet" for load in loads):
        raise SceneError(f"{path}: [[loads]]: no dirichlet load: the rock needs supports against rigid motion")
    return loads


def _solver(path, part, data, participants, default) -> dict:
    t = Table(path, f"solvers.{part}", data, SOLVER_KEYS)
    cfg = {"participant": t.string("participant", default, tuple(participants)),
           "ranks": t.integer("ranks", 1), "allow_unconverged": t.boolean("allow_unconverged", False)}
    cfg["module"] = participants[cfg["participant"]]
    if part == "solid":
        cfg["degree"] = t.integer("degree", 1)
        if cfg["degree"] > 2:
            raise t.error("degree", f"must be 1 or 2, got {cfg['degree']}")
        cfg["linear_solver"] = t.string("linear_solver", "cg", ("cg", "lu"))
        cfg["rtol"] = t.number("rtol", 1e-10, positive=True)
        cfg["max_iterations"] = t.integer("max_iterations", 1000)
        if cfg["participant"] == "spring_solid":
            cfg["stiffness"] = t.number("stiffness", positive=True)
    if part == "fluid" and cfg["participant"] == "replay_fluid":
        cfg["pressure"] = t.number("pressure", 0.0)
        cfg["feedback"] = t.number("feedback", 0.0)
        cfg["unconverged"] = t.numbers("unconverged", [], integer=True, minimum=0, within=None) \
            if "unconverged" in t.data else []
    if part == "fluid" and cfg["participant"] == "openfoam":
        # one participant process; the solver runs decomposed on `ranks` MPI ranks (fluid_openfoam/parallel.py)
        cfg["solver_ranks"], cfg["ranks"] = cfg["ranks"], 1
        cfg["decomposition"] = t.string("decomposition", "simple", DECOMPOSITIONS)
        if "decomposition" in t.data and cfg["solver_ranks"] == 1:
            raise t.error("decomposition", "applies to a parallel fluid (ranks > 1) only")
        cfg["penalization"] = t.string("penalization", "wall", PENALIZATIONS)
        cfg["penalization_exponent"] = t.number("penalization_exponent", 2.0, positive=True)
        if "penalization_exponent" in t.data and cfg["penalization"] != "power":
            raise t.error("penalization_exponent", "applies to penalization = \"power\" only")
        cfg["drag"] = t.number("drag", None, positive=True)
        cfg["max_iterations"] = t.integer("max_iterations", 2000)
        cfg["tolerance"] = t.number("tolerance", 1e-7, positive=True)
        cfg["substeps"] = t.integer("substeps", 1)
        cfg["outer_correctors"] = t.integer("outer_correctors", 50)
        cfg["solid_velocity"] = t.string("solid_velocity", "bodies", ("bodies", "none"))
        cfg["keep_case"] = t.boolean("keep_case", False)
    return cfg
