"""``[check] kind = "cubic_law"``: the flow rate through a gap of aperture w against the cubic
law ``Q = w^3 dp / (12 mu L)`` (plane Poiseuille flow, per unit width), with dp the pressure
drop from the inlet (xmin) to the outlet (xmax), L the grid's length along x and mu the
fluid's viscosity, all from the scene.

The flow rate is measured through every cross-section of the grid (a column of cells at one x,
per unit width: the cells' x velocity times their height across the aperture, summed across
and averaged over the width) and averaged along x; their spread tells how well the discrete
flow conserves mass.

On a coupler of P ranks (``DISTRIBUTED``) each rank sums the cells of its slab of the grid into
the sections (:func:`coupler.fsi.flow_rate.section_flow_rates` with its block and ``comm``: one
allreduce of nx numbers), and every rank has the whole grid's flow rates.
"""

from __future__ import annotations

import numpy as np

from coupler.fsi.flow_rate import section_flow_rates

KIND = "cubic_law"
DISTRIBUTED = True
DESCRIPTION = "the flow rate through a gap against the cubic law w^3 dp / (12 mu L)"
KEYS = {"aperture": "w, the gap [m] (default: the aperture parameter of the [geometry.solid] generator)",
        "across": "the grid axis across the gap, 'y' (default) or 'z'; the other one is the width",
        "tolerance": "largest accepted |Q / Q_cubic - 1|"}


def pressure_drop(table, scene, kind: str) -> float | None:
    """dp = inlet - outlet pressure of the scene's flow, which check `kind` compares with (None
    for a flow driven by [flow] flow_rate: the dp the run finds, :func:`found_pressure_drop`);
    one line naming ``[check] kind`` when there is no flow or no positive pressure drop."""
    if "flow" not in scene.effects:
        raise table.error("kind", f"{kind!r} compares a flow: needs the effect 'flow', got {scene.effects!r}")
    inlet, outlet = scene.flow["inlet"], scene.flow["outlet"]
    if "flow_rate" in inlet:
        return None
    if "pressure" not in inlet:
        raise table.error("kind", f"{kind!r} needs the pressure drop: give [flow] inlet_pressure or flow_rate")
    dp = inlet["pressure"] - outlet["pressure"]
    if not dp > 0:
        raise table.error("kind", f"{kind!r} needs a pressure drop: [flow] inlet_pressure - outlet_pressure is "
                                  f"{dp:g} Pa")
    return dp


def found_pressure_drop(settings, scene, result) -> float:
    """The check's dp: the scene's, or for a flow rate the one the run found (the fluid's last
    ``inlet_pressure`` input minus the outlet pressure)."""
    if settings["pressure_drop"] is not None:
        return settings["pressure_drop"]
    return float(np.ravel(result.fields["fluid"]["inlet_pressure"])[0]) - scene.flow["outlet"]["pressure"]


def parse(table, scene) -> dict:
    dp = pressure_drop(table, scene, KIND)
    generated = (scene.solid.generator or {}).get("parameters", {})
    if "aperture" not in table.data and "aperture" not in generated:
        raise table.error("aperture", "missing: the gap w [m] (no generator of [geometry.solid] gives one)")
    g = scene.fluid
    return {"aperture": table.number("aperture", generated.get("aperture"), positive=True),
            "across": table.string("across", "y", ("y", "z")), "tolerance": table.number("tolerance", positive=True),
            "pressure_drop": dp, "viscosity": scene.fluid_material["viscosity"], "length": g.spacing[0] * g.shape[0]}


def flow_rates(grid, velocity: np.ndarray, across: int, block=None, comm=None) -> np.ndarray:
    """The flow rate per unit width through each cross-section x = const of `grid` (one per
    column of cells along x) [m^2/s]; `across`: the axis (1 or 2) across the gap, the other
    one (2 or 1) is the width; `velocity` at the cells of `block` (the whole grid when None),
    summed over the ranks of `comm` (:func:`coupler.fsi.flow_rate.section_flow_rates`)."""
    width = 3 - across
    return section_flow_rates(grid, velocity, block, comm) / (grid.spacing[width] * grid.shape[width])


def evaluate(settings, scene, result) -> dict:
    across = "xyz".index(settings["across"])
    grid, block = result.grid("fluid")
    Q = flow_rates(grid, result.fields["fluid"]["velocity"], across, block, result.comm)
    w, dp, mu, L = (settings["aperture"], found_pressure_drop(settings, scene, result), settings["viscosity"],
                    settings["length"])
    q_cubic = w ** 3 * dp / (12 * mu * L)
    difference = float(Q.mean() / q_cubic - 1)
    return {"error": abs(difference), "tolerance": settings["tolerance"],
            "passed": bool(abs(difference) <= settings["tolerance"]), "relative_difference": difference,
            "Q": float(Q.mean()), "Q_cubic": q_cubic, "Q_spread": float(np.ptp(Q) / abs(Q.mean())),
            "aperture": w, "pressure_drop": dp, "viscosity": mu, "length": L}


def describe(report: dict) -> str:
    return (f"flow rate {report['Q']:.5g} m^2/s against the cubic law's {report['Q_cubic']:.5g}: "
            f"{report['relative_difference']:+.3%}")
