"""Runs of a shipped case with its scene edited, for the benchmarks: the case copied into a
temporary directory (without its results), the text replacements applied to its scene.toml
(each must occur), ``varcouple run`` on the copy, and what the run left in summary.json."""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path


def run_edited(case: Path, replace: dict, edit=None, prefix: str = "varcouple-bench-",
               inspect=None) -> tuple[int, float, dict]:
    """(exit code, wall seconds, summary) of ``varcouple run`` on a copy of `case` whose scene has
    every {old: new} of `replace` applied, then ``edit(text) -> text`` when given; ``inspect(out)``
    reads the run's output directory (its logs) before it is removed."""
    from coupler.cli import main

    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        copy = Path(tmp) / Path(case).name
        shutil.copytree(case, copy, ignore=shutil.ignore_patterns("results"))
        scene = (copy / "scene.toml").read_text()
        for old, new in replace.items():
            if old not in scene:
                raise SystemExit(f"{Path(case) / 'scene.toml'}: no {old!r} to replace")
            scene = scene.replace(old, new)
        (copy / "scene.toml").write_text(edit(scene) if edit else scene)
        out = Path(tmp) / "out"
        start = time.perf_counter()
        code = main(["run", str(copy), "--output", str(out)])
        seconds = time.perf_counter() - start
        if inspect is not None:
            inspect(out)
        return code, seconds, json.loads((out / "summary.json").read_text())
