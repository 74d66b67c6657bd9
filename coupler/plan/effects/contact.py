"""Effect ``contact``: frictionless contact of the face ``[contact] slave`` with another body's
face ``master`` by mortar coupling (paper 2.2, eq. 9-11), or with a rigid plane
``obstacle`` (eq. 11 with T = 0: the bound is the distance to the plane along its normal;
paper 4.3), solved by the solid participant on the transformed system of eq. 10 in load
steps.

With ``flow`` (the hydro-mechanical fracture): one implicit coupling per load step. The
fluid sees the deformed, contact-closed blocks; its pressure, sampled in the open gap, acts
on both contact faces, and where they touch it is masked: the contact pressure carries the
load there (operator ``open_pressure_trace``). The solid solves the contact problem under
that pressure and its other loads (a platen's stress of the step) in every coupling
iteration. Per step the coupler records the fracture's figures (:mod:`coupler.fsi.fracture`).
"""

import math

from coupler.errors import SceneError
from coupler.scene.tables import Table

NAME = "contact"
DESCRIPTION = "frictionless contact between two faces (mortar coupling, paper 2.2) or with a rigid plane"
ORDER = 2
NEEDS = ("elasticity",)  # the bodies in contact deform
#: nonsmooth solvers of [contact] solver (nonsmooth.solvers)
CONTACT_SOLVERS = ("active_set", "snes_vi", "multilevel")
#: keys of the multilevel solver's hierarchy and smoother (paper 2.4)
MULTILEVEL_KEYS = ("levels", "coarse_shape", "margin", "threads", "smoothing")
TABLES = {"contact": {
    "slave": "the boundary carrying the contact pressure (dual basis; the finer or curved side)",
    "master": "the opposite boundary (another body of the same mesh); or give obstacle",
    "obstacle": "a rigid plane instead of a master: { plane = [a, b, c, d] } (a x + b y + c z + d = 0, the body "
                "where it is >= 0) or { normal = [a, b, c], gap = g } (g beyond the slave's nearest point)",
    "solver": f"nonsmooth solver, one of {', '.join(CONTACT_SOLVERS)} (default active_set)",
    "tolerance": "active_set: scaled KKT residual (default 1e-10); snes_vi: relative residual; multilevel: step "
                 "length [m] (default 1e-12)",
    "max_iterations": "nonsmooth iterations per load step (default 100)",
    "search_distance": "how far along the slave normal the master is looked for [m] (default: half the slave's "
                       "mean edge); at least the largest gap that may close",
    "max_normal_angle": "largest angle between paired slave and master faces [deg] (default 45)",
    "levels": "multilevel: levels of the semi-geometric hierarchy, the fine mesh included (default 3)",
    "coarse_shape": "multilevel: cells per axis of the coarsest grid (default [2, 2, 2])",
    "margin": "multilevel: enlargement of the grids' box per side, a fraction of the body's size (default 0)",
    "threads": "multilevel: threads of the projection assembly (default 1)",
    "smoothing": "multilevel: Gauss-Seidel sweeps before and after each coarse correction (default 3)"}}


def parse(scene, data: dict) -> None:
    """[contact]: the contact faces (or the obstacle) and the nonsmooth solver."""
    path, effects, solid = scene.path, scene.effects, scene.solid
    if "contact" not in data:
        raise SceneError(f"{path}: [contact] slave: missing: the effect 'contact' needs a [contact] table "
                         f"with slave and master boundaries (or slave and obstacle)")
    t = Table(path, "contact", data["contact"], TABLES["contact"])
    if "dynamics" in effects:
        raise SceneError(f"{path}: [physics] effects: 'contact' with 'dynamics' is not supported "
                         f"(contact is static: load steps over [time] steps)")
    s = scene.solvers["solid"]
    if s.kind != "solid_fenicsx" or s.settings["degree"] != 1:
        raise SceneError(f"{path}: [solvers.solid]: contact needs participant solid_fenicsx, degree = 1")
    solver = t.string("solver", "active_set", CONTACT_SOLVERS)
    if s.ranks > 1 and solver != "active_set":
        raise SceneError(f"{path}: [solvers.solid] ranks: {s.ranks} ranks need [contact] solver = 'active_set' "
                         f"(the only one on distributed matrices; {solver!r} runs on one rank)")
    cfg = {"slave": t.string("slave"), "solver": solver,
           "tolerance": t.number("tolerance", 1e-12 if solver == "multilevel" else 1e-10, positive=True),
           "max_iterations": t.integer("max_iterations", 100)}
    if ("master" in t.data) == ("obstacle" in t.data):
        raise t.error("master", "give either master (the other body's face) or obstacle (a rigid plane)")
    if "obstacle" in t.data:
        for key in ("search_distance", "max_normal_angle"):
            if key in t.data:
                raise t.error(key, "a rigid obstacle needs no search: its gap is the distance to the plane")
        cfg["obstacle"] = _obstacle(t)
    else:
        cfg.update(master=t.string("master"), search_distance=t.number("search_distance", None, positive=True),
                   max_normal_angle=t.number("max_normal_angle", 45.0, positive=True, maximum=90.0))
        if cfg["slave"] == cfg["master"]:
            raise t.error("master", f"the same boundary as slave ({cfg['slave']!r}): contact is between two bodies")
    if "flow" in effects:
        _check_with_flow(scene, cfg)
    for key in ("slave", "master"):
        if key in cfg and cfg[key] not in solid.boundaries:
            raise t.error(key, f"unknown boundary {cfg[key]!r}; named boundaries: {', '.join(solid.boundaries)}")
    if solver == "multilevel":
        cfg.update(levels=t.integer("levels", 3, minimum=2), coarse_shape=t.shape("coarse_shape", [2, 2, 2]),
                   margin=t.number("margin", 0.0, minimum=0.0), threads=t.integer("threads", 1),
                   smoothing=t.integer("smoothing", 3))
    else:
        for key in MULTILEVEL_KEYS:
            if key in t.data:
                raise t.error(key, f"only the multilevel solver has it (solver is {solver!r})")
    scene.effect_settings[NAME] = cfg


