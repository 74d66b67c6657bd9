"""FSI benchmark (issue 4): wall time per phase (fluid, solid, transfer incl. the geometry
update of the two-way coupling, messaging) and coupling iterations per step for constant
relaxation, Aitken and IQN-ILS, on a coupled case (default cases/small_fracture; the issue
asks for cases/fracture_flow, not made yet). Each accelerator runs the case once through
``varcouple run`` into a temporary directory; ``--summary FILE`` instead only reports one
existing run's summary.json.

    .venv/bin/python bench/fsi.py [--case cases/small_fracture] [--relaxation 1.0]
        [--set "E = 2.0e5=E = 5.0e3" ...] [-o bench/results/fsi.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


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


def run_case(case: Path, acceleration: str, relaxation: float, replace: dict) -> dict:
    from coupler.cli import main

    with tempfile.TemporaryDirectory(prefix="varcouple-bench-fsi-") as tmp:
        copy = Path(tmp) / "case"
        shutil.copytree(case, copy, ignore=shutil.ignore_patterns("results"))
        scene = (copy / "scene.toml").read_text()
        for old, new in replace.items():
            if old not in scene:
                raise SystemExit(f"--set: {old!r} not in {case / 'scene.toml'}")
            scene = scene.replace(old, new)
        lines = [ln for ln in scene.splitlines() if not ln.startswith(("acceleration =", "relaxation ="))]
        i = lines.index("[coupling]")
        lines[i + 1:i + 1] = [f'acceleration = "{acceleration}"', f"relaxation = {relaxation}"]
        (copy / "scene.toml").write_text("\n".join(lines) + "\n")
        out = Path(tmp) / "out"
        start = time.perf_counter()
        code = main(["run", str(copy), "--output", str(out)])
        result = report(json.loads((out / "summary.json").read_text()))
        result.update(exit_code=code, measured_seconds=time.perf_counter() - start)
        return result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="cases/small_fracture", help="case directory (relative to the repository)")
    ap.add_argument("--accelerations", nargs="+", default=["constant", "aitken", "iqn-ils"])
    ap.add_argument("--relaxation", type=float, default=1.0)
    ap.add_argument("--set", action="append", default=[], metavar="OLD=NEW",
                    help="text replacement in the scene (e.g. a softer rock)")
    ap.add_argument("--summary", help="only report this existing summary.json")
    ap.add_argument("-o", "--output", default=str(ROOT / "bench" / "results" / "fsi.json"))
    a = ap.parse_args(argv)
    if a.summary:
        result = {"summary": a.summary, **report(json.loads(Path(a.summary).read_text()))}
    else:
        replace = {}
        for s in a.set:  # "E = 2.0e5=E = 5.0e3": split at the '=' between the two sides
            parts = s.split("=")
            half = len(parts) // 2
            replace["=".join(parts[:half])] = "=".join(parts[half:])
        result = {"case": a.case, "relaxation": a.relaxation, "replace": replace, "platform": platform.platform(),
                  "runs": {acc: run_case(ROOT / a.case, acc, a.relaxation, replace) for acc in a.accelerations}}
        for acc, r in result["runs"].items():
            print(f"{acc:9s} iterations/step {r['iterations_per_step']}  wall {r['wall_seconds']:.1f} s  "
                  f"fluid {r['fluid_seconds']:.1f}  solid {r['solid_seconds']:.2f}  transfer {r['transfer_seconds']:.2f} "
                  f"(geometry update {r['geometry_update_seconds']:.2f})  messaging {r['messaging_seconds']:.2f}  "
                  f"transfer+messaging {100 * r['transfer_and_messaging_share']:.1f} %")
    out = Path(a.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=float))
    print(f"written {out}")


if __name__ == "__main__":
    main()
