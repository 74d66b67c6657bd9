"""Nonsmooth multilevel benchmark (paper section 4.3, figure 14 left): the cube of
cases/cube_obstacle_large on 2 to 5 levels (lattices of 6, 13, 25, 51 cells per axis, the
scene's solid participant configured in this process), solved by the truncated nonsmooth
multigrid on the semi-geometric hierarchy, by the primal-dual active set method with CG + GAMG
and by PETSc's SNES VI, on the same problems in the same run. Prints a table, writes JSON and a
PNG of the multigrid's convergence histories.

    .venv/bin/python bench/multilevel.py                 # levels 2..5 (412k dofs: minutes)
    .venv/bin/python bench/multilevel.py --levels 2 3 4
    .venv/bin/python bench/multilevel.py --quick -o m.json   # smoke run (levels 2, 3)

Times: the multilevel's is hierarchy setup (projections, eq. 17) + solve; the others' is
their solve (their AMG setup included); assembly is the solid's set-up (mesh, dolfinx's
stiffness, the contact's transformation). The baselines stop on their own criteria (active set:
scaled natural residual 1e-10 relative; SNES VI: rtol 1e-12); their difference to the
multilevel solution is recorded. The machine is shared: the load average is recorded and
single times should not be over-interpreted.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from nonsmooth.multilevel import asymptotic_rate  # noqa: E402
from nonsmooth.solvers import solve  # noqa: E402
from solid_fenicsx.participant import SolidParticipant  # noqa: E402

CASE = ROOT / "cases" / "cube_obstacle_large"
#: paper figure 14's meshes: levels -> cells per axis of the cube's lattice
CELLS = {2: 6, 3: 13, 4: 25, 5: 51}
#: paper figure 14 (left): dofs per level count, about 10 more iterations per added level
PAPER = {"dofs": {2: 1107, 3: 7395, 4: 53955, 5: 412035}, "iterations_per_added_level": 10}
GOALS = {"max_added_iterations_per_level": 2, "max_asymptotic_rate": 0.3,
         "fastest_at_largest": "multilevel time (setup + solve) below active set and SNES VI"}
BASELINES = {"active_set": {}, "snes_vi": {}}


def _relative(x, ref) -> float:
    return float(np.linalg.norm(x - ref) / np.linalg.norm(ref))


def build(levels: int, threads: int):
    """The obstacle QP of the cube on `levels` levels, its multilevel options (with the
    hierarchy) and the seconds of assembly and hierarchy."""
    config = make_plan(load(CASE)).participant("solid").config
    config["box"]["shape"] = [CELLS[levels]] * 3
    config["contact"].update(levels=levels, threads=threads)
    start = time.perf_counter()
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    qp = p.contact.problem()
    hierarchy = p.contact.options["hierarchy"]
    return qp, dict(p.contact.options), {"assembly": time.perf_counter() - start - hierarchy.seconds,
                                         "hierarchy": hierarchy.seconds}


def plot_convergence(path: Path, rows: list[dict]) -> None:
    """Step length against iteration per number of levels (paper figure 14, left)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for r in rows:
        history = r["multilevel"]["step_history"]
        ax.semilogy(np.arange(1, len(history) + 1), history, "o-", ms=3, label=f"{r['levels']} levels, {r['dofs']:,} dofs")
    ax.set_xlabel("iteration")
    ax.set_ylabel("step length ||x_k+1 - x_k||")
    ax.set_title("cube obstacle: truncated nonsmooth multigrid")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_level(levels: int, baselines, threads: int) -> dict:
    qp, options, setup = build(levels, threads)
    hierarchy = options["hierarchy"]
    ml = solve(qp, "multilevel", **options)
    row = {"levels": levels, "cells": CELLS[levels], "dofs": qp.size, "paper_dofs": PAPER["dofs"].get(levels),
           "level_sizes": hierarchy.sizes, "assembly_seconds": setup["assembly"],
           "multilevel": {"iterations": ml.iterations, "converged": ml.converged,
                          "asymptotic_rate": ml.info["asymptotic_rate"], "step_history": ml.history,
                          "setup_seconds": setup["hierarchy"], "solve_seconds": ml.seconds,
                          "seconds": setup["hierarchy"] + ml.seconds, "coarse_rebuilds": ml.info["coarse_rebuilds"],
                          "max_infeasibility": ml.info["max_infeasibility"], "kkt_residual": ml.info["kkt_residual"],
                          "energy": qp.energy(ml.x), "active": int(ml.active.sum())}}
    for name in baselines:
        sol = solve(qp, name, **BASELINES[name])
        row[name] = {"iterations": sol.iterations, "converged": sol.converged, "seconds": sol.seconds,
                     "krylov_iterations": sol.krylov_iterations, "history": sol.history,
                     "asymptotic_rate": asymptotic_rate(sol.history), "energy": qp.energy(sol.x),
                     "kkt_residual": qp.kkt_residual(sol.x), "relative_difference_to_multilevel": _relative(sol.x, ml.x)}
    return row


