"""``[check] kind = "lubrication"``: the hydraulic aperture of a run through a sinusoidal
aperture e(s) = e0 (1 + a sin(2 pi s / lambda)) against its lubrication limits (long
wavelength: the local cubic law everywhere).

The run's hydraulic aperture is e_h = (12 mu Q L / (W dp))^(1/3) (the cubic law solved for the
gap, :func:`coupler.fsi.apertures.hydraulic_aperture`), Q the volume flow rate through the
grid's sections x = const averaged along x, L and W the grid's length (x) and width (y). Over
whole periods the limits are, with the means over one period,

- along the flow (apertures in series): e_h^3 = 1 / mean(1 / e^3) = e0^3 (1 - a^2)^(5/2) / (1 + a^2 / 2),
- across the flow (in parallel): e_h^3 = mean(e^3) = e0^3 (1 + 3 a^2 / 2).

On a coupler of P ranks (``DISTRIBUTED``) Q is summed from each rank's slab of the grid, as
``cubic_law``'s.
"""

from __future__ import annotations

from coupler.fsi.apertures import hydraulic_aperture
from coupler.fsi.flow_rate import section_flow_rates

from .cubic_law import found_pressure_drop, pressure_drop

KIND = "lubrication"
DISTRIBUTED = True
DESCRIPTION = "the hydraulic aperture through a sinusoidal aperture against its lubrication limit (series or parallel)"
KEYS = {"aperture": "e0, the mean aperture [m] (default: the [geometry.solid] generator wavy_plates' aperture)",
        "amplitude": "a, the relative amplitude (default: the generator's)",
        "direction": "'along' (the aperture varies along the flow: series) or 'across' (parallel) "
                     "(default: the generator's)",
        "tolerance": "largest accepted |e_h / e_h,limit - 1|"}
GENERATOR = "wavy_plates"


def series_limit(e0: float, a: float) -> float:
    """e_h of e0 (1 + a sin) along the flow: (1 / mean(1 / e^3))^(1/3)."""
    return e0 * ((1.0 - a * a) ** 2.5 / (1.0 + a * a / 2.0)) ** (1.0 / 3.0)


def parallel_limit(e0: float, a: float) -> float:
    """e_h of e0 (1 + a sin) across the flow: mean(e^3)^(1/3)."""
    return e0 * (1.0 + 1.5 * a * a) ** (1.0 / 3.0)


def parse(table, scene) -> dict:
    dp = pressure_drop(table, scene, KIND)
    made = scene.solid.generator or {}
    generated = made.get("parameters", {}) if made.get("name") == GENERATOR else {}
    for key in ("aperture", "amplitude", "direction"):
        if key not in table.data and key not in generated:
            raise table.error(key, f"missing: {KEYS[key].split(' (')[0]} (the solid is not made by the generator "
                                   f"{GENERATOR!r})")
    amplitude = table.number("amplitude", generated.get("amplitude"), minimum=0.0)
    if not amplitude < 1:
        raise table.error("amplitude", f"must be below 1 (the aperture would close), got {amplitude!r}")
    g = scene.fluid
    return {"aperture": table.number("aperture", generated.get("aperture"), positive=True), "amplitude": amplitude,
            "direction": table.string("direction", generated.get("direction"), ("along", "across")),
            "tolerance": table.number("tolerance", positive=True), "pressure_drop": dp,
            "viscosity": scene.fluid_material["viscosity"],
            "length": g.spacing[0] * g.shape[0], "width": g.spacing[1] * g.shape[1]}


def evaluate(settings, scene, result) -> dict:
    e0, a = settings["aperture"], settings["amplitude"]
    grid, block = result.grid("fluid")
    rate = float(section_flow_rates(grid, result.fields["fluid"]["velocity"], block, result.comm).mean())
    e_h = hydraulic_aperture(rate, settings["viscosity"], settings["length"], settings["width"],
                             found_pressure_drop(settings, scene, result))
    series, parallel = series_limit(e0, a), parallel_limit(e0, a)
    limit = series if settings["direction"] == "along" else parallel
    difference = e_h / limit - 1.0
    return {"error": abs(difference), "tolerance": settings["tolerance"],
            "passed": bool(abs(difference) <= settings["tolerance"]), "relative_difference": difference,
            "flow_rate_difference": (e_h / limit) ** 3 - 1.0, "hydraulic_aperture": e_h, "limit": limit,
            "series_limit": series, "parallel_limit": parallel, "direction": settings["direction"],
            "flow_rate": rate, "aperture": e0, "amplitude": a}


def describe(report: dict) -> str:
    which = "series" if report["direction"] == "along" else "parallel"
    return (f"hydraulic aperture {1e6 * report['hydraulic_aperture']:.4g} um against the {which} lubrication "
            f"limit's {1e6 * report['limit']:.4g} um: {report['relative_difference']:+.3%} (flow rate "
            f"{report['flow_rate_difference']:+.3%})")
