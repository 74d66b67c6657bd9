"""bench/eh_error.py's pieces that need no run: the converged e_h (the truth the estimate is
measured against, as cases/hm_fracture/README.md states it) and the fluid log's per-solve
seconds, fine and coarse apart."""

import json

import pytest

from vc_helpers import ROOT, load_bench


def test_the_truth_is_the_converged_e_h_of_each_penalization():
    """penalization "wall": the study's extrapolated e_h; "lubrication": bench/hm.py --converged's."""
    bench = load_bench("eh_error")
    study = json.loads((ROOT / "bench" / "results" / "hm_fracture_across_study.json").read_text())
    assert [1e6 * e for e in bench.converged(study)] == pytest.approx([80.0, 70.77, 56.03], abs=0.01)
    record = json.loads((ROOT / "bench" / "results" / "hm_converged.json").read_text())
    assert [1e6 * e for e in bench.converged_lubrication(record)] == pytest.approx([80.37, 71.69, 58.06], abs=0.01)


def test_the_coarse_solves_seconds_are_told_apart_in_the_fluid_log(tmp_path):
    bench = load_bench("eh_error")
    (tmp_path / "logs").mkdir()
    prefix = "2026-11-28 23:38:45,126 fluid[0] INFO varcouple.fluid_chorin: window 0 iteration 1: "
    (tmp_path / "logs" / "fluid.log").write_text("\n".join([
        prefix + "chorin steady Newton, 3 iterations, residual 1.1e-08, 0 Poisson solves, 8.500 s",
        prefix + "chorin steady Newton on the grid coarsened 2x across z (error estimate), 2 iterations, "
                 "residual 2e-08, 0 Poisson solves, 3.250 s",
        prefix + "chorin pseudo-time, 384 iterations, residual 9.8e-08, 384 Poisson solves, 1.5 s",
        "steady Newton step 4 of at most 30: change 3.37e-08 (tolerance 1e-07), 1 preconditioners built"]))
    assert bench.solve_seconds(tmp_path) == {"fine": 10.0, "coarse": 3.25}
