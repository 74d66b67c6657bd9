"""``[check]`` with expressions: the displacement a known solution gives, compared at the
solid's vertices."""

from __future__ import annotations

import numpy as np

from coupler.errors import CouplerError
from coupler.protocol.expressions import evaluate_expression


def check_displacement(check: dict, points: np.ndarray, u: np.ndarray) -> dict:
    """Compare the displacement with the scene's expected one ([check]): the largest
    error over the selected vertices relative to the largest expected value."""
    selected = np.ones(len(points), bool)
    if "where" in check:
        selected = evaluate_expression(check["where"], points) > 0.5
    if not selected.any():
        raise CouplerError(f"[check] where: {check['where']!r} selects no vertex of the solid")
    error = scale = 0.0
    for axis, c in enumerate("xyz"):
        if c in check:
            exact = evaluate_expression(check[c], points[selected])
            error = max(error, float(np.max(np.abs(u[selected, axis] - exact))))
            scale = max(scale, float(np.max(np.abs(exact))))
    relative = error / scale if scale > 0 else error
    return {"error": relative, "absolute_error": error, "tolerance": check["tolerance"],
            "passed": bool(relative <= check["tolerance"]), "vertices": int(selected.sum())}
