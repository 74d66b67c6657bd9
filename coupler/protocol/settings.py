"""Settings declarations: every participant declares its keys once, here in typed form.

A :class:`Setting` is one key (name, type, default or required, choices, unit, bounds,
one-line description); :class:`Settings` an ordered set of them that validates a table
(``[solvers.X]`` of a scene) or picks its keys out of a participant's configuration, with
the defaults filled in; a :class:`ParticipantSpec` is what a participant package declares
about itself in its light ``settings`` module (no solver import): its kind, the module the
coupler starts, its role and its settings. The coupler finds the declarations through the
entry-point group ``varcouple.participants`` (pyproject.toml).

The value checks (``check_number``, ``check_string``, ...) are the only implementation of the
typed checks of scene tables too (:class:`coupler.scene.tables.Table` uses them). Each raises
:class:`Invalid` with the reason; callers prefix the file, table and key::

    cases/x/scene.toml: [solvers.fluid] tolerance: must be positive, got -1.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

from coupler.errors import SceneError


class Invalid(ValueError):
    """A value refused by a check: the message is the reason alone (no key, no file)."""


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: the default of a setting that must be given
REQUIRED = _Required()


def _is_number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float))


def check_string(value, choices=None) -> str:
    if not isinstance(value, str) or not value.strip():
        raise Invalid(f"must be a non-empty string, got {value!r}")
    return check_choice(value, choices)


def check_choice(value, choices):
    if choices is not None and value not in choices:
        raise Invalid(f"unknown value {value!r}; use one of {', '.join(map(repr, choices))}")
    return value


def check_number(value, positive=False, minimum=None, maximum=None) -> float:
    """A finite number (int or float, not bool), > 0 with `positive`, in [minimum, maximum]."""
    if not _is_number(value):
        raise Invalid(f"must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise Invalid(f"must be a finite number, got {value!r}")
    if positive and not value > 0:
        raise Invalid(f"must be positive, got {value!r}")
    if minimum is not None and value < minimum or maximum is not None and value > maximum:
        bounds = (f"lie in [{minimum}, {maximum}]" if minimum is not None and maximum is not None else
                  f"be >= {minimum}" if minimum is not None else
                  f"lie in (0, {maximum}]" if positive else f"be <= {maximum}")
        raise Invalid(f"must {bounds}, got {value!r}")
    return value


def check_integer(value, minimum=None, maximum=None, choices=None) -> int:
    """An integer (not bool) in [minimum, maximum], one of `choices` when given."""
    if (isinstance(value, bool) or not isinstance(value, int) or minimum is not None and value < minimum
            or maximum is not None and value > maximum):
        if minimum is not None and minimum == maximum and not isinstance(value, bool) and isinstance(value, int):
            raise Invalid(f"must be {minimum}, got {value!r}")
        bounds = (f" in [{minimum}, {maximum}]" if minimum is not None and maximum is not None else
                  f" >= {minimum}" if minimum is not None else f" <= {maximum}" if maximum is not None else "")
        raise Invalid(f"must be an integer{bounds}, got {value!r}")
    return check_choice(value, choices)


def check_boolean(value) -> bool:
    if not isinstance(value, bool):
        raise Invalid(f"must be true or false, got {value!r}")
    return value


def check_vector(value, length=3) -> list[float]:
    """A list of `length` finite numbers."""
    if not isinstance(value, list) or len(value) != length or any(
            not _is_number(v) or not math.isfinite(v) for v in value):
        raise Invalid(f"must be a list of {length} finite numbers, got {value!r}")
    return [float(v) for v in value]


def check_shape(value) -> list[int]:
    """Cells per axis: a list of 3 positive integers."""
    if not isinstance(value, list) or len(value) != 3 or any(
            isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in value):
        raise Invalid(f"must be a list of 3 positive integers, got {value!r}")
    return list(value)


def check_numbers(value, integer=False, positive=False, minimum=None, below=None, increasing=False, within=None,
                  empty=False) -> list:
    """A list of numbers (integers with `integer`), distinct, in [minimum, below) (and > 0 with
    `positive`); with `increasing` strictly increasing; with `within` each one of those values.
    Empty only with `empty` or `within`."""
    kind = int if integer else (int, float)
    may_be_empty = empty or within is not None
    if (not isinstance(value, list) or not value and not may_be_empty
            or any(isinstance(v, bool) or not isinstance(v, kind) or not math.isfinite(v) for v in value)):
        raise Invalid(f"must be a {'non-empty ' * (not may_be_empty)}list of "
                      f"{'integers' if integer else 'finite numbers'}, got {value!r}")
    if value and (minimum is not None and min(value) < minimum or below is not None and max(value) >= below):
        raise Invalid(f"values must lie in [{minimum}, {below if below is not None else 'inf'}), got {value!r}")
    if positive and value and not min(value) > 0:
        raise Invalid(f"values must be positive, got {value!r}")
    if len(set(value)) != len(value):
        raise Invalid(f"a value is listed twice in {value!r}")
    if increasing and any(b <= a for a, b in zip(value, value[1:])):
        raise Invalid(f"must be increasing, got {value!r}")
    if within is not None and any(v not in within for v in value):
        raise Invalid(f"{value!r}: every value must be one of {list(within)!r}")
    return list(value) if integer else [float(v) for v in value]


def check_strings(value, choices=None) -> list[str]:
    """A list of distinct strings, each one of `choices` when given."""
    if not isinstance(value, list) or any(not isinstance(v, str) for v in value):
        raise Invalid(f"must be a list of strings, got {value!r}")
    for v in value:
        check_choice(v, choices)
    if len(set(value)) != len(value):
        raise Invalid(f"a value is listed twice in {value!r}")
    return list(value)


@dataclass(frozen=True)
class When:
    """The condition under which a setting may be given: ``test`` of the value of ``key``
    (``text`` says it: ``penalization = "power"``, ``ranks > 1``)."""

    key: str
    test: Callable[[object], bool]
    text: str

    @classmethod
    def equals(cls, key: str, value) -> "When":
        return cls(key, lambda v: v == value, f"{key} = {_toml(value)}")

    @classmethod
    def above(cls, key: str, bound) -> "When":
        return cls(key, lambda v: v > bound, f"{key} > {bound}")


#: setting types: what the value must be
TYPES = ("number", "integer", "string", "boolean", "vector", "integers", "strings")


@dataclass(frozen=True)
class Setting:
    """One key of a participant's settings. ``default`` is :data:`REQUIRED` for a key that
    must be given, ``None`` for an optional key without a value (the participant decides,
    as its description says). ``positive``, ``minimum``, ``maximum`` bound numbers (and the
    values of ``integers``); ``choices`` lists the allowed values; ``only`` restricts when the
    key may be given (:class:`When`)."""

    name: str
    type: str
    description: str
    default: object = REQUIRED
    choices: tuple | None = None
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    positive: bool = False
    only: When | None = None

    def __post_init__(self):
        if self.type not in TYPES:
            raise ValueError(f"setting {self.name!r}: unknown type {self.type!r} (one of {', '.join(TYPES)})")
        if self.default is not REQUIRED and self.default is not None:
            self.check(self.default)  # a declaration whose default its own check refuses is a bug

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def check(self, value):
        """The value, checked against the type, bounds and choices (:class:`Invalid` otherwise)."""
        if self.type == "number":
            return check_choice(check_number(value, self.positive, self.minimum, self.maximum), self.choices)
        if self.type == "integer":
            return check_integer(value, self.minimum, self.maximum, self.choices)
        if self.type == "string":
            return check_string(value, self.choices)
        if self.type == "boolean":
            return check_boolean(value)
        if self.type == "vector":
            return check_vector(value)
        if self.type == "integers":
            return check_numbers(value, integer=True, positive=self.positive, minimum=self.minimum, empty=True)
        return check_strings(value, self.choices)

    def describe_type(self) -> str:
        """The type as the key reference shows it: ``number > 0``, ``integer >= 1``, ``"cg" or "lu"``."""
        if self.choices is not None and self.type in ("string", "integer", "number"):
            values = [f"`{_toml(c)}`" for c in self.choices]
            text = values[0] if len(values) == 1 else f"{', '.join(values[:-1])} or {values[-1]}"
            return f"{text}{f' [{self.unit}]' if self.unit else ''}"
        noun = {"vector": "3 numbers", "integers": "list of integers", "strings": "list of strings"}.get(
            self.type, self.type)
        lo, hi = self.minimum, self.maximum
        if lo is not None and lo == hi:
            bounds = [f"= {_toml(lo)}"]
        elif self.positive:
            bounds = ["> 0" if hi is None else f"in (0, {_toml(hi)}]"]
        elif lo is not None and hi is not None:
            bounds = [f"in [{_toml(lo)}, {_toml(hi)}]"]
        elif lo is not None:
            bounds = [f">= {_toml(lo)}"]
        else:
            bounds = [] if hi is None else [f"<= {_toml(hi)}"]
        return " ".join([noun, *bounds]) + (f" [{self.unit}]" if self.unit else "")

    def describe_default(self) -> str:
        """``required``, ``none`` or the default as TOML (in backquotes)."""
        return "required" if self.required else "none" if self.default is None else f"`{_toml(self.default)}`"


def _toml(value) -> str:
    """A value as written in a scene (TOML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, float):
        if value.is_integer() and abs(value) < 1e6:
            return f"{value:.1f}"
        mantissa, _, exponent = f"{value:g}".partition("e")
        return f"{mantissa}e{int(exponent)}" if exponent else mantissa
    return str(value)


