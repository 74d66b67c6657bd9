"""Smoke run of bench/transfer_mpi.py --quick: ours on 1 and 2 MPI ranks (and libsupermesh's
parallel driver when installed), the efficiency against the goal, what travels per rank."""

from __future__ import annotations

import json
import shutil

import pytest

from vc_helpers import load_bench


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_quick_run_writes_both_rank_counts(tmp_path, capsys):
    bench = load_bench("transfer_mpi")
    out = tmp_path / "t.json"
    bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "PASS" in printed or "MISS" in printed
    data = json.loads(out.read_text())
    ours = data["ours"]
    assert set(ours) == {"1", "2"} and data["goal_efficiency"] == 0.9
    for ranks, run in ours.items():
        assert run["ranks"] == int(ranks) and len(run["per_rank"]) == int(ranks)
        assert run["seconds"]["assemble"] > 0 and run["pairs_intersected"] == ours["1"]["pairs_intersected"]
    one, two = ours["1"]["per_rank"], ours["2"]["per_rank"]
    assert one[0]["cells_received"] == 0 and all(p["cells_received"] > 0 for p in two)
    # every target cell has one owner; a rank sends what the other receives
    assert sum(p["target_cells"] for p in two) == one[0]["target_cells"]
    assert two[0]["cells_sent"] == two[1]["cells_received"] and two[0]["bytes_sent"] == two[1]["bytes_received"]
    assert data["efficiency"]["ours"] > 0


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_quick_cli_run_compares_every_input_on_one_and_two_ranks(tmp_path, capsys):
    """`varcouple transfer` end to end on the tiny pair (.vtu, .pvtu, .xdmf target): every output
    equal to the serial one, what each rank read, ratios against the same inputs on one rank."""
    pytest.importorskip("dolfinx")
    bench = load_bench("transfer_mpi")
    out = tmp_path / "c.json"
    bench.main(["--cli", "--quick", "-o", str(out)])
    assert "against pvtu_1" in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert set(data["runs"]) == {"vtu_1", "vtu_2", "pvtu_1", "pvtu_2", "xdmf_1", "xdmf_2"}
    assert all(ok["equal"] for ok in data["pass"].values())
    cells = data["source_tets"] + data["target_tets"]
    for label in ("pvtu_2", "xdmf_2"):  # each rank read its share of both meshes, no more
        read = data["runs"][label]["best"]["cells_read"]
        assert sum(read) == cells and max(read) <= 0.6 * cells
        assert len(data["runs"][label]["best"]["cpu_seconds"]) == 2
    assert set(data["speedup_same_input"]) == set(data["memory_ratio_same_input"]) == {"vtu_2", "pvtu_2", "xdmf_2"}
