"""Typed reading of scene tables: every value checked where it is read, every error naming
the scene file, the table and key, and the reason::

    cases/x/scene.toml: [transfer] source: file 'a.vtu' not found
"""

from __future__ import annotations

from pathlib import Path

from coupler.errors import SceneError
from coupler.protocol.settings import (REQUIRED, Invalid, check_boolean, check_integer, check_number, check_numbers,
                                       check_shape, check_string, check_strings, check_vector)
from transfer.errors import MeshError
from transfer.mesh import check_coordinates

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
        if default is REQUIRED:
            raise self.error(key, f"missing ({self.keys[key]})")
        return default

    def _checked(self, key, default, check, *args, optional=False):
        """The value of `key` (or `default`) through one of the checks of
        :mod:`coupler.protocol.settings`; with `optional`, None stays None."""
        value = self._value(key, default)
        if value is None and optional:
            return None
        try:
            return check(value, *args)
        except Invalid as exc:
            raise self.error(key, str(exc)) from None

    def string(self, key, default=REQUIRED, choices=None):
        return self._checked(key, default, check_string, choices, optional=True)

    def number(self, key, default=REQUIRED, positive=False, minimum=None, maximum=None):
        return self._checked(key, default, check_number, positive, minimum, maximum, optional=True)

    def integer(self, key, default=REQUIRED, minimum=1):
        return self._checked(key, default, check_integer, minimum)

    def vector(self, key, default=REQUIRED, length=3):
        return self._checked(key, default, check_vector, length, optional=True)

    def point(self, key):
        """A point or length of the geometry: 3 finite numbers within :data:`transfer.mesh.COORDINATE_LIMIT`."""
        value = self.vector(key)
        try:
            check_coordinates(key, [value])
        except MeshError as exc:
            raise self.error(key, str(exc).removeprefix(f"{key}: ")) from None
        return value

    def shape(self, key, default=REQUIRED):
        """Cells per axis: a list of 3 positive integers."""
        return self._checked(key, default, check_shape)

    def numbers(self, key, default=REQUIRED, integer=False, positive=False, minimum=None, below=None,
                increasing=False, within=None):
        """A list of numbers (:func:`coupler.protocol.settings.check_numbers`)."""
        return self._checked(key, default, check_numbers, integer, positive, minimum, below, increasing, within)

    def file(self, key, case_dir: Path) -> Path:
        """A file named relative to the case directory, which must exist inside it (:func:`in_case`)."""
        name = self.string(key)
        file = in_case(case_dir, name, self.where(key))
        if not file.exists():
            raise self.error(key, f"file {name!r} not found")
        if not file.is_file():
            raise self.error(key, f"{name!r} is not a file")
        return file

    def strings(self, key, default=REQUIRED, choices=None):
        return self._checked(key, default, check_strings, choices)

    def boolean(self, key, default=REQUIRED):
        return self._checked(key, default, check_boolean)


def in_case(case_dir: Path, name: str, where: str, written: bool = False) -> Path:
    """``case_dir / name``, SceneError naming `where` unless it lies inside the case directory
    once resolved (``..``, an absolute name and symbolic links followed): a scene reads its
    inputs and writes its outputs (`written`) only in its case directory, whoever wrote it
    (cases/README.md). Checked before anything looks at the file, so the error says nothing
    of the files outside."""
    case, path = Path(case_dir).resolve(), Path(case_dir) / name
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError, ValueError) as exc:  # a loop of links, a NUL in the name
        raise SceneError(f"{where}: {name!r} is not a usable file name ({exc})") from None
    if not resolved.is_relative_to(case):
        how = "writes only inside it; write elsewhere with --output DIR" if written else \
            "reads input files only from inside it; copy the file into it"
        raise SceneError(f"{where}: {name!r} is outside the case directory {case} (links followed): a scene {how}")
    return path


def output_directory(case_dir: Path, out: Table, output) -> Path:
    """``--output`` (relative to the working directory, anywhere) or ``[output] directory``
    (relative to the case, default ``results``, inside it: :func:`in_case`); it must not be a file."""
    output_dir = Path(output) if output is not None else \
        in_case(case_dir, out.string("directory", "results"), out.where("directory"), written=True)
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


