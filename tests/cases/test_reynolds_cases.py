"""The Reynolds fluid in the shipped flow cases by the one line ``participant = "reynolds"``
(small grids): every case it can represent runs (the cases with dynamics it refuses at check,
tests/fluid_reynolds); against the 3D Chorin fluid it matches the immersed plates and
overestimates the flow of the rough fracture (the local cubic law's known bias: the flow
follows the throats in 3D, the plane sees their mean)."""

from __future__ import annotations

import json

import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

ONE_LINE = {"openfoam": 'participant = "openfoam"', "chorin": 'participant = "chorin"'}
#: case -> (its fluid now, the edits that make it small)
SMALL = {
    "parallel_plates": ("openfoam", {}),
    "lubrication": ("chorin", {}),
    "plates_fsi": ("openfoam", {}),
    "small_fracture": ("openfoam", {}),
    "fracture_flow": ("openfoam", {"shape = [41, 21, 10]": "shape = [21, 11, 10]"}),
    "hm_fracture": ("chorin", {"shape = [16, 16, 53]": "shape = [8, 8, 53]"}),
    "hm_fracture_paper": ("chorin", {"lattice = [24, 24, 4]": "lattice = [8, 8, 2]"}),  # slow: 32 x 32 columns
}


def run(case: str, fluid: str, tmp_path, edits: dict) -> dict:
    now, small = SMALL[case]
    scene = copy_case(CASES / case, tmp_path / fluid, {**small, **edits,
                                                       ONE_LINE[now]: f'participant = "{fluid}"'})
    out = tmp_path / fluid / "out"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VARCOUPLE_PICTURES", "0")
        code = main(["run", str(scene), "-o", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0 and summary["status"] == "completed", (case, fluid, summary.get("error"))
    return summary


def check_run(summary: dict) -> None:
    """Every fluid solve converged, the [check] passed, the fracture's figures there (percolating:
    a flow)."""
    if summary.get("check"):
        assert summary["check"]["passed"], summary["check"]
    for step in summary["steps"]:
        assert all(s["converged"] for s in step["solves"]["fluid"])
        if "fracture" in step:  # the coupler's figures, as with the 3D fluids
            f = step["fracture"]
            assert 0 < f["mechanical_aperture"] and (f["flow_rate"] > 0) == f["percolating"]


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c == "hm_fracture_paper" else c
                                  for c in sorted(SMALL) if c not in ("hm_fracture", "parallel_plates")])
def test_every_flow_case_it_can_represent_runs_by_the_one_line(case, tmp_path):
    """(hm_fracture and parallel_plates: in the comparisons below.)"""
    check_run(run(case, "reynolds", tmp_path, {}))


def test_the_plates_match_the_3d_fluid(tmp_path):
    """The plates (8 cells across, offset 0.25): the Reynolds flow is the cubic law's, the Chorin
    fluid's within its own 5 % of it."""
    plates = {}
    for fluid in ("reynolds", "chorin"):
        budget = {} if fluid == "reynolds" else {"max_iterations = 5000\n": ""}  # simpleFoam's, not Chorin's
        summary = run("parallel_plates", fluid, tmp_path, budget)
        check_run(summary)
        plates[fluid] = summary["check"]["relative_difference"]
    assert abs(plates["reynolds"]) < 1e-9 and abs(plates["chorin"]) < 0.05


@pytest.mark.slow
def test_the_rough_fracture_flows_more_than_in_3d(tmp_path):
    """The rough fracture (hm_fracture, 8 x 8 columns, 10 cells across): the Reynolds flow exceeds
    the 3D Chorin flow at every stress by more than 10 %, on the same mechanical aperture (slow: the
    3D fluid's run, about 10 s on a quiet machine, 150 s on a loaded one)."""
    rough = {}
    for fluid in ("reynolds", "chorin"):
        summary = run("hm_fracture", fluid, tmp_path, {})
        check_run(summary)
        rough[fluid] = [s["fracture"] for s in summary["steps"]]
    for reynolds, chorin in zip(rough["reynolds"], rough["chorin"]):
        assert reynolds["mechanical_aperture"] == pytest.approx(chorin["mechanical_aperture"], rel=0.02)
        assert reynolds["flow_rate"] > 1.1 * chorin["flow_rate"]
        assert reynolds["hydraulic_aperture"] > chorin["hydraulic_aperture"]


