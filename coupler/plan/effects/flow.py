"""Effect ``flow``: fluid flow on a structured grid around the rock, coupled to it by the
immersed-boundary scheme of paper 2.3 (Steps 1-6): a fluid participant on the grid and the
exchanges between it and the solid.

With ``elasticity``, per coupling iteration, in the order the participants advance: the solid
advances under the fluid's load on its wetted boundary (``[coupling] interface``: the
pressure, or with ``traction = "full"`` the traction (-p I + tau) n; Steps 2-4), which is the
accelerated interface quantity; the fluid advances in the grid cells the deformed solid fills
(the solid fraction, before Step 1) and, when the solid moves in time (``dynamics``), with the
solid's velocity on the grid (Step 6). A quasi-static scene sends no velocity: the solid is at
rest in each step.

Without ``elasticity`` the solid is fixed: a stand-in served by the coupler (``rigid_solid``:
its mesh and zero displacement) and a one-way plan, the solid fraction only (Step 1 with a
solid that the fluid does not load): one fluid solve per step, no fixed point.

``[flow] solid_fraction`` says how the fraction is sampled: ``exact`` intersection volumes
(default) or ``cell_centre`` (1 where the cell's centre is in the solid, 0 elsewhere: the
binary mask the exact fractions replace).
"""

import math

from coupler.errors import SceneError
from coupler.protocol.roles import (DISPLACEMENT, IN_CONTACT, INLET_PRESSURE, PRESSURE, SOLID_FRACTION, SOLID_VELOCITY,
                                     TRACTION, VELOCITY)
from coupler.protocol.slabs import check_whole, slab_bounds
from coupler.scene.participants import for_role
from coupler.scene.tables import Table
from transfer.grid import BOX_FACES, across_axis
from transfer.penalization import LINES

NAME = "flow"
DESCRIPTION = "fluid flow on a structured grid, coupled to the solid (fluid participant, paper 2.3)"
ORDER = 3
TIME_STEPS = True  # [time] dt and steps are required
ROLES = ("fluid",)  # the [solvers.X] tables it needs
DOMAINS = ("solid", "fluid")  # the [geometry.X] tables it needs: the solid, elastic or fixed, and the grid
#: conditions of the fluid grid's side faces ([flow] walls, faces); xmin is the inlet, xmax the outlet
FACE_CONDITIONS = ("wall", "slip", "symmetry", "empty")
#: how the solid fraction of a grid cell is sampled ([flow] solid_fraction; coupler/fsi/operators.py)
FRACTIONS = ("exact", "cell_centre")
#: what drives the flow at the inlet xmin ([flow]: exactly one)
INLETS = ("inlet_velocity", "inlet_pressure", "flow_rate")
TABLES = {"flow": {
    "inlet_velocity": "fixed inlet velocity [u, v, w] on the grid face xmin [m/s]",
    "inlet_pressure": "fixed inlet pressure on the grid face xmin [Pa]",
    "flow_rate": "the volume flow rate Q from xmin to xmax instead of a fixed inlet [m^3/s]: the inlet pressure is "
                 "an unknown of the coupling, adjusted each iteration until Q is reached (a fluid that accepts "
                 "'inlet_pressure')",
    "outlet_pressure": "fixed outlet pressure on the grid face xmax [Pa] (default 0)",
    "walls": f"condition of the other grid faces: one of {', '.join(FACE_CONDITIONS)} (default wall)",
    "faces": "table: face (ymin ... zmax) -> condition ({ pressure = p } for an open face), overriding walls",
    "solid_fraction": "how a grid cell's solid fraction is sampled: 'exact' (intersection volumes, default) or "
                      "'cell_centre' (1 where the cell centre is in the solid)"}}


