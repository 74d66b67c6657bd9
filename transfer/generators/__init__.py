"""Case geometry made from parameters: one module per generator, found by :data:`GENERATORS`.

A scene names one in ``[geometry.solid] generator = "NAME"`` with its ``[geometry.solid.parameters]``.
A generator module defines ``NAME``, ``DESCRIPTION``, ``PARAMETERS`` (``{name: description}``,
every key it takes), ``DEFAULTS`` (the optional ones' values), ``check(parameters) -> dict``
(types and ranges; ``ValueError("<key>: <reason>")``), ``mesh(parameters) -> Mesh`` (the solid)
and, for geometry made for a fluid grid (an immersed-boundary study), ``grid(parameters) ->
{"origin", "spacing", "shape"}``.
"""

from __future__ import annotations

import importlib
import pkgutil


def _discover() -> dict:
    modules = [importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__)]
    return {m.NAME: m for m in sorted(modules, key=lambda m: m.NAME)}


def parameters(name: str, values: dict) -> dict:
    """The complete, checked parameters of generator `name` (defaults filled in);
    ``ValueError("<key>: <reason>")`` for an unknown, missing or bad one."""
    module = GENERATORS[name]
    for key in values:
        if key not in module.PARAMETERS:
            raise ValueError(f"{key}: unknown parameter of generator {name!r}; known: {', '.join(module.PARAMETERS)}")
    for key, description in module.PARAMETERS.items():
        if key not in values and key not in module.DEFAULTS:
            raise ValueError(f"{key}: missing ({description})")
    return module.check({**module.DEFAULTS, **values})


def number(parameters: dict, key: str, minimum: float | None = None, below: float | None = None,
           positive: bool = False, integer: bool = False):
    """``parameters[key]`` checked: a number (an integer with `integer`), > 0 with `positive`, in
    [minimum, below)."""
    value = parameters[key]
    kinds = (int,) if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kinds) or value != value or abs(value) == float("inf"):
        raise ValueError(f"{key}: must be {'an integer' if integer else 'a finite number'}, got {value!r}")
    if positive and not value > 0:
        raise ValueError(f"{key}: must be positive, got {value!r}")
    if minimum is not None and value < minimum or below is not None and value >= below:
        raise ValueError(f"{key}: must lie in [{minimum}, {below if below is not None else 'inf'}), got {value!r}")
    return value if integer else float(value)


#: generator name -> its module (last: the generators use the helpers above)
GENERATORS = _discover()
