"""Scene files: ``cases/NAME/scene.toml`` read with tomllib and validated.

A scene is either a transfer (a ``[transfer]`` table: carry a field from a
source mesh file to a target mesh file with one or more methods, and an
``[output]`` table) or a coupled case (a ``[physics]`` table, see
:mod:`coupler.coupled_scene`); cases/README.md documents every key. Every error names the scene file,
the table and key, and the reason::

    cases/x/scene.toml: [transfer] source: file 'a.vtu' not found
"""

from __future__ import annotations

import ast
import importlib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from transfer import QuadratureError
from transfer.operators import METHODS
from transfer.quadrature import MAX_DEGREE, check_degree

from .errors import SceneError

SCENE_FILE = "scene.toml"

#: table -> key -> one-line description (also the list of allowed keys)
KEYS = {
    "case": {"description": "one line on what the case shows"},
    "transfer": {
        "source": "source mesh file, relative to the case directory",
        "target": "target mesh file, relative to the case directory",
        "field": "name of a point (or cell) field of the source file",
        "method": f"transfer method, one of {', '.join(METHODS)}",
        "methods": "list of transfer methods, run one after the other",
        "exact": "optional: the field as an expression in x, y, z (numpy), to measure the error",
        "quadrature_degree": f"optional: quadrature degree, 1 to {MAX_DEGREE} (default: exact for the bases)",
        "threads": "optional: threads of the assembly kernel (default 1)",
    },
    "output": {
        "directory": "output directory, relative to the case directory (default 'results')",
        "slice_z": "optional: height of the horizontal slice in the plot (default: middle of the target)",
    },
}

#: names an ``exact`` expression may use besides x, y, z
FUNCTIONS = {name: getattr(np, name) for name in (
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "sinh", "cosh", "tanh", "exp", "log",
    "log10", "log2", "sqrt", "abs", "minimum", "maximum", "where", "hypot", "floor", "ceil", "sign", "clip")}
CONSTANTS = {"pi": np.pi, "e": np.e}
VARIABLES = ("x", "y", "z")


@dataclass
class TransferScene:
    path: Path  # the scene file, as given (relative paths stay relative in messages)
    case_dir: Path
    description: str
    source: Path
    target: Path
    field: str
    methods: list[str]
    exact: str | None
    quadrature_degree: int | None
    threads: int
    output_dir: Path
    slice_z: float | None

    def error(self, table: str, key: str, reason: str) -> SceneError:
        return SceneError(f"{self.path}: [{table}] {key}: {reason}")


def _scene_path(case) -> tuple[Path, Path]:
    case = Path(case)
    if case.is_file():
        return case, case.parent
    if not case.exists():
        raise SceneError(f"{case}: case directory not found")
    path = case / SCENE_FILE
    if not path.is_file():
        raise SceneError(f"{case}: no {SCENE_FILE} in the case directory")
    return path, case


_REQUIRED = object()


