"""The Chorin fluid's pressure Poisson solvers side by side: PETSc's sparse Cholesky (``poisson =
"direct"``) against CG + GAMG (``"gamg"``), on the grids where ``"auto"`` has to choose.

Per grid and method, in a process of its own (for its peak memory): the set-up (assembly and
factorization, or the multigrid hierarchy; done again for every new dt or solid), the time of one
solve (median of 5 right-hand sides), the iterations, and the peak resident memory it added. Three
kinds of grid: cubes of n^3 cells with no solid (isotropic, constant coefficients: multigrid's
best case), the same cubes with two penalized blocks around a wavy open gap (coefficient jumps of
1e6 and more), and fracture slabs like cases/hm_fracture_paper (the blocks, in cells 125 times
longer than high). From them, the
cost of a step amortized over the steps that share a set-up, and the largest grid on which the
factorization still wins: the threshold ``"auto"`` uses (fluid_chorin/poisson.py
``DIRECT_CELLS``).

    .venv/bin/python bench/poisson.py                 # writes bench/results/poisson.json
    .venv/bin/python bench/poisson.py --quick -o t.json
    .venv/bin/python bench/poisson.py --grids "cube 24^3" "fracture 32x32x73" -o t.json

The whole run takes about 25 minutes on this machine: the factorization of the 64^3 cube takes 5
minutes, multigrid's set-up on the 48 x 48 x 73 fracture slab (with its threshold) 10.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DEFAULT_OUTPUT = ROOT / "bench" / "results" / "poisson.json"
METHODS = ("direct", "gamg")
#: grid name -> (kind, shape)
GRIDS = {"cube 24^3": ("cube", (24, 24, 24)), "cube 32^3": ("cube", (32, 32, 32)),
         "cube 40^3": ("cube", (40, 40, 40)), "cube 50^3": ("cube", (50, 50, 50)),
         "cube 64^3": ("cube", (64, 64, 64)),
         "blocks 32^3": ("blocks", (32, 32, 32)), "blocks 50^3": ("blocks", (50, 50, 50)),
         "fracture 16x16x53": ("fracture", (16, 16, 53)), "fracture 32x32x73": ("fracture", (32, 32, 73)),
         "fracture 48x48x73": ("fracture", (48, 48, 73))}
QUICK = ("cube 24^3", "fracture 16x16x53")
#: pseudo-time steps sharing one set-up: a coupled steady solve takes hundreds per coupling iteration
STEPS_PER_SETUP = (20, 200)


def solver_on(kind: str, shape, method: str):
    """A Chorin solver on the grid (pressure inlet and outlet on x: a regular matrix) with its solid."""
    from fluid_chorin.solver import ChorinSolver
    from fluid_chorin.spec import ChorinSpec

    nx, ny, nz = shape
    h = 1.0 / nx
    spacing = [h, h, h / 125] if kind == "fracture" else [h, h, h]  # hm_fracture_paper: 2.5 mm x 20 um
    config = {"grid": {"origin": [0, 0, 0], "spacing": spacing, "shape": list(shape)}, "inlet": {"pressure": 1.0},
              "outlet": {"pressure": 0.0}, "walls": "wall", "rho": 1000.0, "mu": 1e-3, "poisson": method}
    solver = ChorinSolver(ChorinSpec.from_config(config))
    if kind != "cube":  # two blocks around a wavy gap of about a third of the height
        x, y, z = np.meshgrid(*[(np.arange(n) + 0.5) / n for n in shape], indexing="ij")
        wave = 0.08 * np.sin(2 * np.pi * 3 * x) * np.cos(2 * np.pi * 2 * y)
        solid = (np.abs(z - 0.5 - wave) > 0.17).astype(float)
        solver.set_solid(solid.transpose(2, 1, 0).ravel())  # x fastest
    return solver


def measure(kind: str, shape, method: str) -> dict:
    """Set-up, one solve, iterations and peak memory of `method` on the grid (this process)."""
    solver = solver_on(kind, shape, method)
    dt = solver.stable_dt(solver.state)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    poisson = solver.poisson(dt)
    setup = time.perf_counter() - start
    rng = np.random.default_rng(0)
    seconds, reports = [], []
    for _ in range(5):
        rhs = rng.standard_normal(solver.state.p.shape)
        start = time.perf_counter()
        _, report = poisson.solve(rhs)
        seconds.append(time.perf_counter() - start)
        reports.append(report)
    return {"cells": int(np.prod(shape)), "method": reports[0].method, "setup_seconds": setup,
            "solve_seconds": float(np.median(seconds)), "iterations": max(r.iterations for r in reports),
            "converged": all(r.converged for r in reports), "residual": max(r.residual for r in reports),
            "peak_memory_bytes": 1024 * (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)}


def amortized(row: dict, steps: int) -> float:
    """Seconds of Poisson work per pseudo-time step when `steps` steps share one set-up."""
    return row["setup_seconds"] / steps + row["solve_seconds"]


def crossover(rows: list[dict], steps: int) -> dict:
    """Per kind of grid: the largest grid on which the factorization is cheaper per step."""
    out = {}
    for kind in ("cube", "blocks", "fracture"):
        wins = [r["direct"]["cells"] for r in rows if r["kind"] == kind and r["direct"]["converged"]
                and (not r["gamg"]["converged"] or amortized(r["direct"], steps) <= amortized(r["gamg"], steps))]
        out[kind] = max(wins, default=0)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the two smallest grids: a smoke run")
    ap.add_argument("--grids", nargs="+", choices=list(GRIDS), metavar="GRID", help="only these grids")
    ap.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT)
    ap.add_argument("--one", nargs=2, metavar=("GRID", "METHOD"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        kind, shape = GRIDS[args.one[0]]
        print(json.dumps(measure(kind, shape, args.one[1])))
        return {}
    env = dict(os.environ, OMP_NUM_THREADS="1")
    result = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_average_before": os.getloadavg(), "rows": []}
    print(f"{'grid':20s} {'cells':>8s}  {'method':14s} {'set-up s':>9s} {'solve s':>9s} {'its':>4s} "
          f"{'memory MB':>10s}  " + "  ".join(f"per step ({s} per set-up)" for s in STEPS_PER_SETUP))
    for name in (QUICK if args.quick else args.grids or GRIDS):
        kind, shape = GRIDS[name]
        row = {"grid": name, "kind": kind, "shape": shape}
        for method in METHODS:
            proc = subprocess.run([sys.executable, __file__, "--one", name, method], capture_output=True, text=True,
                                  env=env, cwd=ROOT)
            if proc.returncode:
                raise SystemExit(f"{name} with {method} failed: {proc.stderr[-2000:]}")
            r = row[method] = json.loads(proc.stdout.strip().splitlines()[-1])
            print(f"{name:20s} {r['cells']:8d}  {r['method']:14s} {r['setup_seconds']:9.3f} {r['solve_seconds']:9.4f} "
                  f"{r['iterations']:4d} {r['peak_memory_bytes'] / 1e6:10.1f}  "
                  + "  ".join(f"{amortized(r, s):22.4f}" for s in STEPS_PER_SETUP)
                  + ("" if r["converged"] else f"  NOT CONVERGED (residual {r['residual']:.2e})"))
        result["rows"].append(row)
    result["direct_wins_up_to_cells"] = {str(s): crossover(result["rows"], s) for s in STEPS_PER_SETUP}
    result["load_average_after"] = os.getloadavg()
    for s, wins in result["direct_wins_up_to_cells"].items():
        print(f"the factorization is cheaper per step ({s} steps per set-up) up to: "
              + ", ".join(f"{kind} {cells:,} cells" for kind, cells in wins.items()))
    print(f"load average before {result['load_average_before'][0]:.2f}, after {result['load_average_after'][0]:.2f}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=1))
    print(f"wrote {args.output}")
    return result


if __name__ == "__main__":
    main()
