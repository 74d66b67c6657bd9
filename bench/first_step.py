"""The first load step of a contact scene against its size: the calibration of the rule by which
``varcouple check`` estimates how long the solid's first ``advance`` takes
(:data:`solid_fenicsx.settings.PARTICIPANT` ``contact_step``,
:func:`coupler.run.preflight.first_step`).

Each run is a shipped closure case cut to its first load step (1 MPa: the step with the most
platen solves, from the unloaded faces) at one size: ``measured_fracture`` (the 33 x 33 node
map at ``coarsen`` 2 with 5 layers, at ``coarsen`` 1 with 3 and 5 layers) and
``fracture_closure`` (``lattice`` 16 x 16 x 5); ``--large`` adds ``measured_fracture`` at
``coarsen`` 1 with 8 layers and ``fracture_closure`` at 32 x 32 x 8 (minutes each). Per run:
tetrahedra, dofs, platen solves, active-set iterations, the seconds the coupler spent in the
solid's ``advance`` (``phases_seconds.solid``), the solid process's CPU seconds over the run's
wall time (its share of a core: the machine is shared) and the advance's core seconds (the
advance's seconds times that share: what it takes on a core of its own), their ratio to the
smallest run's; then the least-squares fit ``core seconds = a (tets / 10^4)^b`` in log-log and
each run's ratio to the fit. The load average before, after and per run is recorded; the rule
is a warning's threshold, not a promise.

    .venv/bin/python bench/first_step.py [--large] [-o OUT.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.case_runs import run_edited  # noqa: E402

MEASURED = ("measured_fracture", {"stress = [1.0e6, 5.0e6, 20.0e6]": "stress = [1.0e6]"})
CLOSURE = ("fracture_closure", {"stress = [1.0e6, 2.0e6, 4.0e6, 6.0e6, 10.0e6, 15.0e6, 20.0e6]": "stress = [1.0e6]"})
#: (label, case, scene edits)
RUNS = [("measured coarsen 2, 5 layers", *MEASURED, {}),
        ("measured coarsen 1, 3 layers", *MEASURED, {"coarsen = 2 ": "coarsen = 1 ", "layers = 5": "layers = 3"}),
        ("measured coarsen 1, 5 layers", *MEASURED, {"coarsen = 2 ": "coarsen = 1 "}),
        ("closure 16 x 16 x 5", *CLOSURE, {})]
LARGE = [("measured coarsen 1, 8 layers", *MEASURED, {"coarsen = 2 ": "coarsen = 1 ", "layers = 5": "layers = 8"}),
         ("closure 32 x 32 x 8", *CLOSURE, {"lattice = [16, 16, 5] ": "lattice = [32, 32, 8] "})]
TIMEOUT = "\n[messaging]\ntimeout = 7200.0\n"


def measure(label: str, case: str, base: dict, edits: dict) -> dict:
    cpu = _children_cpu()
    code, wall, summary = run_edited(ROOT / "cases" / case, {**base, **edits}, edit=lambda text: text + TIMEOUT)
    if code != 0 or not summary["steps"]:
        raise SystemExit(f"{label}: the run ended with exit {code}, status {summary['status']!r}")
    step = summary["steps"][0]
    figures = step["figures"]["solid"]
    row = {"run": label, "exit": code, "tets": summary["sizes"]["solid"]["cells"], "dofs": int(figures["dofs"]),
           "platen_solves": int(figures["platen_solves"]),
           "active_set_iterations": int(figures["step_iterations"]),  # over every contact solve of the step
           "advance_seconds": summary["phases_seconds"]["solid"], "wall_seconds": wall,
           "solid_cpu_seconds": _children_cpu() - cpu, "load_average": os.getloadavg()}
    row["cpu_share"] = min(1.0, row["solid_cpu_seconds"] / wall)
    row["advance_core_seconds"] = row["advance_seconds"] * row["cpu_share"]
    print(f"{label:32s} {row['tets']:7d} tets {row['dofs']:7d} dofs  {row['platen_solves']:2d} platen solves  "
          f"{row['advance_seconds']:7.1f} s, {row['advance_core_seconds']:6.1f} core-s (CPU share "
          f"{row['cpu_share']:.2f}, load {row['load_average'][0]:.1f})", flush=True)
    return row


def _children_cpu() -> float:
    """CPU seconds (user + system) of the finished child processes (the solid participant)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def fit(rows: list) -> tuple[float, float]:
    """(a, b) of core seconds = a (tets / 1e4)^b, least squares in log-log."""
    x = np.log([r["tets"] / 1e4 for r in rows])
    y = np.log([r["advance_core_seconds"] for r in rows])
    b, log_a = np.polyfit(x, y, 1)
    return float(np.exp(log_a)), float(b)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--large", action="store_true", help="also the larger runs (minutes each)")
    ap.add_argument("-o", "--output", default=str(ROOT / "bench" / "results" / "first_step.json"))
    a = ap.parse_args(argv)
    meta = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "host": platform.node(),
            "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg()}
    rows = [measure(*run) for run in RUNS + (LARGE if a.large else [])]
    meta["load_average_after"] = os.getloadavg()
    base = rows[0]["advance_core_seconds"]
    coefficient, exponent = fit(rows)
    for r in rows:
        r["ratio_to_smallest"] = r["advance_core_seconds"] / base
        r["ratio_to_fit"] = r["advance_core_seconds"] / (coefficient * (r["tets"] / 1e4) ** exponent)
    print(f"fit: core seconds = {coefficient:.3g} (tets / 1e4)^{exponent:.3g}; measured / fit "
          f"{min(r['ratio_to_fit'] for r in rows):.2f} .. {max(r['ratio_to_fit'] for r in rows):.2f}")
    Path(a.output).write_text(json.dumps({"meta": meta, "runs": rows,
                                          "fit": {"coefficient": coefficient, "exponent": exponent}}, indent=2))
    print(f"saved {a.output}")


if __name__ == "__main__":
    main()
