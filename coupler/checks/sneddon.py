"""``[check] kind = "sneddon"``: a penny-shaped crack of radius a in an infinite solid under a
uniform pressure p opens by w(r) = 8 (1 - nu^2) p a / (pi E) sqrt(1 - r^2/a^2) (Sneddon); the
face of a model above the crack plane z = z_c moves by u_z = w / 2. Compared at the vertices
of the crack plane within a fraction of the radius (the P1 error grows toward the tip's
singularity). E, nu and p (the scene's single pressure load) come from the scene."""

from __future__ import annotations

import numpy as np

from coupler.checks.expression import compare

KIND = "sneddon"
DESCRIPTION = "a penny crack under pressure: the opening against Sneddon's solution"
DISTRIBUTED = True
KEYS = {"radius": "the crack's radius a [m]", "centre": "the crack's centre (default [0, 0, 0]); the crack "
                                                        "lies in the plane z = centre's z",
        "compared": "the vertices of the crack plane within this fraction of a are compared (default 0.8)",
        "tolerance": "largest relative error accepted: max over the compared vertices, relative to the largest "
                     "expected value"}
PRESSURES = ("fluid_pressure", "pressure")


def parse(table, scene) -> dict:
    loads = [load for load in scene.loads if load.type in PRESSURES]
    if len(loads) != 1:
        raise table.error("kind", f"'sneddon' needs exactly one pressure load (one of {', '.join(PRESSURES)}) on "
                                  f"the crack's faces; the scene has {len(loads)}")
    return {"radius": table.number("radius", positive=True), "centre": table.vector("centre", [0.0, 0.0, 0.0]),
            "compared": table.number("compared", 0.8, positive=True, maximum=1.0),
            "pressure": float(loads[0].value), "tolerance": table.number("tolerance", positive=True)}


def evaluate(settings, scene, result) -> dict:
    E, nu, p, a = scene.material["E"], scene.material["nu"], settings["pressure"], settings["radius"]
    points, fields = result.rows("solid")
    d = points - np.asarray(settings["centre"])
    r2 = d[:, 0] ** 2 + d[:, 1] ** 2
    selected = (np.abs(d[:, 2]) < 1e-8 * a) & (r2 <= (settings["compared"] * a) ** 2)
    opening = 8 * (1 - nu**2) * p * a / (np.pi * E)

    def half_opening(x):
        s = (x[:, 0] - settings["centre"][0]) ** 2 + (x[:, 1] - settings["centre"][1]) ** 2
        return 0.5 * opening * np.sqrt(np.clip(1 - s / a**2, 0, 1))

    report = compare(points, fields["displacement"], {2: half_opening}, selected,
                     settings["tolerance"], f"{scene.path}: [check] radius {a:g}, centre {settings['centre']}: "
                                            f"the crack plane within {settings['compared']:g} a", result.sums)
    return {**report, "opening_centre": opening}


def describe(report: dict) -> str:
    return (f"Sneddon opening {report['opening_centre']:.4g} m at the centre: face displacement error "
            f"{report['error']:.3e} relative on {report['vertices']} vertices")
