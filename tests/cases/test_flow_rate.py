"""A flow driven by a flow rate ([flow] flow_rate): the pressure difference is an unknown of the
coupling's fixed point (coupler/fsi/rate_control.py). On the immersed plates (Chorin) and on
hm_fracture (8 x 8 columns, as tests/cases/test_hm_fracture.py) a rate taken from a
pressure-driven run gives its pressure difference back; an unreachable rate, an inlet pressure
at the confining stress and a block pushed off its platen stop the run with one line."""

from __future__ import annotations

import json

import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

HM = CASES / "hm_fracture"
COARSE = {"shape = [16, 16, 53]": "shape = [8, 8, 53]"}
PLATES = {'participant = "openfoam"        # or "chorin" (drop max_iterations: a simpleFoam budget)':
          'participant = "chorin"', "max_iterations = 5000": ""}


def run(case, out, code: int = 0) -> dict:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VARCOUPLE_PICTURES", "0")
        assert main(["run", str(case), "-o", str(out)]) == code
    return json.loads((out / "summary.json").read_text())


def one_error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.strip().splitlines() if line.startswith("varcouple: error")]
    assert len(err) == 1, err
    return err[0]


def test_plates_driven_by_the_rate_of_a_pressure_driven_run_give_its_pressure_drop(tmp_path):
    """Fixed plates, aperture w = 1 mm, L = 2 mm, 8 cells across: Q of dp = 0.01 Pa asked for gives
    dp = 0.01 Pa back (Stokes: one exact step once the secant is known), and against the cubic law
    dp = 12 mu L Q / (W w^3) within the plates' discretisation error (+2 % in Q at 8 across)."""
    dp_run = run(copy_case(CASES / "parallel_plates", tmp_path / "dp", PLATES), tmp_path / "dp" / "out")
    q_per_width = dp_run["check"]["Q"]
    width = 1.0e-3 / 8  # the 2D grid's one cell along z
    rate = {**PLATES, "inlet_pressure = 1.0e-2 ": f"flow_rate = {q_per_width * width!r} #"}
    summary = run(copy_case(CASES / "parallel_plates", tmp_path / "q", rate), tmp_path / "q" / "out")
    (step,) = summary["steps"]
    control = step["flow_rate_control"]
    assert control["pressure_drop"] == pytest.approx(0.01, rel=1e-9)
    assert control["flow_rate"] == pytest.approx(q_per_width * width, rel=1e-6) and control["relative_error"] <= 1e-6
    assert summary["check"]["pressure_drop"] == pytest.approx(0.01, rel=1e-9) and summary["check"]["passed"]
    cubic = 12 * 1e-3 * 2e-3 * q_per_width / 1e-3 ** 3  # dp the cubic law needs for Q
    assert control["pressure_drop"] / cubic - 1 == pytest.approx(-0.0192, abs=1e-3)
    assert step["iterations"] <= 4