def test_a_fracture_closed_below_the_open_path_gives_no_flow_and_the_warning(tmp_path):
    """The soft rock of tests/cases/test_hm_fracture.py, closed at 4 MPa: Q = 0, e_h = 0 and the
    coupler's percolation warning, as with the 3D fluids."""
    soft = {"E = 1.0e10": "E = 3.0e8", "shape = [8, 8, 53]": "shape = [8, 8, 27]",
            "upper = [0.02, 0.02, 0.00031]": "upper = [0.02, 0.02, 0.00032]"}
    summary = run("hm_fracture", "reynolds", tmp_path, soft)
    last = summary["steps"][-1]["fracture"]
    assert not last["percolating"] and last["flow_rate"] == 0.0 and last["hydraulic_aperture"] == 0.0
    assert any("no connected open path" in w for w in summary["warnings"])


def test_a_fracture_on_the_reynolds_fluid_says_why_e_h_has_no_error_estimate(tmp_path):
    """The plane has no grid across the gap to coarsen: no coarse flow rate, no number; the step's
    figures name the fluid and the reason (hm_fracture at 1 MPa, 8 x 8 columns)."""
    summary = run("hm_fracture", "reynolds", tmp_path, {"stress = [1.0e6, 2.0e6, 4.0e6]": "stress = [1.0e6]",
                                                         "steps = 3": "steps = 1"})
    f = summary["steps"][0]["fracture"]
    assert f["hydraulic_aperture"] > 0 and "hydraulic_aperture_error" not in f
    reason = "the fluid participant 'reynolds' gives no coarse_flow_rate"
    assert f["hydraulic_aperture_error_missing"].startswith(reason)


@pytest.mark.slow
def test_the_frontier_study_records_both_models(tmp_path):
    """``varcouple study`` over the two models and two grids across the gap (hm_fracture at 1 MPa on
    8 x 8 columns, the Chorin fluid by its Newton steady solve; slow: four coupled runs, about 40 s
    on a loaded machine): every run recorded with its model and e_h, the reference the finest 3D
    run (the largest cost, and of the two at that cost the longer: the 3D one), the Reynolds e_h
    above the 3D one on both grids, and study.png drawn."""
    case = copy_case(CASES / "hm_fracture", tmp_path, {"stress = [1.0e6, 2.0e6, 4.0e6]": "stress = [1.0e6]",
                                                       "steps = 3": "steps = 1"})
    out = tmp_path / "study"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VARCOUPLE_PICTURES", "0")
        code = main(["study", str(case), "--vary",
                     'solvers.fluid=[{participant="reynolds"}, {participant="chorin", steady="newton"}]',
                     "--vary", "geometry.fluid.shape=[[8, 8, 22], [8, 8, 43]]",
                     "--figure", "fracture.hydraulic_aperture", "-o", str(out)])
    study = json.loads((out / "study.json").read_text())
    assert code == 0 and study["status"] == "completed", study
    models = [run["values"]["solvers.fluid"]["participant"] for run in study["runs"]]
    assert models == ["reynolds", "reynolds", "chorin", "chorin"]
    assert study["error"]["reference"] == "run_04"
    e_h = [run["figure"][0] for run in study["runs"]]
    assert all(e > 0 for e in e_h) and min(e_h[:2]) > max(e_h[2:])
    assert study["runs"][3]["error"] == 0.0 and all(run["error"] > 0 for run in study["runs"][:3])
    assert (out / "study.png").stat().st_size > 0
