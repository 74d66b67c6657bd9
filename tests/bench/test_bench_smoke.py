"""Smoke run of the transfer benchmark (bench/transfer.py --quick): every code path on tiny
meshes, the JSON has every section and its times are positive."""

from __future__ import annotations

import json
import time

import numpy as np

import pytest

from vc_helpers import load_bench


@pytest.fixture(scope="module")
def bench():
    return load_bench("transfer")


def _positive(value, where):
    assert isinstance(value, (int, float)) and value > 0, f"{where}: {value!r}"


def test_quick_run_writes_every_figure(bench, tmp_path, capsys):
    out = tmp_path / "t.json"
    start = time.perf_counter()
    returned = bench.main(["--quick", "-o", str(out), "--threads", "1", "2"])
    elapsed = time.perf_counter() - start
    assert elapsed < 20, f"--quick took {elapsed:.1f} s"
    printed = capsys.readouterr().out
    assert "PASS" in printed or "MISS" in printed
    data = json.loads(out.read_text())
    assert data["p1p1"][0]["size"] == returned["p1p1"][0]["size"] == "quick"

    for key in ("meta", "args", "reference", "goals", "end_to_end", "p1p1", "grid", "accuracy", "threads"):
        assert key in data, key
    e2e = data["end_to_end"][0]
    for phase in ("read", "search", "solve", "write"):
        _positive(e2e["phases"][phase], f"end_to_end phase {phase}")
    for stage in ("reject", "clip", "integrate", "rows_and_csr"):  # differences of two timings: tiny, noisy
        assert np.isfinite(e2e["phases"][stage]), stage
    _positive(e2e["kernel_stages"]["kernel"], "kernel")
    _positive(e2e["kernel_stages"]["kernel_without_rejection"], "kernel without rejection")
    _positive(e2e["cli_seconds"], "end_to_end cli_seconds")
    assert e2e["goal"]["goal"] == 5.0 and (e2e["goal"]["pass"] is None) == (not e2e["libsupermesh_parallel"]["available"])
    for key in ("date", "platform", "cpu_count", "numpy", "dolfinx", "libsupermesh"):
        assert key in data["meta"], key
    assert data["reference"]["libsupermesh_48k_x_83k_seconds"] == 4.9
    assert data["reference"]["source"].startswith("issue #2")

    (p,) = data["p1p1"]
    for key in ("assembly_seconds", "wall_seconds", "target_tets_per_second"):
        _positive(p[key], key)
    assert p["pairs_tested"] >= p["pairs_intersected"] > 0
    assert abs(p["B_sum_minus_volume"]) < 1e-12
    ours = p["mass_matrix"]["ours"]
    _positive(ours["seconds"], "ours mass matrix")
    _positive(p["ratio_to_mass_ours"], "ratio to ours")
    dolfinx = p["mass_matrix"]["dolfinx"]
    if dolfinx["available"]:
        _positive(dolfinx["seconds"], "dolfinx mass matrix")
        _positive(p["ratio_to_mass_dolfinx"], "ratio to dolfinx")
        assert abs(dolfinx["sum_of_entries"] - 1.0) < 1e-12
        assert p["headline_baseline"] == "dolfinx"
    else:
        assert dolfinx["reason"] and p["headline_baseline"] == "ours"
    lsm = p["libsupermesh"]
    if lsm["available"]:
        _positive(lsm["seconds"], "libsupermesh")
        assert lsm["max_rel_difference_to_ours"] < 1e-10
    else:
        assert lsm["reason"]
    for name in ("target_tets_per_second_per_core", "ratio_to_mass_matrix"):
        assert isinstance(p["goals"][name]["pass"], bool)
    for method in ("l2", "pseudo_l2"):
        t = p["transfer"][method]
        for key in ("assembly_seconds", "setup_seconds", "apply_seconds", "total_seconds"):
            _positive(t[key], f"{method} {key}")
        assert t["conservation_error"] < 1e-10

    grid = data["grid"]
    assert [c["name"] for c in grid["cases"]] == ["P0 tet -> Q0 grid", "P1 tet -> Q1 grid", "Q1 grid -> P1 tet"]
    for case in grid["cases"]:
        _positive(case["assembly_seconds"], case["name"])
        _positive(case["grid_cells_per_second"], case["name"])
    assert grid["cases"][0]["volume_fractions"]["relative_error_vs_box_volume"] < 1e-12

    p1 = data["accuracy"]["p1p1"]["rows"]
    assert [r["quadrature_degree"] for r in p1] == ["exact", 1, 2, 3, 4, 5]
    assert p1[0]["B_rel_max_error"] == 0.0
    assert all(r["B_rel_max_error"] < 1e-12 for r in p1 if r["quadrature_degree"] != 1)  # P1 x P1: degree 2 exact
    q1 = data["accuracy"]["grid_q1_p1"]["rows"]
    assert [r["quadrature_degree"] for r in q1] == [1, 2, 3, 4, 5, 6]
    assert q1[0]["B_rel_max_error"] > 1e-6  # inexact quadrature changes the result
    for r in p1 + q1:
        _positive(r["assembly_seconds"], f"accuracy {r['quadrature_degree']}")

    (threads,) = data["threads"]
    assert [r["nthreads"] for r in threads["rows"]] == [1, 2]
    for r in threads["rows"]:
        _positive(r["assembly_seconds"], f"{r['nthreads']} threads")
        _positive(r["speedup"], f"{r['nthreads']} threads")
