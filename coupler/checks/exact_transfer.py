"""``[check] kind = "exact_transfer"``: the fields a ``transfer`` scene carried (one target per
method) against the source field's known expression f (paper 2.1): per method the true L2
error ``||u_h - f|| / ||f||`` by quadrature over the target cells whose dofs are all covered
(:meth:`transfer.FunctionSpace.l2_squares`), the distance to the interpolant of f,
``||u_h - I_h f||_M / ||I_h f||_M`` with the mass matrix M over the covered dofs (zero when the
transfer returns the interpolant, whose own L2 error is not zero), and the largest error at the
covered dofs. The check passes when every method's L2 error is within the tolerance.

On a coupler of P ranks (``DISTRIBUTED``) each rank has its pieces of the meshes: the squared norms are
sums over its own cells (the mass matrix of its cells), the largest errors its own; one allreduce
of each makes the whole's, then the roots and ratios (:class:`coupler.coupling.row_sums.RowSums`:
on one process the plain sums).
"""

from __future__ import annotations

import math

import numpy as np

from coupler.coupling.row_sums import RowSums
from coupler.errors import CouplerError
from coupler.protocol.expressions import check_expression, evaluate_expression
from transfer import FunctionSpace
from transfer.meshfile import family

KIND = "exact_transfer"
DISTRIBUTED = True
DESCRIPTION = "a transferred field against its known expression: L2 error and distance to the interpolant"
KEYS = {"exact": "the source field as an expression in x, y, z (numpy; scalar fields)",
        "tolerance": "largest accepted relative L2 error of a method"}
#: exact differs from the source field at its dofs by more than this (relative): a note in the log
SOURCE_MISMATCH = 1e-6


def parse(table, scene) -> dict:
    if "transfer" not in scene.effects:
        raise table.error("kind", f"'exact_transfer' compares a transfer: needs the effect 'transfer', got "
                                  f"{scene.effects!r}")
    s = scene.effect_settings["transfer"]
    exact = table.string("exact")
    check_expression(exact, table.where("exact"))
    if s["shape"]:
        raise table.error("exact", f"is a scalar expression but field {s['field']!r} has shape {tuple(s['shape'])} "
                                   f"per {s['kind']}")
    try:
        at_source = evaluate_expression(exact, s["source_dofs"])
    except Exception as exc:  # noqa: BLE001 - e.g. sin(x, y): TypeError from numpy
        raise table.error("exact", f"cannot evaluate {exact!r}: {' '.join(str(exc).split())}") from None
    if not np.all(np.isfinite(at_source)):
        raise table.error("exact", f"{exact!r} is not finite at every source {s['kind']} (e.g. log or sqrt of a "
                                   f"negative number)")
    return {"exact": exact, "tolerance": table.number("tolerance", positive=True)}


def _relative(squares: float, of: float) -> float:
    """sqrt(squares / of): the ratio of two norms from their squares."""
    return math.sqrt(max(squares, 0.0)) / math.sqrt(of) if of > 0 else float("nan")


def _largest(sums: RowSums, values: np.ndarray) -> float:
    """max |values| over every rank's (NaN when no rank has any)."""
    largest = sums.extremum(float(np.max(np.abs(values))) if values.size else -math.inf, "max")
    return largest if math.isfinite(largest) else float("nan")


def errors(space: FunctionSpace, values: np.ndarray, f, sums: RowSums) -> dict:
    """The errors of the transferred dof `values` (NaN where not covered) against `f`, over the
    cells of `space` and every other rank's of `sums`. Collective."""
    covered = np.isfinite(values)
    interpolant = f(space.dof_coordinates)
    e, at_dofs = np.where(covered, values - interpolant, 0.0), np.where(covered, interpolant, 0.0)
    mass = space.mass_matrix()
    l2 = space.l2_squares(np.where(covered, values, 0.0), f, cells=covered[space.cell_dofs].all(axis=1))
    error, norm, distance, scale = sums.sum(np.array([*l2, e @ (mass @ e), at_dofs @ (mass @ at_dofs)]))
    return {"max_error": _largest(sums, e[covered]), "relative_l2_error": _relative(error, norm),
            "relative_interpolant_distance": _relative(distance, scale)}


def evaluate(settings, scene, result) -> dict:
    s = scene.effect_settings["transfer"]

    def f(points):
        return evaluate_expression(settings["exact"], points)

    sums = RowSums(result.comm)
    source = result.meshes["source"]
    source_values = np.asarray(result.fields["source"][s["field"]], float)
    at_source = f(FunctionSpace(source, family(source, s["kind"])).dof_coordinates)
    methods = {}
    for method in s["methods"]:
        mesh = result.meshes[f"target_{method}"]
        values = np.asarray(result.fields[f"target_{method}"][s["field"]], float)
        methods[method] = errors(FunctionSpace(mesh, family(mesh, s["kind"])), values, f, sums)
    worst = max(m["relative_l2_error"] for m in methods.values())
    if not math.isfinite(worst):
        raise CouplerError(f"{scene.path}: [check] exact: no target cell is covered: no L2 error to compare")
    scale = max(_largest(sums, source_values), np.finfo(float).tiny)
    return {"error": worst, "tolerance": settings["tolerance"], "passed": bool(worst <= settings["tolerance"]),
            "exact": settings["exact"], "source_max_difference": _largest(sums, at_source - source_values),
            "source_scale": scale, "methods": methods}


def describe(report: dict) -> str:
    methods = "; ".join(f"{m} L2 error {r['relative_l2_error']:.3e} (distance to the interpolant "
                        f"{r['relative_interpolant_distance']:.3e}, largest at the dofs {r['max_error']:.3e})"
                        for m, r in report["methods"].items())
    note = ""
    if report["source_max_difference"] > SOURCE_MISMATCH * report["source_scale"]:
        note = (f"; note: exact differs from the source field at its dofs by up to "
                f"{report['source_max_difference']:.3g}: the errors are against exact, not the source field")
    return f"transfer against exact: {methods}{note}"