class Settings:
    """An ordered set of :class:`Setting` (by name); ``a + b`` is `a` with `b`'s settings added
    (a setting of `b` replaces `a`'s of the same name, keeping `a`'s place)."""

    def __init__(self, *settings: Setting):
        self._by_name: dict[str, Setting] = {}
        for s in settings:
            if s.name in self._by_name:
                raise ValueError(f"setting {s.name!r} declared twice")
            self._by_name[s.name] = s

    def __iter__(self):
        return iter(self._by_name.values())

    def __len__(self) -> int:
        return len(self._by_name)

    def __contains__(self, name) -> bool:
        return name in self._by_name

    def __getitem__(self, name: str) -> Setting:
        return self._by_name[name]

    def __repr__(self) -> str:
        return f"Settings({', '.join(self.names)})"

    def __add__(self, other: "Settings") -> "Settings":
        merged = {**self._by_name, **other._by_name}
        return Settings(*merged.values())

    @property
    def names(self) -> list[str]:
        return list(self._by_name)

    def defaults(self) -> dict:
        """The default of every setting that has one."""
        return {s.name: s.default for s in self if not s.required}

    def pick(self, values: Mapping, where: str) -> dict:
        """The declared settings of `values` checked, the defaults filled in; other keys of
        `values` are ignored (a participant's configuration also holds its mesh, loads, ...).
        SceneError ``<where> <key>: <reason>`` for a wrong value or a missing required key."""
        out = {}
        for s in self:
            if s.name in values and not (values[s.name] is None and s.default is None):
                try:
                    out[s.name] = s.check(values[s.name])
                except Invalid as exc:
                    raise SceneError(f"{where} {s.name}: {exc}") from None
            elif s.required:
                raise SceneError(f"{where} {s.name}: missing ({s.description})")
            else:
                out[s.name] = list(s.default) if isinstance(s.default, list) else s.default
        return out

    def validate(self, values: Mapping, where: str, owner: str = "") -> dict:
        """A table's values checked against the declaration, with the defaults filled in:
        unknown keys, wrong types, non-finite numbers, values outside the choices or bounds,
        missing required keys and keys given where their condition (``only``) does not hold
        are refused with one line ``<where> <key>: <reason>`` (`owner` names whose keys the
        known ones are, e.g. ``participant 'openfoam'``)."""
        if not isinstance(values, Mapping):
            raise SceneError(f"{where} must be a table, got {values!r}")
        for key in values:
            if key not in self:
                whose = f" ({owner})" if owner else ""
                raise SceneError(f"{where} {key}: unknown key{whose}; known keys: {', '.join(self.names)}")
        out = self.pick(values, where)
        for s in self:
            if s.only is not None and s.name in values and not s.only.test(out[s.only.key]):
                raise SceneError(f"{where} {s.name}: applies to {s.only.text} only")
        return out


