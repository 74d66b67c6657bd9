"""Smoke run of the half-space benchmark (bench/halfspace.py --quick): an 8 x 8 map, one block
shape, 1 and 5 MPa: the table, the goals' PASS/MISS, the load average and every figure."""

import json

import pytest

pytest.importorskip("tamaas", reason="tamaas (the half-space reference) is not installed: scripts/install.sh installs it")

from vc_helpers import load_bench  # noqa: E402


def test_quick_run_writes_the_comparison(tmp_path, capsys):
    bench = load_bench("halfspace")
    out = tmp_path / "halfspace.json"
    returned = bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "mean aperture within 5%" in printed and ("PASS" in printed or "MISS" in printed)
    data = json.loads(out.read_text())
    assert data["meta"]["load_average_before"] and data["meta"]["load_average_after"]
    (level,) = data["levels"]
    assert level["cells"] == 8 and level["layers"] == 2 and level["height"] == pytest.approx(0.01)
    assert [r["stress"] for r in level["steps"]] == [pytest.approx(s, rel=2e-3) for s in (1e6, 5e6)]
    for row in level["steps"]:
        assert row["mean_aperture"] > 0 and row["mean_aperture_halfspace"] > 0
        assert row["error_mean_aperture"] == pytest.approx(row["mean_aperture"] / row["mean_aperture_halfspace"] - 1)
        assert row["platen_displacement"] > row["closure"] > 0 and row["closure_halfspace"] > 0
    assert len(level["area_slopes"]) == len(level["area_slopes_halfspace"]) == 1
    assert [r["refine"] for r in data["resolved_halfspace"]] == [1, 2]
    assert data["resolved_halfspace"][0]["mean_aperture"] == pytest.approx(
        [r["mean_aperture_halfspace"] for r in level["steps"]], rel=1e-6)
    goal = data["goals"]["mean_aperture_within_5_percent_thick_blocks"]
    assert goal["status"] == ("PASS" if goal["worst"] <= 0.05 else "MISS")
    assert returned["goals"] == data["goals"]