@pytest.fixture(scope="module")
def hm_pair(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hm_rate")
    dp_run = run(copy_case(HM, tmp / "dp", COARSE), tmp / "dp" / "out")
    q = dp_run["steps"][0]["fracture"]["flow_rate"]
    rate = {**COARSE, "inlet_pressure = 3.0e5 ": f"flow_rate = {q!r} #"}
    return dp_run, run(copy_case(HM, tmp / "q", rate), tmp / "q" / "out")


def test_hm_fracture_driven_by_the_first_stress_rate_gives_its_pressure_drop(hm_pair):
    """The rate of the pressure-driven run at 1 MPa: dp = 1e5 Pa back at 1 MPa with the same
    apertures; at 2 and 4 MPa the closing fracture needs more dp for the same rate; the rate is
    reached to the coupling tolerance at every stress, the fracture's figures use the dp found."""
    dp_run, rate_run = hm_pair
    first, ref = rate_run["steps"][0], dp_run["steps"][0]
    assert first["flow_rate_control"]["pressure_drop"] == pytest.approx(1e5, rel=1e-6)
    for key in ("hydraulic_aperture", "mechanical_aperture", "contact_area_fraction"):
        assert first["fracture"][key] == pytest.approx(ref["fracture"][key], rel=1e-6), key
    drops = []
    for step in rate_run["steps"]:
        control, fracture = step["flow_rate_control"], step["fracture"]
        assert step["converged"] and control["relative_error"] <= 1e-5
        assert fracture["flow_rate"] == pytest.approx(control["target"], rel=1e-5)
        assert fracture["pressure_drop"] == control["pressure_drop"]
        assert fracture["hydraulic_aperture"] ** 3 == pytest.approx(
            12 * 1.0 * fracture["flow_rate"] * 0.02 / (0.02 * control["pressure_drop"]), rel=1e-12)
        drops.append(control["pressure_drop"])
    assert drops[0] < drops[1] < drops[2] < 1e6 - 2e5


def test_a_rate_needing_the_confining_stress_stops_the_run(tmp_path, capsys):
    """Ten times the rate: the inlet pressure reaches the 1 MPa of the first step: one line naming
    the step, the inlet pressure and the stress, exit 4, nothing claimed."""
    case = copy_case(HM, tmp_path, {**COARSE, "inlet_pressure = 3.0e5 ": "flow_rate = 5.0e-8 #"})
    summary = run(case, tmp_path / "out", code=4)
    line = one_error_line(capsys)
    assert "time step 0 (t = 0 .. 1)" in line and "[flow] flow_rate: the inlet pressure" in line
    assert "reaches the confining stress 1e+06 Pa of [loads.2] stress at this step" in line
    assert "loss of contact" in line and summary["status"] == "failed" and summary["steps"] == []


def test_a_rate_through_a_closed_fracture_stops_the_run(tmp_path, capsys):
    """The soft rock of test_hm_fracture (open at 1 MPa under 0.2 to 0.3 MPa of fluid) with a rate
    that needs little dp, so a fluid near the outlet's 0.2 MPa: closed at 1 MPa already, no pressure
    difference passes the rate; the step converges closed and stops with one line (exit 4)."""
    soft = {"E = 1.0e10": "E = 3.0e8", "shape = [16, 16, 53]": "shape = [8, 8, 27]",
            "upper = [0.02, 0.02, 0.00031]": "upper = [0.02, 0.02, 0.00032]",
            "inlet_pressure = 3.0e5 ": "flow_rate = 1.0e-11 #"}
    summary = run(copy_case(HM, tmp_path, soft), tmp_path / "out", code=4)
    line = one_error_line(capsys)
    assert "time step 0 (t = 0 .. 1): " in line and "[flow] flow_rate: no open path connects the inlet" in line
    assert "(percolation lost)" in line and "nan" not in line.lower()
    assert summary["steps"] == [] and summary["status"] == "failed"


def test_a_block_pushed_off_its_platen_stops_the_run(tmp_path, capsys):
    """A run past check (check_fluid_below_confinement bypassed) whose second stress, 0.25 MPa, is
    below the fluid's push on the upper block: the platen's search finds the stress unchanged as
    it opens and stops (before: it doubled its step to metres and the run died on the fluid grid)."""
    from coupler.plan.effects import contact

    case = copy_case(HM, tmp_path, {**COARSE, "stress = [1.0e6, 2.0e6, 4.0e6]": "stress = [1.0e6, 2.5e5, 1.0e5]"})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(contact, "check_fluid_below_confinement", lambda scene: None)
        summary = run(case, tmp_path / "out", code=4)
    line = one_error_line(capsys)
    assert "participant 'solid' failed: ContactLost: load step 1: the mean normal stress on the platen stays at" in line
    assert "with more than the target 250000 Pa: the faces separate (loss of contact)" in line
    assert len(summary["steps"]) == 1 and summary["status"] == "failed"


@pytest.mark.parametrize("replace, where, reason", [
    ({'walls = "wall" ': 'faces = { ymin = { pressure = 1.5e6 } }\nwalls = "wall" '}, "[flow] faces.ymin",
     "the fluid's pressure 1.5e+06 Pa reaches the smallest confining stress 1e+06 Pa of [loads.2] stress"),
    ({"inlet_pressure = 3.0e5 ": "flow_rate = 1e-9\ninlet_pressure = 3.0e5 "}, "[flow] inlet_velocity",
     "give exactly one of inlet_velocity = [u, v, w] (m/s), inlet_pressure = p (Pa) or flow_rate = Q (m^3/s)"),
    ({"inlet_pressure = 3.0e5 ": "flow_rate = -1e-9 #"}, "[flow] flow_rate", "must be positive"),
])
def test_flow_rate_refusals(tmp_path, capsys, replace, where, reason):
    assert main(["check", str(copy_case(HM, tmp_path, replace))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene.toml" in err[0] and where in err[0] and reason in err[0], err


def test_a_fluid_that_cannot_take_an_inlet_pressure_is_refused(tmp_path, capsys):
    """OpenFOAM's inlet is fixed at configure: a flow rate needs chorin (one line, exit 2)."""
    case = copy_case(CASES / "parallel_plates", tmp_path, {"inlet_pressure = 1.0e-2 ": "flow_rate = 1e-10 #"})
    assert main(["check", str(case)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "scene.toml: [flow] flow_rate: the openfoam fluid does not take a new inlet pressure" in line
    assert "accepts 'inlet_pressure': chorin" in line


def test_check_states_the_rate_control(tmp_path, capsys):
    case = copy_case(HM, tmp_path, {"inlet_pressure = 3.0e5 ": "flow_rate = 3e-9 #"})
    assert main(["check", str(case)]) == 0
    out = capsys.readouterr().out
    assert "fluid.velocity, solid.displacement -> fluid.inlet_pressure: flow_rate_control [step before 1, accelerated]" in out
    assert "flow rate 3e-09 m^3/s, the pressure difference an unknown of the fixed point" in out


def test_an_absurd_flow_rate_names_the_step_the_solver_and_the_key(tmp_path, capsys):
    """flow_rate = 1e10 m^3/s between the plates: the cubic law's first pressure difference (about
    2e18 Pa) blows the Chorin fluid up; the line named neither the step nor the key."""
    case = copy_case(CASES / "parallel_plates", tmp_path, {**PLATES, "inlet_pressure = 1.0e-2 ": "flow_rate = 1e10 #"})
    summary = run(case, tmp_path / "out", code=4)
    line = one_error_line(capsys)
    assert line.startswith("varcouple: error: time step 0 (t = 0 .. 1), coupling iteration 0: participant 'fluid' "
                           "failed: FloatingPointError: chorin: the steady pseudo-time stepping diverged"), line
    assert f"its inlet pressure comes from {case / 'scene.toml'}: [flow] flow_rate = 1e+10 m^3/s" in line
    assert summary["status"] == "failed" and "[flow] flow_rate = 1e+10" in summary["error"]
