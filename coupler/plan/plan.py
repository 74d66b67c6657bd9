"""The plan of a coupled scene: which participants to start and which fields cross.

Only the effects a scene asks for are simulated: elasticity alone starts the
solid alone; a static fluid pressure in a fracture is a load on the solid (no
fluid solver); flow with deformation starts both and couples them by the
transfers of paper 2.3 (Steps 2 and 6).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from coupler.scene.coupled import EFFECTS, CoupledScene
from coupler.errors import SceneError


@dataclass
class PlannedParticipant:
    name: str  # "solid", "fluid"
    kind: str  # "solid_fenicsx", "spring_solid", ...
    module: str  # started as python -m MODULE
    ranks: int


@dataclass
class PlannedCoupling:
    source: str  # "participant.field"
    target: str
    operator: str  # e.g. "P1 (solid mesh) -> Q1 (fluid grid), pseudo_l2"
    step: str  # the step of paper 2.3 it belongs to


@dataclass
class Plan:
    effects: list[str]
    participants: list[PlannedParticipant]
    couplings: list[PlannedCoupling]
    loads: list[str]
    iteration: str  # "one solve per step" or "implicit fixed point (...)"
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict:
        """The plan for summary.json."""
        return {"effects": self.effects,
                "participants": [asdict(p) for p in self.participants],
                "couplings": [asdict(c) for c in self.couplings],
                "loads": self.loads, "iteration": self.iteration, "notes": self.notes}

    def lines(self) -> list[str]:
        """The plan as text, for ``varcouple check``."""
        out = [f"effects       {', '.join(self.effects)}"]
        for p in self.participants:
            out.append(f"participant   {p.name}: {p.kind} (python -m {p.module}, {p.ranks} rank"
                       f"{'s' * (p.ranks > 1)})")
        if not self.couplings:
            out.append("couplings     none (no field crosses between participants)")
        for c in self.couplings:
            out.append(f"coupling      {c.source} -> {c.target}: {c.operator} [{c.step}]")
        out += [f"load          {load}" for load in self.loads]
        out.append(f"iteration     {self.iteration}")
        out += [f"note          {n}" for n in self.notes]
        return out


def _describe_load(load) -> str:
    where = f" on '{load.boundary}'" if load.boundary else ""
    if load.type == "dirichlet":
        return f"dirichlet{where}: u_{''.join(load.components)} = {load.value:g}"
    if load.type in ("pressure", "fluid_pressure"):
        source = " (static fluid pressure, no fluid solver)" if load.type == "fluid_pressure" else ""
        return f"pressure{where}: {load.value:g} Pa{source}"
    return f"{load.type}{where}: {load.value}"


def make_plan(scene: CoupledScene) -> Plan:
    """The minimal plan for the effects of `scene`."""
    unknown = [e for e in scene.effects if e not in EFFECTS]
    if unknown:
        raise SceneError(f"{scene.path}: [physics] effects: unknown {unknown}")
    solid_cfg = scene.solvers["solid"]
    participants = [PlannedParticipant("solid", solid_cfg["participant"], solid_cfg["module"], solid_cfg["ranks"])]
    couplings = []
    iteration = "static: one solve" if scene.time["steps"] == 1 and "dynamics" not in scene.effects \
        else f"{scene.time['steps']} time steps of {scene.time['dt']:g} s, one solve per step"
    if "flow" in scene.effects:
        fluid_cfg = scene.solvers["fluid"]
        participants.append(PlannedParticipant("fluid", fluid_cfg["participant"], fluid_cfg["module"],
                                               fluid_cfg["ranks"]))
        couplings = [
            PlannedCoupling("solid.indicator", "fluid.solid_fraction",
                            "P0 (solid mesh) -> Q0 (fluid grid), exact volume fractions", "before step 1"),
            PlannedCoupling("fluid.pressure", "solid.traction",
                            f"Q0 (fluid grid) -> P1 on the wetted boundary '{scene.coupling['interface']}' moved "
                            f"half a fluid cell into the fluid, pseudo_l2 trace (solids without boundary "
                            f"triangles: Q0 -> P1 on all solid vertices)", "steps 2-3"),
            *([PlannedCoupling("fluid.velocity", "solid.traction",
                               "viscous wall shear mu du_t/dn: Q0 velocity traced on the pressure's surface and "
                               "two deeper ones, quadratic through the three samples (coupler/viscous.py)",
                               "steps 2-3")] if scene.coupling["traction"] == "full" else []),
            PlannedCoupling("solid.velocity", "fluid.solid_velocity",
                            "P1 (solid mesh) -> Q0 (fluid cells), pseudo_l2", "step 6"),
        ]
        c = scene.coupling
        quasi = ""
        if fluid_cfg["participant"] == "openfoam":
            quasi = (f", transient: pimpleFoam over each step ({fluid_cfg['substeps']} time step"
                     f"{'s' * (fluid_cfg['substeps'] > 1)}) and an elastodynamic solid"
                     if "dynamics" in scene.effects else ", quasi-static: steady simpleFoam and a static solid per step")
        iteration = (f"{scene.time['steps']} time steps of {scene.time['dt']:g} s{quasi}; implicit fixed point per "
                     f"step ({c['acceleration']}, tolerance {c['tolerance']:g}, at most {c['max_iterations']} "
                     f"iterations)")
    notes = []
    if scene.contact is not None:
        c = scene.contact
        couplings.append(PlannedCoupling(f"solid.{c['master']}", f"solid.{c['slave']}",
                                         "P1 -> P1 mortar projection T = D^-1 B, dual basis on the slave "
                                         "(pseudo_l2, surface segmentation)", "contact, eq. 9-11"))
        steps = scene.time["steps"]
        iteration = (f"contact: {steps} load step{'s' * (steps > 1)} (loads ramped linearly, each step starts "
                     f"from the last), {c['solver']} on the transformed system of eq. 10 per step")
    if "flow" in scene.effects and scene.solvers["fluid"]["participant"] == "openfoam":
        velocity = ("openfoam: the solid velocity is applied per solid body (a rigid translation with the mean "
                    "velocity of its wetted cells; rotation and deformation within a body are not)"
                    if scene.solvers["fluid"]["solid_velocity"] == "bodies" else
                    "openfoam: the solid velocity is not applied (penalization towards rest)")
        notes.append(velocity + ("" if scene.coupling["deformation"] else
                                 "; [coupling] deformation = false: the solid fraction comes from the undeformed solid"))
        fluid_cfg = scene.solvers["fluid"]
        if fluid_cfg["solver_ranks"] > 1:
            notes.append(f"openfoam: the fluid solver runs on {fluid_cfg['solver_ranks']} MPI ranks "
                         f"({fluid_cfg['decomposition']} decomposition by decomposePar once; fields written and "
                         f"read per processor, no reconstructPar)")
    if scene.material["nu"] > 0.49 and solid_cfg.get("degree", 1) == 1:
        notes.append(f"nu = {scene.material['nu']:g} is nearly incompressible: P1 tetrahedra lock; "
                     f"use [solvers.solid] degree = 2")
    return Plan(effects=list(scene.effects), participants=participants, couplings=couplings,
                loads=[_describe_load(load) for load in scene.loads], iteration=iteration, notes=notes)
