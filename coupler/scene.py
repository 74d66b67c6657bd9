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
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from transfer.operators import METHODS

from .errors import SceneError

SCENE_FILE = "scene.toml"

#: table -> key -> one-line description (also the list of allowed keys)
KEYS = {
    "transfer": {
        "source": "source mesh file, relative to the case directory",
        "target": "target mesh file, relative to the case directory",
        "field": "name of a point (or cell) field of the source file",
        "method": f"transfer method, one of {', '.join(METHODS)}",
        "methods": "list of transfer methods, run one after the other",
        "exact": "optional: the field as an expression in x, y, z (numpy), to measure the error",
        "quadrature_degree": "optional: quadrature degree (default: exact for the bases)",
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


def _positive_int(where, value):
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise SceneError(f"{where}: must be a positive integer, got {value!r}")
    return value


def _string(where, value):
    if not isinstance(value, str) or not value.strip():
        raise SceneError(f"{where}: must be a non-empty string, got {value!r}")
    return value


def _method(where, value):
    if value not in METHODS:
        raise SceneError(f"{where}: unknown method {value!r}; use one of {', '.join(repr(m) for m in METHODS)}")
    return value


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
    return _load_transfer(path, case_dir, data, output)


def _load_transfer(path: Path, case_dir: Path, data: dict, output) -> TransferScene:
    for table, value in data.items():
        if table not in KEYS and not isinstance(value, dict):
            raise SceneError(f"{path}: {table}: unknown key; a scene holds the tables "
                             f"{', '.join(f'[{t}]' for t in KEYS)}")
        if table not in KEYS:
            raise SceneError(f"{path}: unknown table [{table}]; known tables: "
                             f"{', '.join(f'[{t}]' for t in KEYS)} (a transfer scene) or [physics] "
                             f"and the tables of a coupled scene")
        if not isinstance(value, dict):
            raise SceneError(f"{path}: [{table}] must be a table, got {value!r}")
        for key in value:
            if key not in KEYS[table]:
                raise SceneError(f"{path}: [{table}] {key}: unknown key; known keys: {', '.join(KEYS[table])}")
    if "transfer" not in data:
        raise SceneError(f"{path}: [transfer]: missing table (keys: {', '.join(KEYS['transfer'])})")
    tr, out = data["transfer"], data.get("output", {})

    def where(table, key):
        return f"{path}: [{table}] {key}"

    def required(key):
        if key not in tr:
            raise SceneError(f"{where('transfer', key)}: missing ({KEYS['transfer'][key]})")
        return tr[key]

    files = {}
    for key in ("source", "target"):
        name = _string(where("transfer", key), required(key))
        file = case_dir / name
        if not file.exists():
            raise SceneError(f"{where('transfer', key)}: file {name!r} not found")
        if not file.is_file():
            raise SceneError(f"{where('transfer', key)}: {name!r} is not a file")
        files[key] = file
    field = _string(where("transfer", "field"), required("field"))

    if "method" in tr and "methods" in tr:
        raise SceneError(f"{where('transfer', 'methods')}: give either method or methods, not both")
    if "method" in tr:
        methods = [_method(where("transfer", "method"), tr["method"])]
    elif "methods" in tr:
        value = tr["methods"]
        if not isinstance(value, list) or not value:
            raise SceneError(f"{where('transfer', 'methods')}: must be a non-empty list of methods, "
                             f"e.g. {list(METHODS)}, got {value!r}")
        methods = [_method(where("transfer", "methods"), m) for m in value]
        if len(set(methods)) != len(methods):
            raise SceneError(f"{where('transfer', 'methods')}: a method is listed twice in {value!r}")
    else:
        methods_list = ", ".join(f'"{m}"' for m in METHODS)
        raise SceneError(f'{where("transfer", "method")}: missing (give method = "{METHODS[0]}" '
                         f'or methods = [{methods_list}])')

    exact = tr.get("exact")
    if exact is not None:
        _string(where("transfer", "exact"), exact)
        check_expression(exact, where("transfer", "exact"))
    qdeg = tr.get("quadrature_degree")
    if qdeg is not None:
        _positive_int(where("transfer", "quadrature_degree"), qdeg)
    threads = _positive_int(where("transfer", "threads"), tr.get("threads", 1))

    if output is not None:
        output_dir = Path(output)
    else:
        output_dir = case_dir / _string(where("output", "directory"), out.get("directory", "results"))
    if output_dir.exists() and not output_dir.is_dir():
        origin = "--output" if output is not None else where("output", "directory")
        raise SceneError(f"{origin}: {str(output_dir)!r} exists and is not a directory")
    slice_z = out.get("slice_z")
    if slice_z is not None and (isinstance(slice_z, bool) or not isinstance(slice_z, (int, float))):
        raise SceneError(f"{where('output', 'slice_z')}: must be a number, got {slice_z!r}")

    return TransferScene(path=path, case_dir=case_dir, source=files["source"], target=files["target"],
                         field=field, methods=methods, exact=exact, quadrature_degree=qdeg, threads=threads,
                         output_dir=output_dir, slice_z=None if slice_z is None else float(slice_z))
