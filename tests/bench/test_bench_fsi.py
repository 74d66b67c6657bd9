"""Smoke run of the FSI benchmark (bench/fsi.py --quick): small_fracture one step with IQN-ILS
and the 1-rank / 2-rank fluid on a small duct; the JSON has the goals with PASS/MISS, the
phases, the load average, and the 2-rank velocity equals the 1-rank one."""

from __future__ import annotations

import json
import shutil

import pytest

from vc_helpers import load_bench


@pytest.mark.skipif(shutil.which("simpleFoam") is None or shutil.which("mpirun") is None,
                    reason="OpenFOAM or mpirun not installed")
def test_quick_run_writes_goals_and_phases(tmp_path, capsys):
    bench = load_bench("fsi")
    out = tmp_path / "fsi.json"
    bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "goal iqn_ils_iterations_per_step" in printed and ("PASS" in printed or "MISS" in printed)
    data = json.loads(out.read_text())
    for key in ("date", "platform", "cpu_count", "load_average_before", "load_average_after", "goals", "tolerance"):
        assert key in data, key
    assert data["tolerance"] == 1e-6
    r = data["runs"]["iqn-ils"]
    assert r["status"] == "completed" and r["converged"] == [True] and r["exit_code"] == 0
    for phase in ("fluid_seconds", "solid_seconds", "transfer_seconds", "messaging_seconds"):
        assert r[phase] > 0, phase
    assert set(r["goals"]) == {"transfer_and_messaging_share", "iqn_ils_iterations_per_step"}
    assert all(g["status"] in ("PASS", "MISS") for g in r["goals"].values())
    ranks = data["parallel"]["fluid_alone"]["runs"]
    assert [x["ranks"] for x in ranks] == [1, 2] and all(x["converged"] for x in ranks)
    assert ranks[1]["max_velocity_difference_to_1_rank"] < 1e-9
