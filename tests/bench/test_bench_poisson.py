"""Smoke run of the pressure Poisson benchmark (bench/poisson.py --quick): a cube and a fracture
slab of about 14k cells, each method in a process of its own; the factorization wins on the
fracture slab (CG + GAMG needs tens of iterations there, one on the cube's scale of 10)."""

import json

from vc_helpers import load_bench


def test_quick_run_measures_both_methods_and_the_crossover(tmp_path, capsys):
    bench = load_bench("poisson")
    out = tmp_path / "poisson.json"
    bench.main(["--quick", "-o", str(out)])
    assert "the factorization is cheaper per step" in capsys.readouterr().out
    data = json.loads(out.read_text())
    rows = {r["grid"]: r for r in data["rows"]}
    assert list(rows) == ["cube 24^3", "fracture 16x16x53"]
    for row in rows.values():
        assert row["direct"]["method"] == "Cholesky" and row["gamg"]["method"] == "CG + GAMG"
        assert row["direct"]["converged"] and row["gamg"]["converged"] and row["direct"]["iterations"] == 1
        assert all(row[m]["setup_seconds"] > 0 and row[m]["solve_seconds"] > 0 for m in ("direct", "gamg"))
    assert rows["fracture 16x16x53"]["gamg"]["iterations"] > rows["cube 24^3"]["gamg"]["iterations"]
    wins = data["direct_wins_up_to_cells"]["200"]
    assert wins["fracture"] == rows["fracture 16x16x53"]["direct"]["cells"]
