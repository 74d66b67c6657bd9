"""Rough contact against the periodic elastic half-space (issue 30 item 4): a fracture made by
the project's generator (:func:`solid_fenicsx.contact_halfspace.fracture_map`, one period of a
periodic pair: 20 mm square, Hurst 0.8, RMS 20 um per face, faces identical above 5 mm, mean
aperture 40 um), closed by varcouple's stress-controlled platen (two blocks of the generator
``measured_fracture``, E = 30 GPa, nu = 0.25, frictionless mortar contact) at 1, 5 and 20 MPa,
and by tamaas's periodic half-space (composite surface, E* = E / (2 (1 - nu^2)), the stress the
platen reached) on the same sampled surface. Per block shape (height size / 8 to size in
tetrahedra one map spacing tall; the half-size blocks also in tetrahedra two spacings tall, the
quarter-size ones two and half a spacing tall) and stress: the mean aperture (whole plane, contacts as zero) of both and its relative difference, the same over the nodes farther than size / 8 from the box's
free sides, the contact area fractions, the fracture closure (d0 minus the mean aperture) of both
and the platen displacement (the closure plus the blocks' bulk compression, also given against
the elastic column's stress x 2 height / E). Also the half-space on the faces' piecewise-linear
interpolant sampled 2, 4 and 8 times finer: how far the sampled surface's own solution is from
the resolved one.

Goals: the mean aperture within 5 % of the half-space's at every stress for the blocks at least
half the size thick (either tetrahedron height); the contact area's trend the same (the log-log
slope of area fraction against stress between successive stresses within 25 % of the
half-space's).

    .venv/bin/python bench/halfspace.py [--quick] [--cells 16] [-o OUT.json]

The machine is shared: the load average before and after is recorded; times are indicative.
``--quick``: 8 cells, one block shape (half the size high, 2 layers), 1 and 5 MPa (the smoke test).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.output import finish  # noqa: E402

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from solid_fenicsx.contact_halfspace import fracture_map, halfspace  # noqa: E402
from solid_fenicsx.participant import SolidParticipant  # noqa: E402
from transfer.generators.height_maps import write_npz  # noqa: E402

#: where the solid's configuration is taken from (its generator parameters, material and loads replaced)
CASE = ROOT / "cases" / "measured_fracture"
SIZE, APERTURE, RMS, E, NU = 0.02, 40e-6, 20e-6, 30e9, 0.25
#: the goals' tolerances: mean aperture (relative), area slope (relative), blocks counted thick from
GOALS = {"mean_aperture": 0.05, "area_slope": 0.25, "thick_from": 0.5}


def solid(directory, lower: np.ndarray, upper: np.ndarray, size: float, height: float, layers: int,
          E: float, nu: float, stresses, tolerance: float = 1e-3, coarsen: int = 1, grading: float | None = None,
          method: str = "search"):
    """The configured solid participant of the faces `lower`, `upper` (one period, (cells,
    cells)) as a box of two blocks `height` thick with `layers` each (generator
    ``measured_fracture``, the map ``periodic``: the box spans one period; free sides, the bottom
    fixed), the rigid platen on top to the `stresses` (one load step each, within `tolerance`);
    the map written to `directory`; ``coarsen`` and ``grading`` as the generator takes them, the
    platen's ``method`` as the scene does."""
    surfaces = write_npz(Path(directory) / "surfaces.npz", lower.T, upper.T, (size / lower.shape[0],) * 2)
    config = make_plan(load(CASE)).participant("solid").config
    config["generator"]["parameters"].update(surfaces=str(surfaces), height=height, layers=layers, coarsen=coarsen,
                                             ratio=1, periodic=True, min_aperture=0.0, tolerance=None,
                                             grading=grading)
    config["material"].update(E=E, nu=nu)
    platen = next(ld for ld in config["loads"] if ld["type"] == "platen")
    platen.update(value=[float(s) for s in stresses], area=size * size, tolerance=tolerance, method=method)
    config["steps"] = len(platen["value"])
    config["contact"]["search_distance"] = 2.0 * float(np.max(upper - lower)) + size / lower.shape[0]
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p


