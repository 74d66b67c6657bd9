"""Smoke run of the grading benchmark (bench/grading.py --quick): a 16 x 16 map meshed uniform
and graded at coarsen 2 and 1, the closures of both at 1 and 2 MPa: the table, the goals'
PASS/MISS, the load average and every figure."""

import json

import pytest

pytest.importorskip("tamaas", reason="tamaas (the half-space reference) is not installed: scripts/install.sh installs it")

from vc_helpers import load_bench  # noqa: E402


def test_quick_run_writes_the_meshes_and_the_closures(tmp_path, capsys):
    out = tmp_path / "grading.json"
    load_bench("grading").main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "graded dofs at most the uniform mesh's" in printed and ("PASS" in printed or "MISS" in printed)
    data = json.loads(out.read_text())
    assert data["meta"]["load_average_before"] and data["meta"]["load_average_after"]
    assert [m["coarsen"] for m in data["meshes"]] == [2, 1]
    for m in data["meshes"]:
        assert m["graded"]["worst_quality"] > 0.3 and m["uniform"]["dofs"] > 0
        assert m["dofs_graded_over_uniform"] == pytest.approx(m["graded"]["dofs"] / m["uniform"]["dofs"])
    c = data["closures"]
    assert c["coarsen"] == 2 and c["graded"]["dofs"] < c["uniform"]["dofs"]
    for u, g, d in zip(c["uniform"]["steps"], c["graded"]["steps"], c["graded_against_uniform"]):
        assert u["contact_solves"] == g["contact_solves"] == 1  # the platen as an unknown
        assert d["mean_aperture"] == pytest.approx(g["mean_aperture"] / u["mean_aperture"] - 1)
    for goal in data["goals"].values():
        assert goal["status"] in ("PASS", "MISS")
