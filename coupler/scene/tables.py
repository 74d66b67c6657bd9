"""Typed reading of scene tables: every value checked where it is read, every error naming
the scene file, the table and key, and the reason::

    cases/x/scene.toml: [transfer] source: file 'a.vtu' not found
"""

from __future__ import annotations

import math
from pathlib import Path

from coupler.errors import SceneError

SCENE_FILE = "scene.toml"


def scene_path(case) -> tuple[Path, Path]:
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


def check_tables(path: Path, data: dict, tables, kind: str) -> None:
    """SceneError unless every table of `data` is one of `tables` (a scene of `kind`)."""
    for name in data:
        if name not in tables:
            raise SceneError(f"{path}: unknown table [{name}]; known tables of {kind}: "
                             f"{', '.join(f'[{t}]' for t in tables)}")