def compare(lower: np.ndarray, upper: np.ndarray, size: float, height: float, layers: int, E: float, nu: float,
            stresses, band: float = 0.125, tolerance: float = 1e-3, monitor=None, **mesh) -> dict:
    """Each stress in turn on the solid (:func:`solid`) and on the half-space at the stress the
    platen reached: mean apertures, area fractions, closures, the platen displacement and its
    part beyond the closure (the blocks' bulk compression), and the mean apertures of both on
    the nodes farther than `band` x size from the box's sides (the free sides' share of the
    difference); ``mesh``: ``coarsen``, ``grading`` and ``method`` of :func:`solid`. Raises RuntimeError when a
    solve of the solid did not converge."""
    aperture = upper - lower
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        p = solid(tmp, lower, upper, size, height, layers, E, nu, stresses, tolerance, **mesh)
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


def interpolant(values: np.ndarray, refine: int) -> np.ndarray:
    """The piecewise-linear interpolant of periodic node `values` (n, n) on the meshes'
    triangulation (each square split along its (i, j)-(i+1, j+1) diagonal), sampled `refine`
    times finer."""
    n = values.shape[0]
    v = np.pad(values, ((0, 1), (0, 1)), mode="wrap")
    t = np.arange(n * refine) / refine
    i = np.floor(t).astype(int)
    I, J = np.meshgrid(i, i, indexing="ij")
    fx, fy = np.meshgrid(t - i, t - i, indexing="ij")
    below = v[I, J] + fx * (v[I + 1, J] - v[I, J]) + fy * (v[I + 1, J + 1] - v[I + 1, J])
    above = v[I, J] + fy * (v[I, J + 1] - v[I, J]) + fx * (v[I + 1, J + 1] - v[I, J + 1])
    return np.where(fx >= fy, below, above)


def slopes(stresses, areas) -> list[float]:
    """d ln(area fraction) / d ln(stress) between successive stresses."""
    return [float(np.log(a1 / a0) / np.log(s1 / s0)) for s0, s1, a0, a1 in
            zip(stresses, stresses[1:], areas, areas[1:])]


def level(lower, upper, height, layers, stresses) -> dict:
    start = time.perf_counter()

    def say(row):
        print(f"  height {height * 1e3:g} mm, {row['stress'] / 1e6:.3g} MPa: mean aperture {row['mean_aperture'] * 1e6:.3f}"
              f" um (half-space {row['mean_aperture_halfspace'] * 1e6:.3f}, {row['error_mean_aperture']:+.1%}), "
              f"area {row['area_fraction']:.3f} ({row['area_fraction_halfspace']:.3f}), "
              f"{time.perf_counter() - start:.0f} s", flush=True)

    out = compare(lower, upper, SIZE, height, layers, E, NU, stresses, monitor=say)
    rows = out["steps"]
    out["area_slopes"] = slopes([r["stress"] for r in rows], [r["area_fraction"] for r in rows])
    out["area_slopes_halfspace"] = slopes([r["stress"] for r in rows], [r["area_fraction_halfspace"] for r in rows])
    out["wall_seconds"] = time.perf_counter() - start
    return out


def resolved(aperture, stresses, refines) -> list[dict]:
    """The half-space on the faces' interpolant sampled finer: mean aperture and area per stress."""
    rows = []
    for r in refines:
        ref = [halfspace(interpolant(aperture, r), SIZE, E, NU, s) for s in stresses]
        rows.append({"refine": r, "mean_aperture": [x["mean_aperture"] for x in ref],
                     "area_fraction": [x["area_fraction"] for x in ref]})
    return rows


def goals(levels) -> dict:
    thick = [lv for lv in levels if lv["height"] >= GOALS["thick_from"] * SIZE]
    worst = max(abs(r["error_mean_aperture"]) for lv in thick for r in lv["steps"])
    slope = max(abs(a / b - 1) for lv in levels for a, b in zip(lv["area_slopes"], lv["area_slopes_halfspace"]))
    return {"mean_aperture_within_5_percent_thick_blocks": {"worst": worst, "heights": [lv["height"] for lv in thick],
                                                            "status": "PASS" if worst <= GOALS["mean_aperture"] else "MISS"},
            "area_trend_same": {"worst_slope_difference": slope,
                                "status": "PASS" if slope <= GOALS["area_slope"] else "MISS"}}