class Table:
    """One table of the scene: typed access to its keys, errors naming the key."""

    def __init__(self, path: Path, name: str, data, keys: dict[str, str]):
        self.path, self.name, self.keys = path, name, keys
        if not isinstance(data, dict):
            raise SceneError(f"{path}: [{name}] must be a table, got {data!r}")
        self.data = data
        for key in data:
            if key not in keys:
                raise SceneError(f"{self.where(key)}: unknown key; known keys: {', '.join(keys)}")

    def where(self, key: str) -> str:
        return f"{self.path}: [{self.name}] {key}"

    def error(self, key: str, reason: str) -> SceneError:
        return SceneError(f"{self.where(key)}: {reason}")

    def _value(self, key, default):
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            raise self.error(key, f"missing ({self.keys[key]})")
        return default

    def string(self, key, default=_REQUIRED, choices=None):
        value = self._value(key, default)
        if value is None:
            return None
        if not isinstance(value, str) or not value.strip():
            raise self.error(key, f"must be a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.error(key, f"unknown value {value!r}; use one of {', '.join(map(repr, choices))}")
        return value

    def number(self, key, default=_REQUIRED, positive=False, minimum=None, maximum=None):
        value = self._value(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f"must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, f"must be a finite number, got {value!r}")
        if positive and not value > 0:
            raise self.error(key, f"must be positive, got {value!r}")
        if minimum is not None and value < minimum or maximum is not None and value > maximum:
            raise self.error(key, f"must lie in [{minimum}, {maximum}], got {value!r}")
        return value

    def integer(self, key, default=_REQUIRED, minimum=1):
        value = self._value(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise self.error(key, f"must be an integer >= {minimum}, got {value!r}")
        return value

    def vector(self, key, default=_REQUIRED, length=3):
        value = self._value(key, default)
        if value is None:
            return None
        if (not isinstance(value, list) or len(value) != length
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value)):
            raise self.error(key, f"must be a list of {length} finite numbers, got {value!r}")
        return [float(v) for v in value]

    def shape(self, key, default=_REQUIRED):
        """Cells per axis: a list of 3 positive integers."""
        value = self._value(key, default)
        if not isinstance(value, list) or len(value) != 3 or any(
                isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in value):
            raise self.error(key, f"must be a list of 3 positive integers, got {value!r}")
        return list(value)

    def numbers(self, key, default=_REQUIRED, integer=False, positive=False, minimum=None, below=None,
                increasing=False, within=None):
        """A list of numbers (integers with `integer`), distinct, in [minimum, below) (and > 0 with
        `positive`); with `increasing` strictly increasing; with `within` each one of those values
        (may then be empty)."""
        value = self._value(key, default)
        kind = int if integer else (int, float)
        if (not isinstance(value, list) or not value and within is None
                or any(isinstance(v, bool) or not isinstance(v, kind) or not math.isfinite(v) for v in value)):
            raise self.error(key, f"must be a {'non-empty ' * (within is None)}list of "
                                  f"{'integers' if integer else 'finite numbers'}, got {value!r}")
        if value and (minimum is not None and min(value) < minimum or below is not None and max(value) >= below):
            raise self.error(key, f"values must lie in [{minimum}, {below if below is not None else 'inf'}), "
                                  f"got {value!r}")
        if positive and value and not min(value) > 0:
            raise self.error(key, f"values must be positive, got {value!r}")
        if len(set(value)) != len(value):
            raise self.error(key, f"a value is listed twice in {value!r}")
        if increasing and any(b <= a for a, b in zip(value, value[1:])):
            raise self.error(key, f"must be increasing, got {value!r}")
        if within is not None and any(v not in within for v in value):
            raise self.error(key, f"{value!r}: every value must be one of {list(within)!r}")
        return list(value) if integer else [float(v) for v in value]

    def file(self, key, case_dir: Path) -> Path:
        """A file named relative to the case directory, which must exist."""
        name = self.string(key)
        file = Path(case_dir) / name
        if not file.exists():
            raise self.error(key, f"file {name!r} not found")
        if not file.is_file():
            raise self.error(key, f"{name!r} is not a file")
        return file

    def strings(self, key, default=_REQUIRED, choices=None):
        value = self._value(key, default)
        if not isinstance(value, list) or any(not isinstance(v, str) for v in value):
            raise self.error(key, f"must be a list of strings, got {value!r}")
        for v in value:
            if choices is not None and v not in choices:
                raise self.error(key, f"unknown value {v!r}; use one of {', '.join(map(repr, choices))}")
        if len(set(value)) != len(value):
            raise self.error(key, f"a value is listed twice in {value!r}")
        return list(value)

    def boolean(self, key, default=_REQUIRED):
        value = self._value(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"must be true or false, got {value!r}")
        return value


def output_directory(case_dir: Path, out: Table, output) -> Path:
    """``--output`` (relative to the working directory) or ``[output] directory``
    (relative to the case, default ``results``); it must not be a file."""
    output_dir = Path(output) if output is not None else Path(case_dir) / out.string("directory", "results")
    if output_dir.exists() and not output_dir.is_dir():
        origin = "--output" if output is not None else out.where("directory")
        raise SceneError(f"{origin}: {str(output_dir)!r} exists and is not a directory")
    return output_dir


def check_expression(text: str, where: str) -> None:
    """Reject an ``exact`` expression that does not parse or uses other names
    than x, y, z and :data:`FUNCTIONS` / :data:`CONSTANTS` (no attributes)."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise SceneError(f"{where}: invalid expression {text!r}: {exc.msg}") from None
    allowed = set(VARIABLES) | set(FUNCTIONS) | set(CONSTANTS)
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id not in allowed:
            raise SceneError(f"{where}: unknown name {node.id!r} in {text!r}; use x, y, z, "
                             f"{', '.join(CONSTANTS)} and {', '.join(FUNCTIONS)}")
        if isinstance(node, ast.Attribute):
            raise SceneError(f"{where}: attribute access ('.{node.attr}') is not allowed in {text!r}")


def evaluate_expression(text: str, points: np.ndarray) -> np.ndarray:
    """Values of an expression in x, y, z (checked by :func:`check_expression`) at (n, 3) points."""
    # copies: an expression like sin(x, y) writes into its second argument (numpy's out=)
    x, y, z = (np.array(np.asarray(points)[:, d], dtype=np.float64) for d in range(3))
    namespace = {"__builtins__": {}, **FUNCTIONS, **CONSTANTS}
    with np.errstate(all="ignore"):
        value = eval(compile(text.strip(), "<exact>", "eval"), namespace, {"x": x, "y": y, "z": z})
    return np.broadcast_to(np.asarray(value, dtype=np.float64), x.shape).copy()


# Scenes that are studies run inside the coupler process (no participants), recognised by
# a marker table: marker -> module. Each module provides ``parse(path, case_dir, data,
# output)`` -> a scene with ``path`` and ``output_dir``, ``plan_lines(scene)`` -> the plan
# as text (``varcouple check``) and ``run(scene, log)`` -> the summary dict (a failed
# ``[check]`` is ``summary["check"]["passed"] == False``).
STUDIES = {
    "plates": "coupler.plates_case",  # immersed parallel plates against the cubic law
    "obstacle": "coupler.obstacle_case",  # a body pressed onto a plane, nonsmooth multilevel
    "closure": "coupler.closure_case",  # fracture closure under normal stress, mortar contact
}


def load(case, output: str | Path | None = None):
    """Read and validate the scene of `case` (a case directory or its scene.toml):
    a :class:`TransferScene` or a :class:`coupler.coupled_scene.CoupledScene`.
    `output` overrides ``[output] directory`` (relative to the working directory)."""
    path, case_dir = _scene_path(case)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if "physics" in data:
        from .coupled_scene import parse

        return parse(path, case_dir, data, output)
    for marker, module in STUDIES.items():
        if marker in data:
            return importlib.import_module(module).parse(path, case_dir, data, output)
    return _load_transfer(path, case_dir, data, output)


def check_tables(path: Path, data: dict, tables, kind: str) -> None:
    """SceneError unless every table of `data` is one of `tables` (a scene of `kind`)."""
    for name in data:
        if name not in tables:
            raise SceneError(f"{path}: unknown table [{name}]; known tables of {kind}: "
                             f"{', '.join(f'[{t}]' for t in tables)}")


def study_module(scene):
    """The module of a study scene (one of :data:`STUDIES`), or None for coupled and transfer scenes."""
    module = type(scene).__module__
    return importlib.import_module(module) if module in STUDIES.values() else None


def _load_transfer(path: Path, case_dir: Path, data: dict, output) -> TransferScene:
    for table, value in data.items():
        if table not in KEYS:
            raise SceneError(f"{path}: unknown table [{table}]; known tables: "
                             f"{', '.join(f'[{t}]' for t in KEYS)} (a transfer scene), [physics] "
                             f"and the tables of a coupled scene, or a study's {', '.join(f'[{m}]' for m in STUDIES)}")
    if "transfer" not in data:
        raise SceneError(f"{path}: [transfer]: missing table (keys: {', '.join(KEYS['transfer'])})")
    case = Table(path, "case", data.get("case", {}), KEYS["case"])
    tr = Table(path, "transfer", data["transfer"], KEYS["transfer"])
    out = Table(path, "output", data.get("output", {}), KEYS["output"])
    source, target = tr.file("source", case_dir), tr.file("target", case_dir)
    field = tr.string("field")
    if "method" in tr.data and "methods" in tr.data:
        raise tr.error("methods", "give either method or methods, not both")
    if "methods" in tr.data:
        methods = tr.strings("methods", choices=METHODS)
        if not methods:
            raise tr.error("methods", f"must be a non-empty list of methods, e.g. {list(METHODS)}")
    elif "method" in tr.data:
        methods = [tr.string("method", choices=METHODS)]
    else:
        methods_list = ", ".join(f'"{m}"' for m in METHODS)
        raise tr.error("method", f'missing (give method = "{METHODS[0]}" or methods = [{methods_list}])')
    exact = tr.string("exact", None)
    if exact is not None:
        check_expression(exact, tr.where("exact"))
    qdeg = tr.integer("quadrature_degree", None) if "quadrature_degree" in tr.data else None
    if qdeg is not None:
        try:
            check_degree(qdeg)
        except QuadratureError as exc:
            raise tr.error("quadrature_degree", str(exc)) from None
    slice_z = out.number("slice_z", None)
    return TransferScene(path=path, case_dir=case_dir, description=case.string("description", None) or "",
                         source=source, target=target, field=field, methods=methods, exact=exact,
                         quadrature_degree=qdeg, threads=tr.integer("threads", 1),
                         output_dir=output_directory(case_dir, out, output), slice_z=slice_z)