def parse(scene, data: dict) -> None:
    """The fluid domain, the wetted interface and the fluid's boundary conditions ([flow])."""
    path = scene.path
    if scene.fluid is None:
        raise SceneError(f"{path}: [geometry] fluid: missing: the scene asks for 'flow' but has no fluid domain "
                         f"(a grid)")
    interface = scene.coupling["interface"]
    if "elasticity" not in scene.effects:  # a fixed solid: the fluid does not load it
        if interface is not None:
            raise SceneError(f"{path}: [coupling] interface: a fixed solid (no 'elasticity') is not loaded by the "
                             f"fluid: the plan is one-way, the solid fraction only")
        interface = []
    elif interface is None:
        raise SceneError(f"{path}: [coupling] interface: missing: the solid boundary the fluid pressure acts on")
    for name in [interface] if isinstance(interface, str) else interface:
        if name not in scene.solid.boundaries:
            raise SceneError(f"{path}: [coupling] interface: unknown boundary {name!r}; named boundaries: "
                             f"{', '.join(scene.solid.boundaries)}")
    _check_slabs(scene)
    if "flow" in data:
        scene.effect_settings[NAME] = _boundary_conditions(path, data["flow"], scene.fluid)
        _check_rate_control(scene)
    elif NAME in scene.solvers["fluid"].spec.needs:
        raise SceneError(f"{path}: [flow] inlet_velocity: missing: the {scene.solvers['fluid'].kind} fluid needs a "
                         f"[flow] table with "
                         f"inlet_velocity = [u, v, w] or inlet_pressure = p (Pa)")


def _check_slabs(scene) -> None:
    """A fluid cut into slabs over its ranks (``slab_axis``) has enough cells for each, and its
    slabs do not cut the lines across the gap a penalization of :data:`LINES` reads."""
    solver = scene.solvers["fluid"]
    if "slab_axis" in solver.settings and solver.ranks > 1:
        try:
            d, _ = slab_bounds(scene.fluid.shape, solver.ranks, solver.settings["slab_axis"])
        except ValueError as exc:
            raise SceneError(f"{scene.path}: [solvers.fluid] ranks: {exc} ([geometry.fluid] shape)") from None
        mode = solver.settings.get("penalization")
        try:
            check_whole(d, solver.ranks, across_axis(scene.fluid.shape, scene.fluid.spacing) if mode in LINES else None)
        except ValueError as exc:
            raise SceneError(f"{scene.path}: [solvers.fluid] slab_axis: penalization {mode!r}: {exc}") from None


def _check_rate_control(scene) -> None:
    """A flow rate needs a fluid whose inlet pressure the coupler may set in every iteration."""
    solver = scene.solvers["fluid"]
    if "flow_rate" in scene.effect_settings[NAME]["inlet"] and INLET_PRESSURE not in solver.spec.accepts:
        raise SceneError(f"{scene.path}: [flow] flow_rate: the {solver.kind} fluid does not take a new inlet pressure "
                         f"in every coupling iteration (a participant that accepts 'inlet_pressure': "
                         f"{', '.join(k for k, p in for_role('fluid').items() if 'inlet_pressure' in p.accepts)}); give "
                         f"inlet_pressure instead")


def _boundary_conditions(path, data, fluid) -> dict:
    """The fluid's boundary conditions on the faces of its grid ([flow])."""
    t = Table(path, "flow", data, TABLES["flow"])
    if sum(key in t.data for key in INLETS) != 1:
        raise t.error("inlet_velocity", "give exactly one of inlet_velocity = [u, v, w] (m/s), inlet_pressure = p "
                                        "(Pa) or flow_rate = Q (m^3/s)")
    if "inlet_velocity" in t.data:
        inlet = {"velocity": t.vector("inlet_velocity")}
    elif "inlet_pressure" in t.data:
        inlet = {"pressure": t.number("inlet_pressure")}
    else:
        inlet = {"flow_rate": t.number("flow_rate", positive=True)}
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
    return {"inlet": inlet, "outlet": outlet, "walls": walls, "faces": faces,
            "solid_fraction": t.string("solid_fraction", "exact", FRACTIONS)}


