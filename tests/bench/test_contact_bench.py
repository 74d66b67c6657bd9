"""Smoke run of the contact benchmark (bench/contact.py --quick): both problems, both
solvers, every figure in the JSON, the solvers agreeing on the same problems; the cost of a
stress with the AMG set up from scratch and reused, the same closures; the platen as one more
unknown in one contact solve per stress, its closures those of the search within its tolerance."""

import json

import pytest

from vc_helpers import load_bench

pytest.importorskip("gmsh")


def test_quick_run_writes_every_figure(tmp_path, capsys):
    bench = load_bench("contact")
    out = tmp_path / "c.json"
    bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "PASS" in printed or "MISS" in printed
    data = json.loads(out.read_text())
    assert {"meta", "args", "hertz", "fracture", "goals", "stress"} <= set(data)
    assert "load_average_before" in data["meta"] and "load_average_after" in data["meta"]
    for problem in ("hertz", "fracture"):
        levels = data[problem]
        assert len(levels) == 2 and levels[0]["dofs"] < levels[1]["dofs"]
        for level in levels:
            assert level["solver_difference"] < 1e-8  # the same problem, solved twice
            for solver in ("active_set", "snes_vi"):
                figures = level[solver]
                assert len(figures["iterations"]) == len(figures["steps"]) == 2
                assert figures["wall_seconds"] > 0 and figures["krylov_iterations"] > 0
        for goal in ("active_set_iterations_do_not_grow", "time_2x_below_snes_vi_at_finest"):
            assert data["goals"][problem][goal]["status"] in ("PASS", "MISS")
    assert [lv["case"] for lv in data["stress"]] == ["fracture_closure", "measured_fracture"]
    for level in data["stress"]:
        assert level["closure_difference"] < 1e-6 and level["seconds_reported_over_wall"] > 0.9
        for name in ("from_scratch", "reused"):
            steps = level[name]["steps"]
            assert len(steps) == 2 and all(st["converged"] for st in steps)
            assert all(st["contact_solves"] >= 1 and st["step_krylov_iterations"] > 0 for st in steps)
        assert all(st["amg_setups_last_solve"] == 1 for st in level["reused"]["steps"])
        constraint = level["constraint"]["steps"]
        assert len(constraint) == 2 and all(st["converged"] and st["contact_solves"] == 1 for st in constraint)
        assert level["constraint_closure_difference"] < 1e-2 and level["constraint"]["peak_memory_mb"] > 0
        assert level["ratio_time_search_over_constraint"] > 0
    for goal in ("one_contact_solve_per_stress", "constraint_faster_than_search"):
        assert data["stress_goals"][goal]["status"] in ("PASS", "MISS")
