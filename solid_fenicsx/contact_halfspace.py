"""A rough fracture closed by the stress-controlled platen (paper 4.1) against the periodic
elastic half-space, the standard reference of rough contact (issue 30 item 4): the same
sampled faces, the same mean pressure, the mean aperture (the whole plane, contacts as zero)
and the contact area fraction. Used by bench/halfspace.py and its test.

The reference is tamaas's periodic boundary-element contact (Polonsky-Keer-Rey, a bench and
test dependency that scripts/install.sh installs) for the composite problem of two identical
bodies: a rigid surface of heights ``-aperture`` (its peaks where the faces are nearest) on a
flat half-space of modulus E* = E / (2 (1 - nu^2)) (tamaas: ``E = E*``, ``nu = 0``); its gap
field is the aperture, zero on the contacts. The fracture is a box of two blocks with free
sides, fixed at the bottom and held by the rigid platen on top (generator
``measured_fracture``, the map ``periodic``: the faces are one period of the reference's
surfaces, the box spans it); the half-space has neither sides nor depth.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from transfer.generators.height_maps import write_npz
from transfer.generators.surfaces import fracture_pair

#: where the solid's configuration is taken from (its generator parameters, material and loads replaced)
CASE = Path(__file__).resolve().parents[1] / "cases" / "measured_fracture"


def fracture_map(cells: int, size: float, aperture: float, rms: float, hurst: float = 0.8,
                 mismatch_length: float | None = None, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """One period of a periodic fracture pair of the project's generator
    (:func:`~transfer.generators.surfaces.fracture_pair`, touching where the aperture would be
    negative): ``(lower, upper)`` heights (cells, cells) [m], indexed [i, j] at (i dx, j dy)."""
    lower, upper = fracture_pair((cells, cells), (size, size), aperture=aperture, hurst=hurst, rms=rms,
                                 mismatch_length=mismatch_length, seed=seed, min_aperture=0.0, periodic=True)
    return lower[:-1, :-1], upper[:-1, :-1]


def effective_modulus(E: float, nu: float) -> float:
    """E* of two identical elastic bodies in contact, E / (2 (1 - nu^2))."""
    return E / (2.0 * (1.0 - nu * nu))


def halfspace(aperture: np.ndarray, size: float, E: float, nu: float, stress: float,
              tolerance: float = 1e-10) -> dict:
    """The periodic half-space's closure of the initial `aperture` (cells, cells) [m] under the
    mean pressure `stress` [Pa]: its aperture field (zero on the contacts), mean aperture,
    contact area fraction and closure (initial minus loaded mean aperture)."""
    import tamaas

    tamaas.set_log_level(tamaas.LogLevel.error)
    model = tamaas.ModelFactory.createModel(tamaas.model_type.basic_2d, [size, size], list(aperture.shape))
    model.E, model.nu = effective_modulus(E, nu), 0.0
    solver = tamaas.PolonskyKeerRey(model, -np.ascontiguousarray(aperture, float), tolerance)
    solver.solve(stress)
    gap = np.array(model["gap"])
    mean = float(gap.mean())
    return {"gap": gap, "mean_aperture": mean, "area_fraction": float(np.mean(model.traction > 0)),
            "closure": float(aperture.mean()) - mean, "stress": float(model.traction.mean())}


def solid(directory, lower: np.ndarray, upper: np.ndarray, size: float, height: float, layers: int,
          E: float, nu: float, stresses, tolerance: float = 1e-3):
    """The configured solid participant of the faces `lower`, `upper` (one period, (cells,
    cells)) as a box of two blocks `height` thick with `layers` each, the platen on top to the
    `stresses` (one load step each, within `tolerance`); the map written to `directory`."""
    from coupler.plan.plan import make_plan
    from coupler.scene import load

    from .participant import SolidParticipant

    surfaces = write_npz(Path(directory) / "surfaces.npz", lower.T, upper.T, (size / lower.shape[0],) * 2)
    config = make_plan(load(CASE)).participant("solid").config
    config["generator"]["parameters"].update(surfaces=str(surfaces), height=height, layers=layers, coarsen=1,
                                             ratio=1, periodic=True, min_aperture=0.0, tolerance=None)
    config["material"].update(E=E, nu=nu)
    platen = next(ld for ld in config["loads"] if ld["type"] == "platen")
    platen.update(value=[float(s) for s in stresses], area=size * size, tolerance=tolerance)
    config["steps"] = len(platen["value"])
    config["contact"]["search_distance"] = 2.0 * float(np.max(upper - lower)) + size / lower.shape[0]
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p


def compare(lower: np.ndarray, upper: np.ndarray, size: float, height: float, layers: int, E: float, nu: float,
            stresses, band: float = 0.125, tolerance: float = 1e-3, monitor=None) -> dict:
    """Each stress in turn on the solid (:func:`solid`) and on the half-space at the stress the
    platen reached: mean apertures, area fractions, closures, the platen displacement and its
    part beyond the closure (the blocks' bulk compression), and the mean apertures of both on
    the nodes farther than `band` x size from the box's sides (the free sides' share of the
    difference). Raises RuntimeError when a solve of the solid did not converge."""
    aperture = upper - lower
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        p = solid(tmp, lower, upper, size, height, layers, E, nu, stresses, tolerance)
        xy = p.contact.mortar.slave.points[:, :2]
        cell = size / lower.shape[0]
        ij = np.rint(xy / cell).astype(int) % lower.shape[0]  # map node of each slave node (the sides wrap)
        inner = np.all((xy > band * size) & (xy < (1 - band) * size), axis=1)
        weights = p.contact.mortar.weights
        d0 = p.contact.initial_mean_gap
        for k, target in enumerate(stresses):
            p.advance(k, 0, float(k), 1.0, {})
            reports, figures = p.take_reports()
            failed = [r for r in reports if not r.converged]
            if failed:
                raise RuntimeError(f"solid at {target:g} Pa: {failed[0].solver} did not converge: {failed[0].detail}")
            gap = p.static.state.gap
            ref = halfspace(aperture, size, E, nu, figures["stress"])
            inner_ref = float(ref["gap"][ij[inner, 0], ij[inner, 1]].mean())
            inner_solid = float(np.sum(weights[inner] * gap[inner]) / np.sum(weights[inner]))
            bulk = figures["platen_displacement"] - figures["closure"]
            rows.append({"stress": figures["stress"], "mean_aperture": figures["mean_gap"],
                         "mean_aperture_halfspace": ref["mean_aperture"],
                         "error_mean_aperture": figures["mean_gap"] / ref["mean_aperture"] - 1,
                         "area_fraction": figures["area_fraction"], "area_fraction_halfspace": ref["area_fraction"],
                         "closure": figures["closure"], "closure_halfspace": ref["closure"],
                         "platen_displacement": figures["platen_displacement"], "bulk_compression": bulk,
                         "bulk_compression_over_column": bulk / (figures["stress"] * 2 * height / E),
                         "inner_mean_aperture": inner_solid, "inner_mean_aperture_halfspace": inner_ref,
                         "error_inner_mean_aperture": inner_solid / inner_ref - 1,
                         "contact_solves": int(figures["contact_solves"]), "seconds": figures["seconds"]})
            if monitor is not None:
                monitor(rows[-1])
        out = {"cells": int(lower.shape[0]), "size": size, "height": height, "layers": layers, "E": E, "nu": nu,
               "dofs": int(p.contact.num_dofs), "initial_mean_aperture": d0,
               "initial_mean_aperture_map": float(aperture.mean()), "band": band, "steps": rows}
    return out
