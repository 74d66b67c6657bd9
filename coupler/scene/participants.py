"""The participants a scene may name, and its ``[solvers.X]`` tables read through them.

Participants are found through the entry-point group ``varcouple.participants``
(pyproject.toml: kind -> ``package.settings:OBJECT``, a
:class:`~coupler.protocol.settings.ParticipantSpec`). A ``[solvers.X]`` table holds the keys
every one has (:func:`common`: ``participant``, ``ranks``, ``allow_unconverged``) and the keys
the chosen participant declares, validated through its declaration: nothing of a participant
is known here but what it declares.

Reading a declaration imports the participant's light ``settings`` module only, never its
solver (tests/test_layers.py)."""

from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import entry_points

from coupler.errors import CouplerError, SceneError
from coupler.protocol.settings import REQUIRED, ParticipantSpec, Setting, Settings

GROUP = "varcouple.participants"
#: the participant of each role when ``[solvers.X]`` names none
DEFAULTS = {"solid": "solid_fenicsx", "fluid": "openfoam"}

_registered: dict[str, ParticipantSpec] | None = None


def registered() -> dict[str, ParticipantSpec]:
    """kind -> declaration of every installed participant, by kind."""
    global _registered
    if _registered is None:
        found = {}
        for ep in entry_points(group=GROUP):
            try:
                spec = ep.load()
            except Exception as exc:  # noqa: BLE001 - a broken plug-in is named, not a traceback
                raise CouplerError(f"entry point {GROUP} {ep.name} = {ep.value}: cannot load it: {exc}") from None
            if not isinstance(spec, ParticipantSpec) or spec.kind != ep.name:
                raise CouplerError(f"entry point {GROUP} {ep.name} = {ep.value}: not the ParticipantSpec of kind "
                                   f"{ep.name!r} (got {spec!r:.80})")
            found[ep.name] = spec
        _registered = dict(sorted(found.items()))
    return _registered


def for_role(role: str) -> dict[str, ParticipantSpec]:
    """The participants that can fill ``[solvers.<role>]``."""
    return {kind: spec for kind, spec in registered().items() if spec.role == role}


def common(role: str) -> Settings:
    """The keys of every ``[solvers.<role>]`` (the coupler's, not a participant's)."""
    return Settings(
        Setting("participant", "string", "which participant runs this part (one of those below for the role); "
                "swapping a solver is this one line, with that participant's own keys",
                default=DEFAULTS.get(role, REQUIRED), choices=tuple(for_role(role))),
        Setting("ranks", "integer", "MPI ranks: the coupler starts the participant with mpirun -n ranks (a "
                "participant that declares ranks itself is one process running its solver on them)",
                default=1, minimum=1),
        Setting("allow_unconverged", "boolean", "accept this participant's unconverged inner solves on purpose "
                "(e.g. a deliberately capped steady solve); false: a step whose accepted coupling iteration rests "
                "on an unconverged inner solve stops the run with status not_converged (exit 3); true: the run "
                "goes on and summary.json lists the accepted solves per step (accepted_unconverged)",
                default=False))


@dataclass
class Solver:
    """A validated ``[solvers.<role>]``: the chosen participant, the MPI ranks of this part,
    whether its unconverged inner solves are accepted, and its own settings (its configuration
    keys, the defaults filled in)."""

    role: str
    spec: ParticipantSpec
    ranks: int
    allow_unconverged: bool
    settings: dict
    ignored: dict[str, str]  # key -> the participant of the role that declares it (not the chosen one)

    @property
    def kind(self) -> str:
        return self.spec.kind

    @property
    def processes(self) -> int:
        """MPI processes to start: one for a participant that runs its own ranks."""
        return 1 if self.spec.own_ranks else self.ranks

    @property
    def notes(self) -> list[str]:
        return [f"[solvers.{self.role}] {key}: a key of {owner}, ignored by {self.kind}"
                for key, owner in self.ignored.items()]


def read_solver(path, role: str, data) -> Solver:
    """``[solvers.<role>]`` of the scene `path`, validated through the declaration of the
    participant it names; errors ``<scene.toml>: [solvers.<role>] <key>: <reason>``. A key
    that another participant of the role declares is set aside (and noted in the plan), so
    that swapping a participant stays its ``participant`` line; any other unknown key is refused."""
    where = f"{path}: [solvers.{role}]"
    keys = common(role)
    if not isinstance(data, dict):
        raise SceneError(f"{where} must be a table, got {data!r}")
    kind = Settings(keys["participant"]).pick(data, where)["participant"]
    spec = registered()[kind]
    own = keys + spec.settings
    others = {name: other for other, o in for_role(role).items() if other != kind for name in o.settings.names}
    ignored = {key: others[key] for key in data if key not in own and key in others}
    values = own.validate({k: v for k, v in data.items() if k not in ignored}, where, owner=f"participant {kind!r}")
    return Solver(role, spec, values["ranks"], values["allow_unconverged"],
                  {name: values[name] for name in spec.settings.names}, ignored)