def _check_with_flow(scene, cfg: dict) -> None:
    """Contact with flow: the fluid fills the gap between the two contact faces, which are the
    wetted interface; it loads them by its pressure only, with no static fluid besides."""
    path = scene.path
    if "obstacle" in cfg:
        raise SceneError(f"{path}: [contact] obstacle: contact with 'flow' is the fluid in a fracture between two "
                         f"bodies: give master (the other face) instead")
    if "fluid_pressure" in scene.effects:
        raise SceneError(f"{path}: [physics] effects: 'fluid_pressure' (a fluid at rest, no fluid solver) and 'flow' "
                         f"both load the fracture faces: keep one")
    interface = scene.coupling["interface"]
    names = {interface} if isinstance(interface, str) else set(interface or ())
    if names != {cfg["slave"], cfg["master"]}:
        raise SceneError(f"{path}: [coupling] interface: with contact the fluid wets the two contact faces: give "
                         f"[{cfg['slave']!r}, {cfg['master']!r}], got {interface!r}")
    if scene.coupling["traction"] != "pressure":
        raise SceneError(f"{path}: [coupling] traction: contact with 'flow' takes the fluid's pressure on the faces "
                         f"(traction = \"pressure\"), got {scene.coupling['traction']!r}")


def check_fluid_below_confinement(scene) -> None:
    """Contact with flow (after [flow] is read): the flow is driven by a pressure difference
    (or a flow rate, the inlet pressure then found in the run and stopped there at the
    confining stress: coupler/fsi/rate_control.py), and no boundary pressure of the fluid
    (inlet, outlet, open faces) reaches a platen's confining stress, where the faces would
    separate and the platen could no longer reach its stress."""
    path, flow = scene.path, scene.effect_settings.get("flow") or {}
    inlet = flow.get("inlet", {})
    if "pressure" not in inlet and "flow_rate" not in inlet:
        raise SceneError(f"{path}: [flow] inlet_pressure: missing: contact with 'flow' drives the flow by a pressure "
                         f"difference (inlet_pressure on xmin, outlet_pressure on xmax) or a flow rate (flow_rate); "
                         f"the fracture's hydraulic aperture needs it")
    given = {"inlet_pressure": inlet.get("pressure"), "outlet_pressure": flow["outlet"]["pressure"],
             **{f"faces.{face}": c["pressure"] for face, c in flow["faces"].items() if isinstance(c, dict)}}
    key, fluid = max(((k, p) for k, p in given.items() if p is not None), key=lambda kp: kp[1])
    for i, load in enumerate(scene.loads, start=1):
        if load.type == "platen" and fluid >= min(load.value):
            raise SceneError(f"{path}: [flow] {key}: the fluid's pressure {fluid:g} Pa reaches the smallest "
                             f"confining stress {min(load.value):g} Pa of [loads.{i}] stress: the faces would "
                             f"separate; keep the fluid's pressure below the confining stress")


