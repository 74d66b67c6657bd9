"""``[check] kind = "expression"`` (the default): the solid's displacement against a known
one written as expressions in x, y, z, compared at the solid's vertices. :func:`compare` is
the comparison every displacement check shares (``uniaxial``, ``sneddon``)."""

from __future__ import annotations

import numpy as np

from coupler.errors import CouplerError
from coupler.protocol.expressions import check_expression, evaluate_expression

KIND = "expression"
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
            where: str) -> dict:
    """The largest error of the displacement `u` over the `selected` vertices relative to the
    largest expected value; `exact` maps an axis (0, 1, 2) to ``f(points) -> expected values``;
    `where` names the selection in the error when it selects nothing."""
    if not selected.any():
        raise CouplerError(f"{where} selects no vertex of the solid")
    error = scale = 0.0
    for axis, f in exact.items():
        expected = f(points[selected])
        error = max(error, float(np.max(np.abs(u[selected, axis] - expected))))
        scale = max(scale, float(np.max(np.abs(expected))))
    relative = error / scale if scale > 0 else error
    return {"error": relative, "absolute_error": error, "tolerance": tolerance,
            "passed": bool(relative <= tolerance), "vertices": int(selected.sum())}


def evaluate(settings, scene, result) -> dict:
    points = result.meshes["solid"].points
    selected = np.ones(len(points), bool)
    if "where" in settings:
        selected = evaluate_expression(settings["where"], points) > 0.5
    exact = {axis: (lambda p, text=settings[c]: evaluate_expression(text, p))
             for axis, c in enumerate("xyz") if c in settings}
    return compare(points, result.fields["solid"]["displacement"], exact, selected, settings["tolerance"],
                   f"{scene.path}: [check] where: {settings.get('where')!r}")


def describe(report: dict) -> str:
    return f"displacement error {report['error']:.3e} relative on {report['vertices']} vertices"
