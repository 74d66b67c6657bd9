"""The plan of a coupled scene: the object ``varcouple check`` prints and ``varcouple run``
executes (docs/architecture.md).

Each effect the scene asks for is a rule (:mod:`coupler.plan.effects`) that adds what it
needs: participants (each with the configuration it will be sent), exchanges (fields that
cross between participants, each with the operator that carries them, its place in
Steps 1-6 of paper 2.3 and whether it is the accelerated interface quantity of the fixed
point), loads and notes. Nothing that no effect asks for is planned: a scene without flow
starts no fluid, and a quasi-static one sends no solid velocity to the grid.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


@dataclass
class PlannedParticipant:
    """A participant to start: ``python -m module`` on ``ranks`` MPI ranks, sent ``config``;
    or, ``in_process``, a stand-in of ``module`` served inside the coupler (one that solves
    nothing: a fixed solid, a mesh file)."""

    name: str  # "solid", "fluid"
    kind: str  # "solid_fenicsx", "openfoam", "spring_solid", ...
    module: str
    ranks: int
    config: dict = field(default_factory=dict)
    allow_unconverged: bool = False  # its unconverged inner solves accepted on purpose
    in_process: bool = False
    arguments: list[str] = field(default_factory=list)  # after the protocol's own (the stand-ins' --kind KIND)

    @classmethod
    def of(cls, solver, config: dict) -> "PlannedParticipant":
        """The participant of a scene's validated ``[solvers.X]`` (:class:`coupler.scene.participants.Solver`)."""
        spec = solver.spec
        return cls(solver.role, spec.kind, spec.module, solver.processes, config, solver.allow_unconverged,
                   arguments=list(spec.arguments))

    def describe(self) -> str:
        if self.in_process:
            return f"{self.name}: {self.kind} (served in the coupler's process)"
        command = " ".join(["python -m", self.module, *self.arguments])
        return f"{self.name}: {self.kind} ({command}, {self.ranks} rank{'s' * (self.ranks > 1)})"


@dataclass
class Exchange:
    """Fields that cross: `operator` (a name of :data:`coupler.fsi.operators.OPERATORS`)
    turns the latest outputs of the `sources` (``"participant.field"``) into the input
    `target` (``"participant.field"``) before the target advances. An accelerated exchange
    carries the interface quantity of the fixed point: its value is the iterate x, and
    evaluated on the new outputs it is H(x). `options` are the operator's (e.g. how the solid
    fraction is sampled, a projection's quadrature degree)."""

    sources: list[str]
    target: str
    operator: str
    step: str  # its place in Steps 1-6 of paper 2.3 ("" outside a fluid-solid coupling)
    accelerated: bool = False
    description: str = ""
    options: dict = field(default_factory=dict)

    @property
    def target_participant(self) -> str:
        return self.target.split(".", 1)[0]

    @property
    def target_field(self) -> str:
        return self.target.split(".", 1)[1]

    def describe(self) -> str:
        acc = ", accelerated" if self.accelerated else ""
        options = f" ({', '.join(f'{k} {v}' for k, v in self.options.items())})" if self.options else ""
        step = f" [step {self.step}{acc}]" if self.step else ""
        return f"{', '.join(self.sources)} -> {self.target}: {self.operator}{options}{step} {self.description}"


@dataclass
class Plan:
    effects: list[str]
    participants: list[PlannedParticipant] = field(default_factory=list)  # in the order they advance
    exchanges: list[Exchange] = field(default_factory=list)
    loads: list[str] = field(default_factory=list)
    tasks: list[str] = field(default_factory=list)  # what a participant does inside (e.g. contact)
    iteration: str = ""
    notes: list[str] = field(default_factory=list)  # warnings about the scene, printed by check and run
    monitors: list[str] = field(default_factory=list)  # per-step figures (coupler.fsi.monitors.MONITORS)

    @property
    def implicit(self) -> bool:
        """A fixed point per step (an accelerated exchange), else one advance per step."""
        return any(e.accelerated for e in self.exchanges)

    def participant(self, name: str) -> PlannedParticipant:
        for p in self.participants:
            if p.name == name:
                return p
        raise KeyError(f"the plan has no participant {name!r} (it has {[p.name for p in self.participants]})")

    def inputs_of(self, name: str) -> list[Exchange]:
        return [e for e in self.exchanges if e.target_participant == name]

    def as_dict(self) -> dict:
        """The plan for summary.json."""
        return {"effects": self.effects,
                "participants": [{k: v for k, v in asdict(p).items() if k != "config"} for p in self.participants],
                "exchanges": [asdict(e) for e in self.exchanges],
                "loads": self.loads, "tasks": self.tasks, "iteration": self.iteration, "notes": self.notes,
                **({"monitors": self.monitors} if self.monitors else {})}

    def lines(self) -> list[str]:
        """The plan as text, for ``varcouple check``."""
        out = [f"effects       {', '.join(self.effects)}"]
        out += [f"participant   {p.describe()}" for p in self.participants]
        if not self.exchanges:
            out.append("exchanges     none (no field crosses between participants)")
        out += [f"exchange      {e.describe()}" for e in self.exchanges]
        out += [f"load          {load}" for load in self.loads]
        out += [f"task          {task}" for task in self.tasks]
        out += [f"figures       {m} per step" for m in self.monitors]
        out.append(f"iteration     {self.iteration}")
        out += [f"note          {n}" for n in self.notes]
        return out


def make_plan(scene) -> Plan:
    """The minimal plan for the effects of `scene`: each effect's rule, in the rules' order."""
    from .effects import RULES

    plan = Plan(effects=list(scene.effects))
    for name, rule in RULES.items():
        if name in scene.effects:
            rule.plan(scene, plan)
    plan.notes += [note for solver in scene.solvers.values() for note in solver.notes]
    if scene.solid is not None:
        plan.notes += scene.solid.notes
    return plan
