"""cases/hm_fracture_paper: the hydro-mechanical fracture at the paper's scale (an 80 mm square
of the 122 mm closure specimen, 2 to 20 MPa, flow at 1 MPa). The default run checks that
`varcouple check` accepts it and plans what the README says, without running it; the run itself
is slow-marked (minutes: README.md)."""

from __future__ import annotations

import json
import time

import pytest

from coupler.cli import main
from vc_helpers import CASES

CASE = CASES / "hm_fracture_paper"


def test_varcouple_check_accepts_the_paper_scale_scene_quickly(capsys):
    start = time.perf_counter()
    assert main(["check", str(CASE)]) == 0
    assert time.perf_counter() - start < 30
    out = capsys.readouterr().out
    assert "solid 17,280 cells; fluid 74,752 cells" in out
    assert "hydro-mechanical fracture (flow solver chorin" in out and "4 load steps" in out


@pytest.mark.slow
def test_the_paper_scale_run_closes_the_fracture_and_chokes_the_flow(tmp_path):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VARCOUPLE_PICTURES", "0")
        assert main(["run", str(CASE), "-o", str(tmp_path)]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    f = [step["fracture"] for step in s["steps"]]
    assert s["status"] == "completed" and len(f) == 4
    for step, stress in zip(s["steps"], (2e6, 4e6, 10e6, 20e6)):
        solid = step["figures"]["solid"]
        assert solid["stress"] == pytest.approx(stress, rel=5e-3)
        assert -solid["force_z"] + solid["fluid_force_fracture_upper_z"] == pytest.approx(solid["platen_force"],
                                                                                          rel=1e-6)
    for a, b in zip(f, f[1:]):
        assert b["mechanical_aperture"] < a["mechanical_aperture"] and b["flow_rate"] <= a["flow_rate"]
        assert b["contact_area_fraction"] >= a["contact_area_fraction"]
    assert all(x["hydraulic_aperture"] <= x["mechanical_aperture"] for x in f)
