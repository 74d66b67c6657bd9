"""FSI benchmark: wall time per phase (fluid, solid, transfer incl. the geometry
update of the two-way coupling, messaging) and coupling iterations per step for constant
relaxation, Aitken and IQN-ILS, on a coupled case (default cases/fracture_flow). Each
accelerator runs the case once through ``varcouple run`` into a temporary directory, with the
coupling tolerance set to ``--tolerance`` (default 1e-6, the issue's); ``--summary FILE``
instead only reports one existing run's summary.json.

Goals, each reported PASS/MISS per run: transfer + messaging under 5 % of the wall
time; IQN-ILS under 6 coupling iterations in every step.

Two more sections (skip them with ``--no-parallel``, ``--no-soft``):

* ``parallel``: the fluid alone, one simpleFoam solve on a 3D duct with an immersed layer
  (96 x 48 x 24 cells) on 1 and 2 MPI ranks (fluid_openfoam/parallel.py), and the coupled
  case with ``[solvers.fluid] ranks = 2`` (IQN-ILS);
* ``soft_rock``: cases/small_fracture with E = 5 kPa (one step, the fracture opens by half
  its aperture; grid extended in z), IQN-ILS with first relaxation 1.0 and 0.5, IQN-ILS with
  the newest 3 secant columns only (``[coupling] columns = 3``), constant relaxation 1.0.

    .venv/bin/python bench/fsi.py [--case cases/fracture_flow] [--relaxation 1.0]
        [--set "E = 1.0e9=E = 5.0e3" ...] [--no-parallel] [--no-soft] [--quick] [-o FILE]

``--quick`` (smoke test): cases/small_fracture, one step, IQN-ILS only, a 16 x 8 x 4 duct
(fluid alone), no coupled 2-rank run, no soft rock; output bench/results/fsi_quick.json unless ``-o`` is given.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.case_runs import run_edited  # noqa: E402


#: the issue's goals: (key of the report, bound, what it measures)
GOALS = {"transfer_and_messaging_share": 0.05, "iqn_ils_iterations_per_step": 6}


def goals(result: dict) -> dict:
    """PASS/MISS against :data:`GOALS` for one run (the iteration goal applies to IQN-ILS)."""
    out = {}
    share = result.get("transfer_and_messaging_share")
    if share is not None:
        out["transfer_and_messaging_share"] = {"value": share, "goal": f"< {GOALS['transfer_and_messaging_share']}",
                                               "status": "PASS" if share < GOALS["transfer_and_messaging_share"]
                                               else "MISS"}
    if result.get("acceleration") == "iqn-ils":
        worst = max((i for i in result["iterations_per_step"] if i is not None), default=None)
        ok = worst is not None and worst < GOALS["iqn_ils_iterations_per_step"] and all(result["converged"])
        out["iqn_ils_iterations_per_step"] = {"value": worst, "goal": f"< {GOALS['iqn_ils_iterations_per_step']} "
                                              "in every step, converged", "status": "PASS" if ok else "MISS"}
    return out


def report(summary: dict) -> dict:
    phases = dict(summary.get("phases_seconds", {}))
    wall = float(summary.get("wall_seconds", sum(phases.values())))
    transfer = phases.get("transfer", 0.0) + phases.get("geometry update", 0.0)
    messaging = phases.get("messaging", 0.0)
    steps = summary.get("steps", [])
    return {"status": summary.get("status"), "wall_seconds": wall, "phases_seconds": phases,
            "fluid_seconds": phases.get("fluid", 0.0), "solid_seconds": phases.get("solid", 0.0),
            "transfer_seconds": transfer, "geometry_update_seconds": phases.get("geometry update", 0.0),
            "messaging_seconds": messaging,
            "transfer_share": transfer / wall if wall else None,
            "transfer_and_messaging_share": (transfer + messaging) / wall if wall else None,
            "iterations_per_step": [s.get("iterations") for s in steps],
            "converged": [s.get("converged") for s in steps],
            "final_residuals": [s.get("residuals", [None])[-1] for s in steps],
            "geometry_update": summary.get("geometry_update"), "error": summary.get("error")}


def run_case(case: Path, acceleration: str, relaxation: float, replace: dict, tolerance: float) -> dict:
    """``varcouple run`` on a copy of `case` with the scene text replacements and the coupling
    keys given; the report of its summary.json with the goals."""
    def coupling(scene: str) -> str:
        lines = scene.splitlines()
        i = lines.index("[coupling]")
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("[")), len(lines))
        keep = [ln for ln in lines[i + 1:end] if not re.match(r"(acceleration|relaxation|tolerance)\s*=", ln)]
        lines[i + 1:end] = [f'acceleration = "{acceleration}"', f"relaxation = {relaxation}",
                            f"tolerance = {tolerance!r}", *keep]
        return "\n".join(lines) + "\n"

    code, seconds, summary = run_edited(case, replace, coupling, prefix="varcouple-bench-fsi-")
    result = report(summary)
    result.update(acceleration=acceleration, relaxation=relaxation, exit_code=code, measured_seconds=seconds)
    result["goals"] = goals(result)
    return result


def fluid_ranks(shape, ranks_list=(1, 2)) -> dict:
    """One simpleFoam solve (from rest, tolerance 1e-7) of a duct with 1 mm cells, a velocity
    inlet and the lower 30 % solid, on each number of ranks; wall time of the solve (the
    decomposition, once per case, separately) and the speed-up against 1 rank."""
    import numpy as np

    from fluid_openfoam.case import CaseSpec
    from fluid_openfoam.solver import OpenFOAMSolver

    runs, fields = [], {}
    for ranks in ranks_list:
        spec = CaseSpec.from_config({"grid": {"origin": [0, 0, 0], "spacing": [1e-3] * 3, "shape": list(shape)},
                                     "inlet": {"velocity": [0.01, 0, 0]}, "mu": 1e-3, "rho": 1000.0,
                                     "tolerance": 1e-7, "max_iterations": 3000, "ranks": ranks})
        with tempfile.TemporaryDirectory(prefix="varcouple-bench-ranks-") as tmp:
            solver = OpenFOAMSolver(Path(tmp) / "case", spec)
            t0 = time.perf_counter()
            solver.setup()
            setup = time.perf_counter() - t0
            c = spec.grid.cell_centres()
            t0 = time.perf_counter()
            U, _ = solver.solve((c[:, 1] < 0.3 * shape[1] * 1e-3).astype(float))
            solve = time.perf_counter() - t0
        fields[ranks] = U
        runs.append({"ranks": ranks, "cells": spec.grid.n_cells, "setup_seconds": setup, "solve_seconds": solve,
                     "simpleFoam_iterations": solver.last_run["iterations"],
                     "converged": solver.last_run["converged"]})
    base = runs[0]
    for r in runs:
        r["speedup"] = base["solve_seconds"] / r["solve_seconds"]
        r["max_velocity_difference_to_1_rank"] = float(np.max(np.abs(fields[r["ranks"]] - fields[base["ranks"]])))
    return {"shape": list(shape), "runs": runs}


#: small_fracture on a soft rock (as tests/test_small_fracture.py): one step, grid extended in z
SOFT = {"E = 2.0e5": "E = 5.0e3", "steps = 2": "steps = 1",
        "lower = [0.0, 0.0, -0.0006]": "lower = [0.0, 0.0, -0.0016]",
        "upper = [0.05, 0.025, 0.0016]": "upper = [0.05, 0.025, 0.0026]",
        "shape = [21, 11, 11]": "shape = [21, 11, 21]", "max_iterations = 30": "max_iterations = 25"}
FLUID_RANKS = ('participant = "openfoam"', 'participant = "openfoam"\nranks = 2')


def parse_set(items) -> dict:
    replace = {}
    for s in items:  # "E = 2.0e5=E = 5.0e3": split at the '=' between the two sides
        parts = s.split("=")
        half = len(parts) // 2
        replace["=".join(parts[:half])] = "=".join(parts[half:])
    return replace


def line(name: str, r: dict) -> str:
    share = r["transfer_and_messaging_share"]
    if share is None:
        return f"{name:24s} {r['status']}: {r['error']}"
    return (f"{name:24s} iterations/step {r['iterations_per_step']}  wall {r['wall_seconds']:.1f} s  "
            f"fluid {r['fluid_seconds']:.1f}  solid {r['solid_seconds']:.2f}  transfer {r['transfer_seconds']:.2f} "
            f"(geometry update {r['geometry_update_seconds']:.2f})  messaging {r['messaging_seconds']:.2f}  "
            f"transfer+messaging {100 * share:.1f} %")


def print_goals(r: dict) -> None:
    for key, g in r["goals"].items():
        print(f"    goal {key} {g['goal']}: {g['value']:.4g} {g['status']}" if g["value"] is not None
              else f"    goal {key}: no value, {g['status']}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="cases/fracture_flow", help="case directory (relative to the repository)")
    ap.add_argument("--accelerations", nargs="+", default=["constant", "aitken", "iqn-ils"])
    ap.add_argument("--relaxation", type=float, default=1.0)
    ap.add_argument("--set", action="append", default=[], metavar="OLD=NEW",
                    help="text replacement in the scene (e.g. a softer rock)")
    ap.add_argument("--tolerance", type=float, default=1e-6, help="relative coupling tolerance (issue: 1e-6)")
    ap.add_argument("--no-parallel", action="store_true", help="skip the 1-rank / 2-rank fluid section")
    ap.add_argument("--no-soft", action="store_true", help="skip the soft-rock section")
    ap.add_argument("--summary", help="only report this existing summary.json")
    ap.add_argument("--quick", action="store_true", help="smoke run: small_fracture, one step, IQN-ILS")
    ap.add_argument("-o", "--output", default=None, help="JSON output (default bench/results/fsi.json)")
    a = ap.parse_args(argv)
    duct = (96, 48, 24)
    if a.quick:
        a.case, a.accelerations, a.set, a.no_soft = "cases/small_fracture", ["iqn-ils"], a.set + ["steps = 2=steps = 1"], True
        duct = (16, 8, 4)
    if a.output is None:
        a.output = ROOT / "bench" / "results" / ("fsi_quick.json" if a.quick else "fsi.json")
    if a.summary:
        result = {"summary": a.summary, **report(json.loads(Path(a.summary).read_text()))}
    else:
        replace = parse_set(a.set)
        result = {"case": a.case, "relaxation": a.relaxation, "tolerance": a.tolerance, "replace": replace,
                  "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "platform": platform.platform(),
                  "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg(),
                  "note": "2 cores shared with other engineers' jobs: times are indicative, the 2-rank speed-up "
                          "is a lower bound of what two free cores give",
                  "goals": {"transfer_and_messaging_share": f"< {GOALS['transfer_and_messaging_share']}",
                            "iqn_ils_iterations_per_step": f"< {GOALS['iqn_ils_iterations_per_step']}"},
                  "runs": {}}
        for acc in a.accelerations:
            r = result["runs"][acc] = run_case(ROOT / a.case, acc, a.relaxation, replace, a.tolerance)
            print(line(acc, r), flush=True)
            print_goals(r)
        if not a.no_parallel:
            par = result["parallel"] = {"fluid_alone": fluid_ranks(duct)}
            for r in par["fluid_alone"]["runs"]:
                print(f"duct {'x'.join(map(str, duct))} ({r['cells']} cells), {r['ranks']} rank"
                      f"{'s' * (r['ranks'] > 1)}: solve {r['solve_seconds']:.2f} s ({r['simpleFoam_iterations']} "
                      f"iterations), speed-up {r['speedup']:.2f}, max |U - U_1 rank| "
                      f"{r['max_velocity_difference_to_1_rank']:.2e} m/s", flush=True)
            if not a.quick:  # the coupled 2-rank run is tests/test_fluid_parallel.py's in the smoke test
                r = par["coupled_2_ranks"] = run_case(ROOT / a.case, "iqn-ils", a.relaxation,
                                                      {**replace, FLUID_RANKS[0]: FLUID_RANKS[1]}, a.tolerance)
                print(line("iqn-ils, fluid 2 ranks", r), flush=True)
                print_goals(r)
        if not a.no_soft:
            soft = result["soft_rock"] = {"case": "cases/small_fracture", "replace": SOFT, "runs": {}}
            last_three = {"[coupling]": "[coupling]\ncolumns = 3"}
            for name, acc, omega, extra in (("iqn-ils relaxation 1.0", "iqn-ils", 1.0, {}),
                                            ("iqn-ils relaxation 0.5", "iqn-ils", 0.5, {}),
                                            ("iqn-ils relaxation 1.0, 3 columns", "iqn-ils", 1.0, last_three),
                                            ("constant relaxation 1.0", "constant", 1.0, {})):
                r = soft["runs"][name] = run_case(ROOT / "cases" / "small_fracture", acc, omega, {**SOFT, **extra},
                                                  a.tolerance)
                print(line(f"soft rock, {name}", r), flush=True)
                print_goals(r)
        result["load_average_after"] = os.getloadavg()
    out = Path(a.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=float))
    print(f"written {out}")
    return result


if __name__ == "__main__":
    main()
