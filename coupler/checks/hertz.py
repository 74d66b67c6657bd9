"""``[check] kind = "hertz"``: a sphere of radius R pressed onto a half-space of the same
material (paper 4.1, figure 5). Hertz theory for the normal contact force F gives the contact
radius a = (3 F R / (4 E*))^(1/3) and the peak pressure p0 = 3 F / (2 pi a^2), with
E* = E / (2 (1 - nu^2)). The run's a and p0 come from the solid's contact fields on the slave
face (``contact_pressure``, ``mortar_weight``, ``slave``, ``in_contact``): F = sum(p w) (the
dual basis of eq. 9 makes the weights the face's lumped areas), and a, p0 from the elliptic
fit p^2 = p0^2 (1 - r^2/a^2) of the nodal pressures above :data:`FIT_ABOVE` of the largest,
r the distance from the contact's axis (through the pressure's centroid, normal to the
contact patch). Every figure is a sum or a maximum over the slave vertices, so a coupler on
several ranks evaluates it from each rank's own vertices. E and nu come from the scene; R from ``[check] radius``."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums
from coupler.errors import CouplerError

KIND = "hertz"
DISTRIBUTED = True
DESCRIPTION = "a sphere pressed onto a block: contact radius and peak pressure against Hertz theory"
KEYS = {"radius": "the sphere's radius R [m]",
        "tolerance": "largest relative error accepted, of the contact radius a and of the peak pressure p0"}
#: nodal pressures above this fraction of the largest enter the elliptic fit (the rim of the
#: contact area, where the discrete pressure falls to zero over one cell, is left out)
FIT_ABOVE = 0.2


def parse(table, scene) -> dict:
    if scene.contact is None:
        raise table.error("kind", "'hertz' needs the effect 'contact' (the contact pressure on the sphere's face)")
    return {"radius": table.number("radius", positive=True), "tolerance": table.number("tolerance", positive=True)}


def theory(force: float, radius: float, E: float, nu: float) -> tuple[float, float]:
    """Hertz's contact radius a and peak pressure p0 for the normal force `force`."""
    E_star = E / (2.0 * (1.0 - nu * nu))
    a = (3.0 * force * radius / (4.0 * E_star)) ** (1.0 / 3.0)
    return a, 3.0 * force / (2.0 * np.pi * a * a)


def fit(points: np.ndarray, pressure: np.ndarray, weight: np.ndarray, where: str, sums=None) -> dict:
    """The contact force and the elliptic fit of the pressure at the slave face's vertices held
    here, every figure made of sums and maxima over them that `sums` (a
    :class:`coupler.coupling.row_sums.RowSums`; None: these vertices are all) combines over the
    ranks: the force and centroid, the patch's normal as the weighted covariance's flattest
    direction, and the least squares line p^2 = p0^2 + slope r^2 from its centred normal
    equations."""
    sums = sums or RowSums()
    touching = pressure > 0
    force, touching_count = sums.sum(np.array([np.sum(pressure * weight), np.count_nonzero(touching)]))
    if force <= 0 or touching_count < 3:
        raise CouplerError(f"{where}: {int(touching_count)} slave vertices carry pressure (force {force:.3g} N): "
                           f"no contact area to compare with Hertz")
    centre = sums.sum(np.sum((pressure * weight)[:, None] * points, axis=0)) / force
    x = points[touching] - centre
    covariance = sums.sum((weight[touching][:, None] * x).T @ x)
    normal = np.linalg.eigh(covariance)[1][:, 0]  # the flattest direction of the contact patch
    r2 = np.sum(x**2, axis=1) - (x @ normal) ** 2
    p_max = sums.extremum(float(np.max(pressure, initial=0.0)), "max")
    above = pressure[touching] > FIT_ABOVE * p_max
    r2, p2 = r2[above], pressure[touching][above] ** 2
    count, r2_sum, p2_sum = sums.sum(np.array([len(r2), np.sum(r2), np.sum(p2)]))
    r2_mean, p2_mean = r2_sum / count, p2_sum / count
    Srr, Srp = sums.sum(np.array([np.sum((r2 - r2_mean) ** 2), np.sum((r2 - r2_mean) * (p2 - p2_mean))]))
    slope = Srp / Srr if Srr > 0 else np.nan
    intercept = p2_mean - slope * r2_mean
    if not (slope < 0 < intercept):
        raise CouplerError(f"{where}: the contact pressure does not fall off from the centre (fit p^2 = "
                           f"{intercept:.3g} + {slope:.3g} r^2): no Hertz contact to compare")
    return {"force": float(force), "a": float(np.sqrt(-intercept / slope)), "p0": float(np.sqrt(intercept)),
            "p_max": float(p_max), "centre": centre.tolist(), "normal": normal.tolist(),
            "fitted_vertices": int(count)}


def evaluate(settings, scene, result) -> dict:
    points, fields = result.rows("solid")
    slave = fields["slave"] > 0.5
    points = points[slave]
    measured = fit(points, fields["contact_pressure"][slave], fields["mortar_weight"][slave],
                   f"{scene.path}: [check] kind 'hertz'", result.sums)
    a, p0 = theory(measured["force"], settings["radius"], scene.material["E"], scene.material["nu"])
    in_contact = fields["in_contact"][slave] > 0.5
    a_area = float(np.sqrt(result.sums.sum(float(fields["mortar_weight"][slave][in_contact].sum())) / np.pi))
    error_a, error_p0 = abs(measured["a"] / a - 1), abs(measured["p0"] / p0 - 1)
    return {"error": max(error_a, error_p0), "tolerance": settings["tolerance"],
            "passed": bool(max(error_a, error_p0) <= settings["tolerance"]), "radius": settings["radius"],
            "force": measured["force"], "a_hertz": a, "p0_hertz": p0, "a": measured["a"], "p0": measured["p0"],
            "error_a": error_a, "error_p0": error_p0, "a_area": a_area, "error_a_area": abs(a_area / a - 1),
            "p_max": measured["p_max"], "error_p_max": abs(measured["p_max"] / p0 - 1),
            "centre": measured["centre"], "fitted_vertices": measured["fitted_vertices"]}


def describe(report: dict) -> str:
    return (f"Hertz (R = {report['radius']:g} m, F = {report['force']:.4g} N): a {report['a']:.4g} m against "
            f"{report['a_hertz']:.4g} m (error {report['error_a']:.2%}), p0 {report['p0']:.4g} Pa against "
            f"{report['p0_hertz']:.4g} Pa (error {report['error_p0']:.2%})")
