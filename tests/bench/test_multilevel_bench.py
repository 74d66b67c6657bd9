"""Smoke run of the multilevel benchmark (bench/multilevel.py --quick): every solver on levels
2 and 3 of the cube, the JSON has every section and the solvers agree."""

from __future__ import annotations

import json

from vc_helpers import load_bench


def test_quick_run_writes_every_figure(tmp_path, capsys):
    bench = load_bench("multilevel")
    out = tmp_path / "m.json"
    returned = bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "PASS" in printed or "MISS" in printed
    data = json.loads(out.read_text())
    assert (tmp_path / "m.png").stat().st_size > 0
    for key in ("meta", "args", "paper", "goals", "rows", "criterion"):
        assert key in data, key
    assert "load_average_at_start" in data["meta"]
    assert [r["levels"] for r in data["rows"]] == [r["levels"] for r in returned["rows"]] == [2, 3]
    for row in data["rows"]:
        ml = row["multilevel"]
        assert ml["converged"] and ml["step_history"][-1] < 1e-12 and ml["max_infeasibility"] == 0.0
        assert ml["setup_seconds"] > 0 and ml["solve_seconds"] > 0
        for name in ("active_set", "snes_vi"):
            assert row[name]["converged"] and row[name]["seconds"] > 0
            assert row[name]["relative_difference_to_multilevel"] < 1e-8
    for goal in data["goals"].values():
        assert isinstance(goal["pass"], bool)
