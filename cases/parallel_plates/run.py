"""Immersed parallel plates against the cubic law: accuracy against cost.

    .venv/bin/python cases/parallel_plates/run.py [--resolutions 4 8 16 32] [--quick]

For each resolution (cells across the aperture) and each fraction handling (binary
centre mask; exact fractions with the stock linear drag table, with D_max f^3, and with
the sub-cell wall drag; see fluid_openfoam/plates.py), runs the fluid alone at several
offsets of the plates against the grid lines and writes

    results/summary.json   every run, and per (method, resolution): the error at offset
                           0.3, the worst |error| over the offsets, the mean wall time
    results/plates.png     |error| (worst and at offset 0.3) and wall time against cells across
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

from fluid_openfoam import plates  # noqa: E402

OFFSETS = (0.0, 0.25, 0.3, 0.5, 0.75)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[4, 8, 16, 32])
    ap.add_argument("--methods", nargs="+", default=list(plates.METHODS))
    ap.add_argument("--offsets", type=float, nargs="+", default=list(OFFSETS))
    ap.add_argument("--output", type=Path, default=HERE / "results")
    args = ap.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    runs, table = [], []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="plates-") as tmp:
        for method in args.methods:
            for n in args.resolutions:
                rs = [plates.run(n, method, off, Path(tmp) / f"{method}-{n}-{off}") for off in args.offsets]
                runs += rs
                ref = min(rs, key=lambda r: abs(r["offset"] - 0.3))
                row = {"method": method, "n_across": n, "cells": rs[0]["cells"],
                       "error_offset_0.3": ref["error"],
                       "error_worst": max((r["error"] for r in rs), key=abs),
                       "error_min": min(r["error"] for r in rs), "error_max": max(r["error"] for r in rs),
                       "time_total_mean": sum(r["time_total"] for r in rs) / len(rs),
                       "time_solve_mean": sum(r["time_solve"] for r in rs) / len(rs),
                       "time_fractions_mean": sum(r["time_fractions"] for r in rs) / len(rs),
                       "all_converged": all(r["converged"] for r in rs)}
                table.append(row)
                print(f"{method:7s} {n:3d} across: error {row['error_offset_0.3']:+.4%} at offset 0.3, "
                      f"worst {row['error_worst']:+.4%} over offsets {args.offsets}, "
                      f"{row['time_total_mean']:.2f} s per run (solve {row['time_solve_mean']:.2f} s)", flush=True)
    summary = {"case": "parallel_plates", "cubic_law": "Q = w^3 dp / (12 mu L)",
               "w": plates.W, "L": plates.L, "dp": plates.DP, "mu": plates.MU, "rho": plates.RHO,
               "nx": plates.NX, "offsets": args.offsets, "table": table, "runs": runs,
               "wall_time": time.perf_counter() - t_start}
    (args.output / "summary.json").write_text(json.dumps(summary, indent=1))
    plot(table, args.output / "plates.png")
    print(f"wrote {args.output / 'summary.json'} and plates.png ({summary['wall_time']:.1f} s)")


def plot(table, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    label = {"binary": "binary centre mask", "linear": "exact fractions, linear drag",
             "power": "exact fractions, D_max f^3", "wall": "exact fractions, sub-cell wall drag"}
    for m in dict.fromkeys(r["method"] for r in table):
        rows = [r for r in table if r["method"] == m]
        n = [r["n_across"] for r in rows]
        line, = a.loglog(n, [abs(r["error_worst"]) for r in rows], "o-", label=label.get(m, m))
        a.loglog(n, [abs(r["error_offset_0.3"]) for r in rows], "x--", color=line.get_color(), lw=0.8)
        b.loglog(n, [r["time_total_mean"] for r in rows], "o-", label=label.get(m, m))
    a.axhline(0.05, color="k", ls=":", lw=1)
    a.axvline(8, color="k", ls=":", lw=1)
    a.set(xlabel="cells across the aperture", ylabel="|Q / Q_cubic - 1|",
          title="accuracy: worst over offsets (solid), offset 0.3 (dashed)")
    b.set(xlabel="cells across the aperture", ylabel="wall time per run (s)", title="cost (setup + solve)")
    a.legend(fontsize=8)
    for ax in (a, b):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
