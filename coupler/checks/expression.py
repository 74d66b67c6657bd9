"""``[check] kind = "expression"`` (the default): the solid's displacement against a known
one written as expressions in x, y, z, compared at the solid's vertices. :func:`compare` is
the comparison every displacement check shares (``uniaxial``, ``sneddon``): maxima and a count
over the rows held here, combined over a coupler's ranks."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums
from coupler.errors import CouplerError
from coupler.protocol.expressions import check_expression, evaluate_expression

KIND = "expression"
DISTRIBUTED = True
DESCRIPTION = "the solid's displacement against expressions in x, y, z"
KEYS = {"x": "expected x displacement (expression in x, y, z)", "y": "expected y displacement",
        "z": "expected z displacement", "where": "expression selecting the vertices compared (default all)",
        "tolerance": "largest relative error accepted"}


def parse(table, scene) -> dict:
    settings = {c: table.string(c) for c in ("x", "y", "z", "where") if c in table.data}
    for key, expression in settings.items():
        check_expression(expression, table.where(key))
    if not set(settings) & {"x", "y", "z"}:
        raise table.error("z", "give the expected displacement of at least one component (x, y or z)")
    settings["tolerance"] = table.number("tolerance", positive=True)
    return settings


def compare(points: np.ndarray, u: np.ndarray, exact: dict, selected: np.ndarray, tolerance: float,
            where: str, sums=None) -> dict:
    """The largest error of the displacement `u` over the `selected` vertices relative to the
    largest expected value; `exact` maps an axis (0, 1, 2) to ``f(points) -> expected values``;
    `where` names the selection in the error when it selects nothing. `sums` (a
    :class:`coupler.coupling.row_sums.RowSums`; None: these rows are all) combines the maxima
    and the count over the ranks' rows."""
    sums = sums or RowSums()
    vertices = int(round(sums.sum(float(np.count_nonzero(selected)))))
    if vertices == 0:
        raise CouplerError(f"{where} selects no vertex of the solid")
    error = scale = 0.0
    for axis, f in exact.items():
        expected = f(points[selected])
        error = max(error, float(np.max(np.abs(u[selected, axis] - expected), initial=0.0)))
        scale = max(scale, float(np.max(np.abs(expected), initial=0.0)))
    error, scale = sums.extremum(np.array([error, scale]), "max")
    relative = error / scale if scale > 0 else error
    return {"error": float(relative), "absolute_error": float(error), "tolerance": tolerance,
            "passed": bool(relative <= tolerance), "vertices": vertices}


def evaluate(settings, scene, result) -> dict:
    points, fields = result.rows("solid")
    selected = np.ones(len(points), bool)
    if "where" in settings:
        selected = evaluate_expression(settings["where"], points) > 0.5
    exact = {axis: (lambda p, text=settings[c]: evaluate_expression(text, p))
             for axis, c in enumerate("xyz") if c in settings}
    return compare(points, fields["displacement"], exact, selected, settings["tolerance"],
                   f"{scene.path}: [check] where: {settings.get('where')!r}", result.sums)


def describe(report: dict) -> str:
    return f"displacement error {report['error']:.3e} relative on {report['vertices']} vertices"
