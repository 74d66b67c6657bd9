"""The error estimate of the hydraulic aperture e_h (summary.json ``fracture.hydraulic_aperture_error``:
Richardson at order 1/2 from the Chorin fluid's flow rate on its grid coarsened 2x across the
gap, coupler/fsi/resolution.py) against the true error on cases/hm_fracture, and what the coarse
solve costs.

* ``estimate``: the case with the Newton steady solve on the shipped 16 x 16 columns at 8 and 16
  cells across the mean initial aperture (43 and 87 cells across z); per stress e_h, the
  estimate, the true error against the converged e_h and their ratio. The converged e_h: with
  the scene's penalization "lubrication", ``bench/results/hm_converged.json`` (bench/hm.py
  --converged); with ``--wall`` (penalization "wall") the study
  ``bench/results/hm_fracture_across_study.json`` extrapolated (Richardson from its 16 and 32
  across runs at the order the three finest show, as cases/hm_fracture/README.md states it).
  Goal (PASS/MISS): the estimate brackets the true error (ratio >= 1) at every stress at 8 and
  16 across.
* ``cost``: the fluid's seconds in the coarse solves against those in the fine ones in the same
  run (the fluid log's per-solve times), for the Newton runs above and the shipped case with the
  default march. Goal: the coarse solves cost at most 30 % of the fine ones.

    .venv/bin/python bench/eh_error.py [--wall] [-o FILE]

The machine is shared: the load average before and after is recorded; times are indicative.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.case_runs import run_edited  # noqa: E402
from bench.output import finish  # noqa: E402

CASE = ROOT / "cases" / "hm_fracture"
SHIPPED = "shape = [16, 16, 53]"
PENALIZATION = 'penalization = "lubrication"'  # the scene's (cases/hm_fracture/scene.toml)
ACROSS = {8: 43, 16: 87}  # cells across the mean initial aperture -> cells across z (the study's grids)
GOAL_COST = 0.30
#: a fluid log line of one solve: its name and seconds (fluid_chorin/participant.py)
SOLVE = re.compile(r"window \d+ iteration \d+: (?P<solver>.*?), \d+ iterations, .* (?P<seconds>[0-9.]+) s$")


def solve_seconds(out: Path) -> dict:
    """The fluid's seconds in its fine and its coarse (error estimate) steady solves, from its log."""
    seconds = {"fine": 0.0, "coarse": 0.0}
    for line in (out / "logs" / "fluid.log").read_text().splitlines():
        found = SOLVE.search(line)
        if found:
            seconds["coarse" if "coarsened" in found["solver"] else "fine"] += float(found["seconds"])
    return seconds


def run(replace: dict) -> dict:
    """cases/hm_fracture with `replace` in its scene: per stress the fracture's figures, and the
    fluid's fine and coarse solve seconds."""
    seconds = {}
    code, wall, summary = run_edited(CASE, replace, prefix="varcouple-bench-eh-",
                                     inspect=lambda out: seconds.update(solve_seconds(out)))
    fracture = [{k: v for k, v in s["fracture"].items() if k != "warnings"} for s in summary.get("steps", [])]
    return {"exit_code": code, "status": summary.get("status"), "wall_seconds": wall, "fracture": fracture,
            "stress": [s["figures"]["solid"]["stress"] for s in summary.get("steps", [])],
            "solve_seconds": seconds, "coarse_cost": seconds["coarse"] / seconds["fine"] if seconds["fine"] else None}


def converged_lubrication(record: dict) -> list[float]:
    """bench/hm.py --converged's extrapolated e_h per stress."""
    return [e["value"] for e in record["converged"]["extrapolated"]]


def converged(study: dict) -> list[float]:
    """The study's extrapolated e_h per stress: Richardson from its two finest runs at the order
    its three finest show."""
    figures = [r["figure"] for r in study["runs"]]
    out = []
    for coarse, middle, fine in zip(*figures[-3:]):
        order = math.log2((coarse - middle) / (middle - fine))
        out.append(fine - (middle - fine) / (2 ** order - 1))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wall", action="store_true", help='the scene with penalization "wall"')
    parser.add_argument("-o", "--output", type=Path)
    args = parser.parse_args(argv)
    results = ROOT / "bench" / "results"
    source = results / ("hm_fracture_across_study.json" if args.wall else "hm_converged.json")
    truth = (converged if args.wall else converged_lubrication)(json.loads(source.read_text()))
    mode = {PENALIZATION: 'penalization = "wall"'} if args.wall else {}
    load = {"before": os.getloadavg()}
    newton = {'participant = "chorin"': 'participant = "chorin"\nsteady = "newton"'}
    runs = {n: run({SHIPPED: f"shape = [16, 16, {nz}]", **newton, **mode}) for n, nz in ACROSS.items()}
    march = run(mode)
    load["after"] = os.getloadavg()
    lines = [f"e_h error estimate on cases/hm_fracture (Newton, 16 x 16 columns, penalization "
             f"{'wall' if args.wall else 'lubrication'}); truth: {source.name} "
             f"extrapolated {' / '.join(f'{1e6 * t:.2f}' for t in truth)} um",
             "across  stress [MPa]  e_h [um]  estimate [um]  true error [um]  estimate / true"]
    ratios = {}
    for n, r in runs.items():
        ratios[n] = []
        for stress, f, t in zip(r["stress"], r["fracture"], truth):
            true = f["hydraulic_aperture"] - t
            ratio = f["hydraulic_aperture_error"] / abs(true)
            ratios[n].append(ratio)
            lines.append(f"{n:6d}  {stress / 1e6:12.3g}  {1e6 * f['hydraulic_aperture']:8.2f}  "
                         f"{1e6 * f['hydraulic_aperture_error']:13.2f}  {1e6 * true:15.2f}  {ratio:15.2f}")
    brackets = all(x >= 1.0 for values in ratios.values() for x in values)
    lines.append(f"the estimate brackets the true error at 8 and 16 across: {'PASS' if brackets else 'MISS'}")
    costs = {**{f"newton, {n} across": r["coarse_cost"] for n, r in runs.items()},
             "march, shipped grid (10 across)": march["coarse_cost"]}
    for label, cost in costs.items():
        lines.append(f"coarse solves / fine solves, {label}: {cost:.2f} "
                     f"({'PASS' if cost <= GOAL_COST else 'MISS'}: goal {GOAL_COST:.2f})")
    lines.append(f"load average before {load['before'][0]:.1f}, after {load['after'][0]:.1f}")
    finish({"machine": platform.node(), "load_average": load, "truth_hydraulic_aperture": truth,
            "penalization": "wall" if args.wall else "lubrication", "truth": source.name, "runs": {str(n): r for n, r in runs.items()}, "march_shipped": march,
            "ratio_estimate_true": {str(n): v for n, v in ratios.items()}, "brackets": brackets,
            "coarse_cost": costs, "goal_coarse_cost": GOAL_COST}, lines,
           args.output or results / f"eh_error{'_wall' if args.wall else ''}.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
