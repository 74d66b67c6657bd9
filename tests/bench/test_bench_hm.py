"""Smoke run of the hydro-mechanical fracture benchmark (bench/hm.py --quick): one stress on
8 x 8 columns, the grid refined across the gap (4 and 8 cells across): iterations with the
goal's PASS/MISS, the phases, errors against the finest run (zero for itself) and the PNG."""

import json

import pytest

from vc_helpers import load_bench


def test_quick_run_writes_iterations_phases_and_error_against_cost(tmp_path, capsys):
    bench = load_bench("hm")
    out = tmp_path / "hm.json"
    bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "goal iqn_ils_iterations_per_stress" in printed and ("PASS" in printed or "MISS" in printed)
    data = json.loads(out.read_text())
    shipped = data["iterations"]
    assert shipped["status"] == "completed" and shipped["stress"] == [pytest.approx(1e6, rel=5e-3)]
    assert shipped["phases_seconds"]["fluid"] > 0 and shipped["phases_seconds"]["solid"] > 0
    goal = data["goals"]["iqn_ils_iterations_per_stress"]
    assert goal["value"] == max(shipped["iterations"]) and goal["status"] == ("PASS" if goal["value"] <= 8 else "MISS")
    rows = data["refinement"]
    assert [r["cells_across_initial_aperture"] for r in rows] == [4, 8]
    assert rows[0]["fluid_cells"] == 8 * 8 * 22 and rows[1]["fluid_cells"] == 8 * 8 * 43  # 25 and 12.5 um cells
    assert rows[-1]["error_hydraulic_aperture"] == [0.0] and rows[0]["error_hydraulic_aperture"][0] > 0
    # the mean open aperture in fluid cells doubles with the cells across
    ratio = rows[1]["fracture"][0]["cells_across"] / rows[0]["fracture"][0]["cells_across"]
    assert ratio == pytest.approx(25 / 12.5, rel=0.05)
    assert (tmp_path / "hm.png").stat().st_size > 10_000
