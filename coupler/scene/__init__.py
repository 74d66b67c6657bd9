"""Scene files: ``cases/NAME/scene.toml`` read with tomllib and validated.

A scene is a case of effects (a ``[physics]`` table, :mod:`coupler.scene.coupled`);
cases/README.md documents every key. Every error names the scene file, the table and key, and the reason.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from coupler.errors import SceneError

from .overrides import apply
from .tables import scene_path


def load(case, output: str | Path | None = None, overrides: dict | None = None):
    """Read and validate the scene of `case` (a case directory or its scene.toml):
    a :class:`~coupler.scene.coupled.CoupledScene`.
    `output` overrides ``[output] directory`` (relative to the working directory); `overrides`
    (``{dotted key: value}``, :mod:`coupler.scene.overrides`) set keys before validation."""
    path, case_dir = scene_path(case)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # binary content: its bytes are not shown
        raise SceneError(f"{path}: not a TOML text file: byte {exc.start} is not UTF-8") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror or exc}") from None
    for key, value in (overrides or {}).items():
        apply(data, key, value)
    if "physics" not in data:
        hint = ' (a [transfer] table: effects = ["transfer"])' if "transfer" in data else ""
        raise SceneError(f"{path}: [physics] effects: missing: the effects the scene simulates{hint}")
    from .coupled import parse

    return parse(path, case_dir, data, output)