def _obstacle(t: Table) -> dict:
    """[contact] obstacle: { plane = [a, b, c, d] } or { normal = [a, b, c], gap = g }."""
    spec = t.data["obstacle"]
    where = f"{t.path}: [contact] obstacle"

    def numbers(key, count):
        value = spec.get(key)
        if (not isinstance(value, list) or len(value) != count or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value)):
            raise SceneError(f"{where}: {key} must be a list of {count} finite numbers, got {value!r}")
        if not any(value[:3]):
            raise SceneError(f"{where}: {key}: the plane's normal (a, b, c) is zero")
        return [float(v) for v in value]

    if not isinstance(spec, dict) or set(spec) not in ({"plane"}, {"normal"}, {"normal", "gap"}):
        raise SceneError(f"{where}: give {{ plane = [a, b, c, d] }} or {{ normal = [a, b, c], gap = g }}, "
                         f"got {spec!r}")
    if "plane" in spec:
        return {"plane": numbers("plane", 4)}
    gap = spec.get("gap", 0.0)
    if isinstance(gap, bool) or not isinstance(gap, (int, float)) or not gap >= 0:
        raise SceneError(f"{where}: gap must be a number >= 0 (the plane's distance beyond the slave), got {gap!r}")
    return {"normal": numbers("normal", 3), "gap": float(gap)}


def plan(scene, plan) -> None:
    c = scene.effect_settings[NAME]
    solid = plan.participant("solid")
    solid.config.update(contact=c, steps=scene.time["steps"])  # loads ramped over the steps
    solver = c["solver"]
    if c["solver"] == "multilevel":
        solver += (f" on {c['levels']} levels (coarsest grid {c['coarse_shape']} cells, margin {c['margin']:g}, "
                   f"{c['smoothing']} Gauss-Seidel sweeps)")
    if "obstacle" in c:
        o = c["obstacle"]
        plane = (f"the plane {o['plane']} (a x + b y + c z + d = 0)" if "plane" in o else
                 f"the plane of normal {o['normal']} {o['gap']:g} m beyond it")
        plan.tasks.append(f"solid: contact of '{c['slave']}' with the rigid obstacle {plane}, eq. 11 with T = 0: the "
                          f"bound is the distance to the plane along its normal; {solver}")
    else:
        plan.tasks.append(f"solid: contact of '{c['slave']}' (slave) on '{c['master']}' (master), eq. 9-11: mortar "
                          f"projection T = D^-1 B with the dual basis on the slave, {solver} on the transformed "
                          f"system of eq. 10")
    steps = scene.time["steps"]
    plan.iteration = (f"contact: {steps} load step{'s' * (steps > 1)} (constant loads ramped linearly, those given "
                      f"per step as given; each step starts from the last), {c['solver']} per step")


def plan_with_flow(scene, plan) -> None:
    """Contact with flow, after the flow rule planned the fluid and its exchanges: the
    hydro-mechanical fracture's iteration and per-step figures."""
    c, coupling = scene.effect_settings[NAME], scene.coupling
    steps, flow = scene.time["steps"], scene.effect_settings["flow"]
    platen = [load for load in scene.loads if load.type == "platen"]
    loading = (f"the platen's stress of the step ({', '.join(f'{v:g}' for v in platen[0].value)} Pa)" if platen
               else "the step's loads")
    plan.tasks.append(f"solid: in every coupling iteration the contact of '{c['slave']}' and '{c['master']}' under "
                      f"{loading} and the fluid's pressure on the open parts of both faces (where they touch, the "
                      f"contact pressure carries the load and no fluid acts)")
    plan.tasks.append("coupler: per step the fracture's mechanical aperture (contacts as zero), contact area "
                      "fraction, flow rate Q through the sections x = const, hydraulic aperture "
                      "(12 mu Q L / (W dp))^(1/3) and mean fluid pressure on the open faces "
                      "(coupler/fsi/fracture.py)")
    plan.monitors.append("fracture")
    inlet = flow["inlet"]
    drive = (f"pressure difference {inlet['pressure'] - flow['outlet']['pressure']:g} Pa" if "pressure" in inlet else
             f"flow rate {inlet['flow_rate']:g} m^3/s, the pressure difference an unknown of the fixed point,")
    plan.iteration = (f"hydro-mechanical fracture (flow solver {scene.solvers['fluid'].kind}, not the "
                      f"fluid at rest of 'fluid_pressure'): {steps} load step{'s' * (steps > 1)}, each one implicit "
                      f"coupling ({coupling['acceleration']} on the fluid pressure at the faces, tolerance "
                      f"{coupling['tolerance']:g}, at most {coupling['max_iterations']} iterations): the fluid "
                      f"({drive} from xmin to xmax) in the deformed, contact-closed blocks, "
                      f"the solid's contact ({c['solver']}) from the step's start under {loading} and the fluid's "
                      f"pressure")
