"""Case geometry made from parameters: one module per generator, found by :data:`GENERATORS`.

A scene names one in ``[geometry.solid] generator = "NAME"`` with its ``[geometry.solid.parameters]``;
the solid participant makes on each rank only that rank's cells and points when the generator
describes its mesh by index (``lattices``), else runs it on rank 0; cases that ship a mesh file
make it with the same generator (their ``make_mesh.py``). A generator module defines ``NAME``, ``DESCRIPTION``,
``PARAMETERS`` (``{name: description}``, every key it takes), ``DEFAULTS`` (the optional ones'
values), ``check(parameters) -> dict`` (types and ranges; ``ValueError("<key>: <reason>")``),
``mesh(parameters)`` (the solid: a :class:`~transfer.generators.blocks.Block`, tetrahedra with
named boundary faces), ``FACES`` (``{name: tag}`` of the faces every mesh it makes carries)
and, optionally, ``FILES`` (the parameters that name files: the scene gives them relative to the
case directory and resolves them), ``cells(parameters)`` (the number of tetrahedra without
building the mesh), ``notes(parameters)`` (what it did to its input that the user should know,
e.g. a map's remainder cell: lines for the plan and the run's summary), ``lattices(parameters)`` (the mesh by index,
:class:`~transfer.generators.lattices.Lattices`: any block of cells or points made alone; None for
parameters that make a mesh that is not a lattice, e.g. graded blocks) and,
for geometry made for a fluid grid (an immersed-boundary study), ``grid(parameters) ->
{"origin", "spacing", "shape"}``.

- ``rough_fracture``: two rock blocks around a matched rough fracture (small_fracture, fracture_flow)
- ``fracture_specimen``: the closure specimen, box or cylinder, non-matching fracture faces (paper 4.1)
- ``measured_fracture``: two blocks around a measured fracture, the faces from height maps (.npz or
  XYZ files named relative to the case directory: the parameters in the module's ``FILES``)
- ``rough_block``: a block with a flat top and a rough bottom face (rock_obstacle, paper figure 15)
- ``hertz``: a half-sphere on a block, gmsh (paper figure 5)
- ``penny_crack``: the quarter model of a penny-shaped crack (pressurized_fracture)
- ``plates``: two flat blocks with a gap and the 2D fluid grid made for them (parallel_plates)
- ``wavy_plates``: two blocks with a sinusoidal aperture and the fluid grid made for them (lubrication)

The modules without ``NAME`` are their building blocks: :mod:`.surfaces` (self-affine rough
surfaces), :mod:`.blocks` (:class:`~transfer.generators.blocks.Block`, the blocks around a
fracture), :mod:`.lattice` (graded lattices), :mod:`.graded` (blocks graded away from a fracture face,
coarsened in-plane with depth), :mod:`.height_maps` (height map files).
"""

from __future__ import annotations

import importlib
import pkgutil


def _discover() -> dict:
    modules = [importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__)]
    return {m.NAME: m for m in sorted(modules, key=lambda m: m.__name__) if hasattr(m, "NAME")}


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


def generate(name: str, values: dict | None = None):
    """The mesh of generator `name` with `values` (checked, defaults filled in)."""
    return GENERATORS[name].mesh(parameters(name, dict(values or {})))


def lattices_of(name: str, values: dict | None = None):
    """The :class:`~transfer.generators.lattices.Lattices` of generator `name` with `values` (its mesh by
    index, nothing built), or None for a generator that only builds whole meshes."""
    module = GENERATORS[name]
    return module.lattices(parameters(name, dict(values or {}))) if hasattr(module, "lattices") else None


def cells(name: str, values: dict) -> int:
    """How many tetrahedra generator `name` makes with `values` (built only without a formula)."""
    module, checked = GENERATORS[name], parameters(name, values)
    return int(module.cells(checked)) if hasattr(module, "cells") else len(module.mesh(checked).cells)


def notes(name: str, values: dict) -> list[str]:
    """What generator `name` did to its input with `values` that the user should know (none
    without a ``notes`` of its module)."""
    module = GENERATORS[name]
    return list(module.notes(parameters(name, values))) if hasattr(module, "notes") else []


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


def numbers(parameters: dict, key: str, count: int, positive: bool = False, integer: bool = False) -> list:
    """``parameters[key]`` checked: a list of `count` numbers (integers with `integer`), > 0 with `positive`."""
    value = parameters[key]
    if not isinstance(value, (list, tuple)) or len(value) != count:
        raise ValueError(f"{key}: must be a list of {count} {'integers' if integer else 'numbers'}, got {value!r}")
    return [number({key: v}, key, positive=positive, integer=integer) for v in value]


def choice(parameters: dict, key: str, choices: tuple) -> str:
    """``parameters[key]`` checked: one of `choices`."""
    value = parameters[key]
    if value not in choices:
        raise ValueError(f"{key}: must be one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


#: generator name -> its module (last: the generators use the helpers above)
GENERATORS = _discover()
