"""The figures of a finished case that must not change unless a change means them to: for
every VTU file a run wrote, the minimum, maximum and L2 norm of each field, and the
coupling iterations per step. They are compared with ``tests/data/case_figures.json``
by ``tests/cases/test_shipped_cases.py``.

Record them again (after a change that is meant to change results, say why in the commit)::

    .venv/bin/python tests/case_figures.py [CASE ...]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"
RECORD = Path(__file__).resolve().parent / "data" / "case_figures.json"


def _stats(values) -> list[float]:
    v = np.asarray(values, dtype=float).reshape(len(values), -1)
    finite = v[np.isfinite(v).all(axis=1)]
    return [float(finite.min()), float(finite.max()), float(np.linalg.norm(finite))] if finite.size else []


def figures(out: Path) -> dict:
    """``{file: {field: [min, max, l2]}}`` for the VTU files in `out`, and the iterations per step."""
    import meshio

    found: dict = {}
    for f in sorted(out.glob("*.vtu")):
        m = meshio.read(f)
        fields = {f"point:{k}": _stats(v) for k, v in m.point_data.items()}
        fields.update({f"cell:{k}": _stats(np.concatenate([np.asarray(b).reshape(len(b), -1) for b in v]))
                       for k, v in m.cell_data.items()})
        fields["points"] = _stats(m.points)
        found[f.name] = fields
    summary = json.loads((out / "summary.json").read_text())
    if "iterations" in summary:
        found["iterations"] = summary["iterations"]
    found["summary"] = dict(_numbers(summary))
    return found


#: summary keys whose values change from run to run (times, processes, machine) or restate the input
VOLATILE = ("seconds", "wall", "time", "pid", "run_id", "load_average", "platform", "elapsed", "phases",
            "participants_announced", "scene", "case", "outputs", "rebuild", "history", "krylov")


def _numbers(tree, path=""):
    """(path, value) of every finite number in a summary, volatile keys left out."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            if not any(word in str(k) for word in VOLATILE):
                yield from _numbers(v, f"{path}/{k}")
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from _numbers(v, f"{path}/{i}")
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool) and np.isfinite(tree):
        yield path, float(tree)


def run_case(name: str, directory: Path) -> Path:
    """Run cases/NAME into `directory`; the output directory."""
    from coupler.cli import main

    out = directory / name
    code = main(["run", str(CASES / name), "--output", str(out)])
    if code not in (0, 1):
        raise RuntimeError(f"{name}: varcouple run exited with {code}")
    return out


def record(names: list[str]) -> None:
    known = json.loads(RECORD.read_text()) if RECORD.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            known[name] = figures(run_case(name, Path(tmp)))
            print(f"recorded {name}: {len(known[name])} entries", flush=True)
    RECORD.parent.mkdir(exist_ok=True)
    RECORD.write_text(json.dumps(known, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    import os

    os.environ["VARCOUPLE_PICTURES"] = "0"  # as the tests run the cases (conftest.no_pictures): no picture figures
    record(sys.argv[1:] or sorted(p.name for p in CASES.iterdir() if (p / "scene.toml").is_file()))