def fluid_config(scene) -> dict:
    """What the fluid participant is configured with: its grid, the fluid, the time step, the
    boundary conditions ([flow]) and its validated ``[solvers.fluid]`` settings (with
    ``keep_case``, the case directory in the output's logs)."""
    from pathlib import Path

    settings = scene.solvers["fluid"].settings
    g = scene.fluid
    config = {"grid": {"origin": g.origin, "spacing": g.spacing, "shape": g.shape}, "location": "cells",
              "rho": scene.fluid_material["density"], "mu": scene.fluid_material["viscosity"],
              "transient": "dynamics" in scene.effects, "dt": scene.time["dt"], **settings}
    if settings.get("keep_case"):
        config["case_dir"] = str((Path(scene.output_dir) / "logs" / "fluid_case").resolve())
    f = scene.effect_settings.get(NAME)
    if f:
        # a flow rate: a fixed-pressure inlet whose value the coupler sends with every advance
        inlet = {"pressure": f["outlet"]["pressure"]} if "flow_rate" in f["inlet"] else f["inlet"]
        config.update(inlet=inlet, outlet=f["outlet"], walls=f["walls"], boundaries=dict(f["faces"]))
    return config


def plan(scene, plan) -> None:
    from coupler.plan.plan import Exchange, PlannedParticipant

    from .elasticity import geometry_config

    solver = scene.solvers["fluid"]
    c = scene.coupling
    elastic = "elasticity" in scene.effects
    if elastic:
        plan.participant("solid").config.update(wetted=c["interface"], traction=c["traction"])
    else:
        plan.participants.append(PlannedParticipant("solid", "rigid_solid", "coupler.standins", 1,
                                                    geometry_config(scene.solid), in_process=True))
    plan.participants.append(PlannedParticipant.of(solver, fluid_config(scene)))
    dynamic = "dynamics" in scene.effects
    if elastic:
        _loading(scene, plan)
    rate = (scene.effect_settings.get(NAME) or {}).get("inlet", {}).get("flow_rate")
    if rate is not None:
        plan.exchanges.append(Exchange(
            [f"fluid.{VELOCITY}", f"solid.{DISPLACEMENT}"], f"fluid.{INLET_PRESSURE}", "flow_rate_control", "before 1",
            accelerated=True, description=f"the pressure difference dp that passes [flow] flow_rate = {rate:g} m^3/s: "
                                          f"an unknown of the fixed point, H(dp) = dp Q_target / Q (Stokes: Q linear "
                                          f"in dp); converged when also |Q / Q_target - 1| <= tolerance "
                                          f"(coupler/fsi/rate_control.py)"))
    fraction = (scene.effect_settings.get(NAME) or {}).get("solid_fraction", "exact")
    deformed = ("the fixed solid" if not elastic else "the deformed solid" if c["deformation"] else
                "the undeformed solid ([coupling] deformation = false)")
    sampled = "exact volume fractions" if fraction == "exact" else "1 where the cell centre is in the solid"
    plan.exchanges.append(Exchange([f"solid.{DISPLACEMENT}"], f"fluid.{SOLID_FRACTION}", SOLID_FRACTION, "before 1",
                                   description=f"P0 indicator of {deformed} -> Q0, {sampled}",
                                   options={"fraction": fraction}))
    if dynamic:
        plan.exchanges.append(Exchange([f"solid.{DISPLACEMENT}", f"solid.{VELOCITY}"], f"fluid.{SOLID_VELOCITY}",
                                       SOLID_VELOCITY, "6",
                                       description=f"P1 (solid mesh) -> Q0 (fluid cells) of {deformed}, pseudo_l2"))
    quasi = ""
    s = solver.settings
    if solver.kind == "openfoam":
        quasi = (f", transient: pimpleFoam over each step ({s['substeps']} time step"
                 f"{'s' * (s['substeps'] > 1)}) and an elastodynamic solid" if dynamic
                 else ", quasi-static: steady simpleFoam and a static solid per step" if elastic
                 else ", steady simpleFoam")
        if dynamic:
            plan.notes.append("openfoam: the solid velocity is applied per solid body (a rigid translation with the "
                              "mean velocity of its wetted cells; rotation and deformation within a body are not)"
                              if s["solid_velocity"] == "bodies" else
                              "openfoam: the solid velocity is not applied (penalization towards rest)")
        if solver.ranks > 1:
            plan.tasks.append(f"fluid: openfoam on {solver.ranks} MPI ranks ({s['decomposition']} "
                              f"decomposition by decomposePar once; one participant process per processor, each "
                              f"writing and reading its own processor's fields, no reconstructPar)")
    if solver.kind == "chorin":
        how = ("Newton on the steady equations of the grid" if s.get("steady") == "newton"
               else "Chorin projection in pseudo-time to steady state")
        quasi = (", transient: Chorin projection time steps over each step (implicit Euler) and an elastodynamic "
                 "solid" if dynamic else f", quasi-static: {how} and a static solid per step" if elastic
                 else f", {how}")
        if solver.ranks > 1:
            along = "the longest direction" if s["slab_axis"] == "longest" else s["slab_axis"]
            plan.tasks.append(f"fluid: chorin on {solver.ranks} MPI ranks, the grid in slabs along {along} (one per "
                              f"rank, ghost layers exchanged each step, the pressure Poisson solve distributed)")
        if dynamic:
            plan.notes.append({"cells": "chorin: the solid velocity is applied per cell (the fluid follows rotating "
                                        "and deforming solids)",
                               "bodies": "chorin: the solid velocity is applied per solid body (a rigid translation "
                                         "with the mean velocity of its wetted cells, as the openfoam fluid)",
                               "none": "chorin: the solid velocity is not applied (penalization towards rest)"}
                              [s["solid_velocity"]])
    n = scene.time["steps"]
    if elastic or rate is not None:
        plan.iteration = (f"{n} time steps of {scene.time['dt']:g} s{quasi}; implicit fixed point per step "
                          f"({c['acceleration']}, tolerance {c['tolerance']:g}, at most {c['max_iterations']} "
                          f"iterations)")
    else:
        plan.iteration = (f"{n} time step{'s' * (n > 1)} of {scene.time['dt']:g} s{quasi}; one-way (a fixed "
                          f"solid): one fluid solve per step, no fixed point")
    if "contact" in scene.effects:  # the hydro-mechanical fracture
        from . import contact

        contact.check_fluid_below_confinement(scene)
        contact.plan_with_flow(scene, plan)


