"""Comparisons of a run's final result with known solutions: the scene's ``[check]``.

Each kind is one module of this package (``[check] kind = "NAME"``, default
``expression``), found by :data:`KINDS`. A kind module defines

- ``KIND``: its name, and ``DESCRIPTION``: one line on what it compares;
- ``KEYS``: ``{key: description}`` of its ``[check]`` keys (``kind`` is common to all);
- ``parse(table, scene) -> dict``: its settings, read from ``table`` (a
  :class:`coupler.scene.tables.Table` of ``[check]`` whose keys are already checked
  against ``KEYS``) with the scene's own parameters (materials, loads, geometry, effect
  settings) taken from ``scene``, validated when the scene is read;
- ``evaluate(settings, scene, result) -> dict``: the comparison with at least ``error`` (the
  figure compared with the tolerance), ``tolerance`` and ``passed``, plus its own figures;
  ``result`` is a :class:`Result`;
- ``describe(report) -> str``: the comparison as one line for the log;
- ``DISTRIBUTED = True`` when ``evaluate`` makes every figure of local sums, maxima and minima
  combined by ``Result.sums`` (:class:`coupler.coupling.row_sums.RowSums`) over the rows a rank
  counts (``Result.rows``) or the cells of its pieces (``Result.meshes``, ``Result.fields``; a
  grid's piece is a block of it, ``Result.grid``):
  such a kind also runs on a coupler of several ranks (docs/scaling.md, step 3); the others
  compare whole meshes on one process and are refused there.

summary.json's ``check`` is ``{"kind": KIND, **evaluate(...)}``; a run whose check did not
pass exits 1.
"""

from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass, field

from coupler.coupling.row_sums import RowSums
from coupler.errors import SceneError
from coupler.scene.tables import Table

DEFAULT = "expression"


def _discover() -> dict:
    modules = [importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__)]
    return {m.KIND: m for m in sorted(modules, key=lambda m: m.KIND)}


#: check kind -> its module
KINDS = _discover()


@dataclass
class Result:
    """What a check compares: per participant its mesh (or grid), its final fields (outputs and
    the inputs it got, at the vertices of a mesh or the cells of a grid) and its figures of the
    last step.

    On a coupler of several ranks (`comm`) ``meshes`` and ``fields`` are this rank's pieces (each
    cell in one piece, a vertex on a cut in several: sums over cells add up), ``held`` the rows
    each rank counts once (a participant's vertices or cells held here, disjoint over the ranks:
    their coordinates and fields), which :meth:`rows` gives, and ``grids`` each grid's whole grid
    and the block of its cells this rank's piece is, which :meth:`grid` gives; on one process
    (`comm` None) these are the whole mesh."""

    meshes: dict
    fields: dict
    figures: dict = field(default_factory=dict)
    comm: object = None
    held: dict = field(default_factory=dict)
    grids: dict = field(default_factory=dict)

    def rows(self, name: str) -> tuple:
        """(points, fields) of the rows of participant `name` that this rank counts (module doc)."""
        return self.held[name] if name in self.held else (self.meshes[name].points, self.fields[name])

    def grid(self, name: str) -> tuple:
        """(grid, block) of grid participant `name`: the whole grid and this rank's piece of it,
        ``(lower, upper)`` cell indices (None: the whole grid, on one process)."""
        return self.grids[name] if name in self.grids else (self.meshes[name], None)

    @property
    def sums(self) -> RowSums:
        """Sums, maxima and minima over the ranks' rows (this process's own on one process)."""
        return RowSums(self.comm)


def parse(path, data, scene) -> dict:
    """The settings of ``[check]`` (`data`, the table as read from TOML) for `scene`:
    ``{"kind": KIND, **settings}``."""
    if not isinstance(data, dict):
        raise SceneError(f"{path}: [check] must be a table, got {data!r}")
    kind = Table(path, "check", {k: v for k, v in data.items() if k == "kind"}, {"kind": ""}).string(
        "kind", DEFAULT, tuple(KINDS))
    module = KINDS[kind]
    table = Table(path, "check", data, {"kind": f"one of {', '.join(KINDS)}", **module.KEYS})
    return {"kind": kind, **module.parse(table, scene)}


def evaluate(scene, result: Result) -> dict:
    """The scene's check of `result`: ``{"kind": ..., "error": ..., "tolerance": ..., "passed": ..., ...}``."""
    settings = dict(scene.check)
    kind = settings.pop("kind")
    return {"kind": kind, **KINDS[kind].evaluate(settings, scene, result)}


def describe(report: dict) -> str:
    """A check's report (:func:`evaluate`) as one line."""
    verdict = "PASS" if report["passed"] else "FAIL"
    return f"check: {KINDS[report['kind']].describe(report)} (tolerance {report['tolerance']:g}): {verdict}"