def _table(rows) -> list[str]:
    lines = [f"{'levels':>6} {'dofs':>9} {'paper':>9} | {'ML it':>5} {'rate':>6} {'setup s':>8} {'solve s':>8} | "
             f"{'AS it':>5} {'AS s':>7} {'AS diff':>8} | {'VI it':>5} {'VI s':>7} {'VI diff':>8}"]
    for r in rows:
        m = r["multilevel"]
        line = (f"{r['levels']:>6} {r['dofs']:>9,} {r['paper_dofs'] or 0:>9,} | {m['iterations']:>5} "
                f"{m['asymptotic_rate']:>6.3f} {m['setup_seconds']:>8.2f} {m['solve_seconds']:>8.2f} |")
        for name in BASELINES:
            b = r.get(name)
            line += (f" {b['iterations']:>5} {b['seconds']:>7.2f} {b['relative_difference_to_multilevel']:>8.1e} |"
                     if b else f" {'-':>5} {'-':>7} {'-':>8} |")
        lines.append(line.rstrip(" |"))
    return lines


def _goals(rows) -> dict:
    its = [r["multilevel"]["iterations"] for r in rows]
    added = [b - a for a, b in zip(its, its[1:])]
    rates = [r["multilevel"]["asymptotic_rate"] for r in rows]
    largest = rows[-1]
    times = {name: largest[name]["seconds"] for name in ["multilevel", *BASELINES] if name in largest}
    goals = {
        "added_iterations_per_level": {"measured": added, "goal": f"<= {GOALS['max_added_iterations_per_level']}",
                                       "pass": bool(all(a <= GOALS["max_added_iterations_per_level"] for a in added))},
        "asymptotic_rate": {"measured": rates, "goal": f"< {GOALS['max_asymptotic_rate']}",
                            "pass": bool(all(r < GOALS["max_asymptotic_rate"] for r in rates))},
        "fastest_at_largest": {"dofs": largest["dofs"], "seconds": times, "goal": GOALS["fastest_at_largest"],
                               "pass": bool(len(times) == 3 and min(times, key=times.get) == "multilevel")},
    }
    return goals


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4, 5])
    parser.add_argument("--quick", action="store_true", help="levels 2 and 3 only (smoke test)")
    parser.add_argument("--baselines", nargs="*", choices=list(BASELINES), default=list(BASELINES),
                        help="baseline solvers to run beside the multilevel one (none: multilevel only)")
    parser.add_argument("--threads", type=int, default=2, help="threads of the projection assembly")
    parser.add_argument("-o", "--output", default=str(ROOT / "bench" / "results" / "multilevel.json"))
    args = parser.parse_args(argv)
    levels = [2, 3] if args.quick else args.levels
    unknown = [lv for lv in levels if lv not in CELLS]
    if unknown:
        parser.error(f"levels {unknown}: the benchmark has lattices for {sorted(CELLS)}")
    load_start = list(os.getloadavg())
    print(f"cube obstacle, {os.cpu_count()} CPUs, load average {load_start}")
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for lv in levels:
        rows.append(run_level(lv, args.baselines, args.threads))
        print(_table(rows)[-1] if len(rows) > 1 else "\n".join(_table(rows)), flush=True)
        result = _write(out, rows, args, levels, load_start, complete=len(rows) == len(levels))
    for name, g in result["goals"].items():
        print(f"{name:<28} {'PASS' if g['pass'] else 'MISS'}  measured {g.get('measured', g.get('seconds'))}  "
              f"goal {g['goal']}")
    print(f"wrote {out.relative_to(ROOT) if out.is_relative_to(ROOT) else out} and {result['figure']}")
    return result


def _write(out: Path, rows, args, levels, load_start, complete: bool) -> dict:
    """JSON and PNG of the levels done so far (rewritten after each, so a long run leaves its figures)."""
    png = out.with_suffix(".png")
    plot_convergence(png, rows)
    result = {
        "meta": {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                 "platform": platform.platform(), "cpu_count": os.cpu_count(), "numpy": np.__version__,
                 "load_average_at_start": load_start, "load_average_at_end": list(os.getloadavg()),
                 "shared_machine_note": "other engineers load the machine; single runs, not over-interpreted"},
        "args": {"levels": levels, "quick": args.quick, "baselines": args.baselines, "threads": args.threads},
        "complete": complete, "case": "cases/cube_obstacle_large/scene.toml",
        "criterion": "step length ||x_k+1 - x_k||_2 < 1e-12", "paper": PAPER, "goals": _goals(rows), "rows": rows,
        "figure": png.name,
    }
    out.write_text(json.dumps(result, indent=1))
    return result

if __name__ == "__main__":
    main()