def _loading(scene, plan) -> None:
    """Steps 2-3: the fluid's load on the elastic solid's wetted boundary, the accelerated exchange."""
    from coupler.plan.plan import Exchange

    c = scene.coupling
    interface = c["interface"] if isinstance(c["interface"], str) else ", ".join(c["interface"])
    if c["traction"] == "full":
        plan.exchanges.append(Exchange(
            [f"fluid.{PRESSURE}", f"fluid.{VELOCITY}", f"solid.{VELOCITY}"], f"solid.{TRACTION}", "viscous_traction", "2-3",
            accelerated=True, description=f"(-p I + tau) n on the wetted boundary '{interface}': the Q0 pressure "
                                          f"traced half a cell into the fluid, the wall shear from three velocity "
                                          f"samples (coupler/fsi/viscous.py)"))
    elif "contact" in scene.effects:
        plan.exchanges.append(Exchange(
            [f"fluid.{PRESSURE}", f"solid.{IN_CONTACT}"], f"solid.{PRESSURE}", "open_pressure_trace", "2-3", accelerated=True,
            description=f"Q0 (grid) -> P1 on the contact faces '{interface}' moved half a fluid cell into the gap, "
                        f"pseudo_l2 trace, times the open share of each vertex: zero at slave nodes in contact, "
                        f"on the master face one minus the L2 projection of the slave's contact indicator"))
    else:
        plan.exchanges.append(Exchange(
            [f"fluid.{PRESSURE}"], f"solid.{PRESSURE}", "pressure_trace", "2-3", accelerated=True,
            description=f"Q0 (grid) -> P1 on the wetted boundary '{interface}' moved half a fluid cell into the "
                        f"fluid, pseudo_l2 trace (solids without boundary triangles: onto all solid vertices)"))
