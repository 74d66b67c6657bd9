"""Smoke run of the messaging benchmark (bench/messaging.py --quick): real processes over
TCP and shared memory; the JSON has every size, both round trip and one way, and the goal."""

from __future__ import annotations

import json

import pytest

from vc_helpers import load_bench


@pytest.fixture(scope="module")
def bench():
    return load_bench("messaging")


def test_quick_run_writes_the_table(bench, tmp_path, capsys):
    out = tmp_path / "m.json"
    assert bench.main(["--quick", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "goal (best transport): " in printed and ("PASS" in printed or "MISS" in printed)
    data = json.loads(out.read_text())
    for key in ("benchmark", "quick", "meta", "transports", "results", "goal"):
        assert key in data, key
    assert data["quick"] is True and "tcp" in data["transports"]
    sizes = [8_000, 80_000, 800_000, 8_000_000, 80_000_000]
    for transport in data["transports"]:
        for kind in ("round_trip", "one_way"):
            rows = [r for r in data["results"] if r["transport"] == transport and r["kind"] == kind]
            assert [r["size_bytes"] for r in rows] == sizes
            for r in rows:
                for k in ("min_ms", "median_ms", "MB_per_s", "repeats", "n_doubles", "shm_used"):
                    assert k in r, k
                assert 0 < r["min_ms"] <= r["median_ms"] and r["MB_per_s"] > 0
        goal = data["goal"]["per_transport"][transport]
        assert goal["status"] in ("PASS", "MISS") and goal["round_trip_median_ms"] > 0
    assert all(not r["shm_used"] for r in data["results"] if r["transport"] == "tcp")
    assert data["goal"]["status"] in ("PASS", "MISS") and data["goal"]["size_bytes"] == 8_000_000
