"""Scene keys set from the command line (``varcouple study --vary KEY=VALUES``): a dotted key
(``geometry.fluid.shape``, ``coupling.acceleration``, ``loads.3.value`` for the third
``[[loads]]``) given a value in the scene's TOML data before the scene is validated, so an
override is checked like any key of the file."""

from __future__ import annotations

import tomllib

from coupler.errors import SceneError


def parse_vary(text: str) -> tuple[str, list]:
    """``KEY=VALUES`` -> (KEY, the values): VALUES is a TOML array, e.g. ``[[21, 11, 7], [21, 11, 11]]``
    or ``["aitken", "iqn-ils"]``."""
    key, sep, values = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise SceneError(f"--vary {text!r}: give KEY=VALUES, KEY a dotted scene key (e.g. coupling.acceleration) "
                         f"and VALUES a TOML array (e.g. [\"aitken\", \"iqn-ils\"])")
    try:
        parsed = tomllib.loads(f"values = {values.strip()}")["values"]
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"--vary {key}: {values.strip()!r} is not a TOML value: {exc}") from None
    if not isinstance(parsed, list) or not parsed:
        raise SceneError(f"--vary {key}: give the values as a non-empty TOML array, e.g. {key}=[1, 2]; got "
                         f"{values.strip()!r}")
    return key, parsed


def apply(data: dict, key: str, value) -> None:
    """Set the dotted `key` of the scene's TOML `data` to `value` (tables created as needed; a
    number after an array of tables is its 1-based entry, as in ``[loads.3]``)."""
    parts = key.split(".")
    node, seen = data, []
    for part in parts[:-1]:
        seen.append(part)
        if isinstance(node, list):
            node = _entry(node, part, key, '.'.join(seen[:-1]))
        elif isinstance(node, dict):
            node = node.setdefault(part, {})
        if not isinstance(node, (dict, list)):
            raise SceneError(f"--vary {key}: {'.'.join(seen)} is a value ({node!r}), not a table")
    if isinstance(node, list):
        raise SceneError(f"--vary {key}: {'.'.join(seen)} is an array of tables: name an entry and its key, "
                         f"e.g. {'.'.join(seen)}.1.{parts[-1]}")
    node[parts[-1]] = value


def _entry(tables: list, part: str, key: str, where: str) -> dict:
    if not part.isdigit() or not 1 <= int(part) <= len(tables):
        raise SceneError(f"--vary {key}: [{where}] has entries 1 to {len(tables)}, got {part!r}")
    return tables[int(part) - 1]