def table(levels) -> list[str]:
    lines = [f"{'height mm':>9} {'layers':>6} {'dofs':>6} {'MPa':>6} | {'mean aperture um':>16} {'half-space':>10} "
             f"{'diff':>7} {'inner diff':>10} | {'area':>6} {'half-space':>10} | {'closure um':>10} {'half-space':>10} "
             f"{'platen um':>9} {'bulk/column':>11} | {'solves':>6} {'s':>6}"]
    for lv in levels:
        for r in lv["steps"]:
            lines.append(f"{lv['height'] * 1e3:>9g} {lv['layers']:>6} {lv['dofs']:>6} {r['stress'] / 1e6:>6.3g} | "
                         f"{r['mean_aperture'] * 1e6:>16.3f} {r['mean_aperture_halfspace'] * 1e6:>10.3f} "
                         f"{r['error_mean_aperture']:>+7.1%} {r['error_inner_mean_aperture']:>+10.1%} | "
                         f"{r['area_fraction']:>6.3f} {r['area_fraction_halfspace']:>10.3f} | {r['closure'] * 1e6:>10.3f} "
                         f"{r['closure_halfspace'] * 1e6:>10.3f} {r['platen_displacement'] * 1e6:>9.3f} "
                         f"{r['bulk_compression_over_column']:>11.3f} | {r['contact_solves']:>6} {r['seconds']:>6.1f}")
    return lines


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8 cells, one block shape, two stresses (smoke test)")
    ap.add_argument("--cells", type=int, default=None, help="map cells per side (default 16; --quick 8)")
    ap.add_argument("-o", "--output", default=None, help="JSON output (default bench/results/halfspace.json)")
    a = ap.parse_args(argv)
    out = Path(a.output) if a.output else ROOT / "bench" / "results" / f"halfspace{'_quick' if a.quick else ''}.json"
    cells = a.cells or (8 if a.quick else 16)
    # (block height / size, tetrahedra per map spacing in height): one spacing tall; the half-size
    # blocks also two spacings tall, the quarter-size ones two and half a spacing tall (the
    # tetrahedra's height's share of the difference)
    shapes = [(0.5, 0.5)] if a.quick else [(0.125, 1.0), (0.25, 1.0), (0.5, 1.0), (1.0, 1.0), (0.5, 0.5), (0.25, 0.5),
                                           (0.25, 2.0)]
    stresses = [1e6, 5e6] if a.quick else [1e6, 5e6, 20e6]
    refines = [1, 2] if a.quick else [1, 2, 4, 8]
    result = {"meta": {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "platform": platform.platform(),
                       "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg(),
                       "note": "machine shared with other engineers: times are indicative"},
              "args": {"quick": a.quick, "cells": cells, "size": SIZE, "aperture": APERTURE, "rms": RMS, "E": E,
                       "nu": NU, "heights": [f * SIZE for f, _ in shapes], "stresses": stresses, "goals": GOALS}}
    lower, upper = fracture_map(cells, SIZE, APERTURE, RMS, mismatch_length=SIZE / 4)
    print(f"map {cells} x {cells} cells of {SIZE / cells * 1e3:g} mm, initial mean aperture "
          f"{np.mean(upper - lower) * 1e6:.2f} um (min {np.min(upper - lower) * 1e6:.2f}, max "
          f"{np.max(upper - lower) * 1e6:.2f})", flush=True)
    levels = []
    for f, per_spacing in shapes:
        levels.append(level(lower, upper, f * SIZE, max(1, round(f * cells * per_spacing)), stresses))
    result["levels"] = levels
    result["resolved_halfspace"] = resolved(upper - lower, [r["stress"] for r in levels[-1]["steps"]], refines)
    result["goals"] = goals(levels)
    result["meta"]["load_average_after"] = os.getloadavg()
    lines = table(levels) + [""]
    lines.append("half-space on the faces' interpolant sampled finer (at the last shape's stresses): "
                 + "; ".join(f"x{r['refine']}: " + ", ".join(f"{m * 1e6:.3f} um / {s:.3f}" for m, s in
                                                             zip(r["mean_aperture"], r["area_fraction"]))
                             for r in result["resolved_halfspace"]))
    g = result["goals"]
    lines.append(f"mean aperture within {GOALS['mean_aperture']:.0%} of the half-space (blocks >= "
                 f"{GOALS['thick_from']:g} x size thick): worst {g['mean_aperture_within_5_percent_thick_blocks']['worst']:.1%} "
                 f"{g['mean_aperture_within_5_percent_thick_blocks']['status']}")
    lines.append(f"contact area trend (log-log slope against stress within {GOALS['area_slope']:.0%}): worst "
                 f"{g['area_trend_same']['worst_slope_difference']:.1%} {g['area_trend_same']['status']}")
    lines.append(f"load average before {result['meta']['load_average_before'][0]:.2f}, after "
                 f"{result['meta']['load_average_after'][0]:.2f}")
    return finish(result, lines, out)


if __name__ == "__main__":
    main()