@dataclass(frozen=True)
class ParticipantSpec:
    """What a participant declares about itself (its package's light ``settings`` module).

    ``kind``: the name a scene gives (``[solvers.X] participant``); ``module``: started as
    ``python -m module`` with ``arguments`` after the protocol's own; ``role``: the
    ``[solvers.X]`` it can fill (``"solid"``, ``"fluid"``; None: none, a test participant);
    ``settings``: its keys; ``needs``: the scene tables it cannot run without (``"flow"``: the
    grid's boundary conditions); ``accepts``: the optional inputs of ``advance`` it takes
    beyond its role's (``"inlet_pressure"``: the pressure on the grid face xmin, set by the
    coupler in every coupling iteration of a flow driven by ``[flow] flow_rate``); ``memory``:
    (bytes per MPI rank, bytes per cell) of its peak
    resident memory, for the coupler's estimate before a run; ``refuses``: its own check of a
    parsed scene, the reason it cannot run it (None: it can; e.g. a fluid without a 3D
    velocity field and a solid moving in the flow); ``contact_step``: (seconds, exponent) of
    its first load step with contact, about seconds x (cells / 10^4)^exponent on a core of its
    own, for the coupler's warning that it outlasts ``[messaging] timeout`` (None: not
    estimated). A participant that declares the
    key ``ranks`` is one process that runs its own solver on that many MPI ranks (the coupler
    does not start it with ``mpirun -n``); otherwise the coupler starts it on ``ranks`` MPI
    processes."""

    kind: str
    module: str
    role: str | None
    description: str
    settings: Settings = field(default_factory=Settings)
    arguments: tuple[str, ...] = ()
    needs: tuple[str, ...] = ()
    accepts: tuple[str, ...] = ()
    memory: tuple[int, int] = (50 * 2**20, 100)
    refuses: Callable[[object], str | None] | None = None
    contact_step: tuple[float, float] | None = None

    @property
    def own_ranks(self) -> bool:
        return "ranks" in self.settings

    def configuration(self, config: Mapping) -> dict:
        """The participant's settings in a configuration it received, checked, defaults filled."""
        return self.settings.pick(config, f"{self.kind} configuration:")
