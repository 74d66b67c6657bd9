"""The hydro-mechanical fracture (cases/hm_fracture; effects elasticity, contact and flow): a
rough fracture closed by a platen at three confining stresses with a pressure-driven flow
through it, one implicit coupling per load step. On a coarser fluid grid in the plane (8 x 8
columns instead of 16 x 16; the same 10 um across): the force balance at every stress, the
apertures and flow rate against stress, zero flow against the pure contact scene, a lost open
path and the refusals."""

from __future__ import annotations

import json
import re

import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

CASE = CASES / "hm_fracture"
COARSE = {"shape = [16, 16, 53]": "shape = [8, 8, 53]"}
FLOW_TABLES = ("geometry.fluid", "materials.fluid", "flow", "solvers.fluid", "coupling")


def run(case, out) -> dict:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VARCOUPLE_PICTURES", "0")
        assert main(["run", str(case), "-o", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def coarse(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hm")
    return run(copy_case(CASE, tmp, COARSE), tmp / "out")


def test_platen_force_is_contact_plus_fluid_force_at_every_stress(coarse):
    """The upper block: the platen's force = the contact force of the lower block on it + the
    fluid's force on its face (zero where the faces touch), to 1e-6."""
    for step, stress in zip(coarse["steps"], (1e6, 2e6, 4e6)):
        f = step["figures"]["solid"]
        assert step["converged"] and f["stress"] == pytest.approx(stress, rel=5e-3)
        fluid = f["fluid_force_fracture_upper_z"]
        assert -f["force_z"] + fluid == pytest.approx(f["platen_force"], rel=1e-6)
        # the fluid (0.2 to 0.3 MPa over the open part of the 20 mm square) carries a real share
        assert 0.2e6 * 0.02 ** 2 * 0.8 < fluid < 0.3e6 * 0.02 ** 2
        # the lower face gets the opposite push from the same fluid: the coarser upper face (4 x 4
        # lattice) loses the slave's contact area (coupler/fsi/open_gap.py), not a nodal mask's
        # (with the nearest slave node's contact the two differed by up to 7 %)
        assert f["fluid_force_fracture_lower_z"] == pytest.approx(-fluid, rel=2e-3)


def test_rough_fracture_apertures_and_flow_fall_with_stress(coarse):
    rows = [s["fracture"] for s in coarse["steps"]]
    for r in rows:
        assert r["percolating"] and 0 < r["hydraulic_aperture"] <= r["mechanical_aperture"]
        assert 2e5 < r["mean_face_pressure"] < 3e5
    for before, after in zip(rows, rows[1:]):
        assert after["mechanical_aperture"] < before["mechanical_aperture"]
        assert after["hydraulic_aperture"] < before["hydraulic_aperture"]
        assert after["flow_rate"] < before["flow_rate"]
        assert after["contact_area_fraction"] >= before["contact_area_fraction"]
    step = coarse["steps"][0]  # e_h is the cubic law's aperture for the measured Q
    mu, L, W, dp = 1.0, 0.02, 0.02, 1e5
    assert rows[0]["hydraulic_aperture"] ** 3 == pytest.approx(12 * mu * rows[0]["flow_rate"] * L / (W * dp),
                                                               rel=1e-12)
    assert step["iterations"] <= 8


def test_each_step_estimates_the_error_of_e_h_from_the_coarsened_grid(coarse):
    """The Chorin fluid's flow rate on its grid coarsened 2x across (53 cells: 27) gives e_h there
    and the estimate (Richardson at order 1/2) per step; at 10 cells across the mean aperture of
    8 x 8 columns, penalization "lubrication", it is 0.2, 0.2 and 2.2 % (measured): under 5 %, no
    warning (with penalization "wall" 39 to 61 %, each step warns: fails)."""
    for step in coarse["steps"]:
        f, fluid = step["fracture"], step["figures"]["fluid"]
        assert f["coarse_hydraulic_aperture"] ** 3 == pytest.approx(
            f["hydraulic_aperture"] ** 3 * fluid["coarse_flow_rate"] / f["flow_rate"], rel=1e-12)
        assert f["hydraulic_aperture_error"] == pytest.approx(
            (f["coarse_hydraulic_aperture"] - f["hydraulic_aperture"]) / (2 ** 0.5 - 1), rel=1e-12)
        assert f["hydraulic_aperture_relative_error"] == pytest.approx(
            f["hydraulic_aperture_error"] / f["hydraulic_aperture"], rel=1e-12)
        assert 0 < f["hydraulic_aperture_relative_error"] < 0.05
        assert not any("is uncertain by about" in w for w in f.get("warnings", []))
        assert any("on the grid coarsened 2x across z" in r["solver"] and r["converged"]
                   for r in step["solves"]["fluid"])
    assert not any("is uncertain by about" in w for w in coarse.get("warnings", []))


#: e_h [m] at 1, 2 and 4 MPa converged across the gap on the scene's 16 x 16 columns (README.md,
#: "Converged e_h": Richardson's extrapolation from 16 and 32 cells across)
CONVERGED_HYDRAULIC_APERTURE = (80.37e-6, 71.69e-6, 58.06e-6)


@pytest.mark.slow
def test_hydraulic_aperture_at_8_cells_across_is_within_5_percent_of_the_converged_value(tmp_path):
    """The scene as shipped (penalization "lubrication") at 8 cells across the mean initial aperture
    (16 x 16 x 43 cells) with Newton's steady solve: e_h within 5 % of the converged value at every
    stress (issue 27 item 2; measured -0.10, -0.14, -0.06 %, 77 s at a load of 12; with penalization
    "wall" +12 to +20 %: fails)."""
    eight = {"shape = [16, 16, 53]": "shape = [16, 16, 43]",
             'participant = "chorin"': 'participant = "chorin"\nsteady = "newton"'}
    summary = run(copy_case(CASE, tmp_path, eight), tmp_path / "out")
    assert summary["status"] == "completed"
    for step, converged in zip(summary["steps"], CONVERGED_HYDRAULIC_APERTURE, strict=True):
        assert step["fracture"]["hydraulic_aperture"] == pytest.approx(converged, rel=0.05)


def _without_flow(text: str) -> str:
    """The same scene as pure contact: effects elasticity and contact, no fluid tables."""
    text = text.replace('effects = ["elasticity", "contact", "flow"]', 'effects = ["elasticity", "contact"]')
    parts = re.split(r"(?m)^(?=\[)", text)
    return "".join(p for p in parts if not any(p.startswith(f"[{t}]") for t in FLOW_TABLES))


def test_zero_pressure_difference_gives_the_pure_contact_closure(tmp_path):
    """No pressure difference and no fluid pressure: the coupled scene's closure figures are
    the pure contact scene's (the same scene without flow) to 1e-8."""
    fluidless = {"inlet_pressure = 3.0e5": "inlet_pressure = 0.0", "outlet_pressure = 2.0e5": "outlet_pressure = 0.0",
                 **COARSE}
    coupled = run(copy_case(CASE, tmp_path / "flow", fluidless), tmp_path / "flow" / "out")
    case = copy_case(CASE, tmp_path / "dry")
    (case / "scene.toml").write_text(_without_flow((case / "scene.toml").read_text()))
    dry = run(case, tmp_path / "dry" / "out")
    assert "flow" not in dry["effects"]
    keys = ("closure", "mean_gap", "area_fraction", "active_nodes", "force_z", "platen_force",
            "platen_displacement", "stress")
    for wet, ref in zip(coupled["steps"], dry["steps"], strict=True):
        a, b = wet["figures"]["solid"], ref["figures"]["solid"]
        for key in keys:
            assert a[key] == pytest.approx(b[key], rel=1e-8, abs=1e-20), key
        assert wet["fracture"]["flow_rate"] == 0.0 or abs(wet["fracture"]["flow_rate"]) < 1e-20
        assert wet["fracture"]["hydraulic_aperture"] == 0.0 and wet["fracture"]["mean_face_pressure"] == 0.0
        assert wet["iterations"] == 1


def test_a_closed_path_gives_zero_flow_and_a_message(tmp_path, capsys):
    """A soft rock closed to below two fluid cells: no open path through the grid's cells from
    inlet to outlet: flow rate and hydraulic aperture 0, the warning in the log and summary. At
    4 MPa its contact area exceeds 50 % and its mean open aperture (13 um) is under one fluid cell
    (20 um): both accuracy warnings in that step's figures, each printed once; the throat of the
    widest column path is under 4 cells at every stress (its warning every step, printed once)."""
    soft = {"E = 1.0e10": "E = 3.0e8", "shape = [16, 16, 53]": "shape = [8, 8, 27]",
            "upper = [0.02, 0.02, 0.00031]": "upper = [0.02, 0.02, 0.00032]"}
    summary = run(copy_case(CASE, tmp_path, soft), tmp_path / "out")
    last = summary["steps"][-1]["fracture"]
    assert not last["percolating"] and last["flow_rate"] == 0.0 and last["hydraulic_aperture"] == 0.0
    assert last["mechanical_aperture"] > 0
    assert any("no connected open path" in w for w in summary["warnings"])
    h = 0.00054 / 27
    for step in summary["steps"]:
        f = step["fracture"]
        assert f["cells_across"] == pytest.approx(f["mean_open_aperture"] / h, rel=1e-12)
        assert f["mean_open_aperture"] * (1 - f["contact_area_fraction"]) == pytest.approx(f["mechanical_aperture"],
                                                                                          rel=1e-9)
    assert [len(s["fracture"].get("warnings", [])) for s in summary["steps"]] == [1, 1, 3]
    for step in summary["steps"]:
        f = step["fracture"]
        assert 0 < f["throat_aperture"] < f["mean_open_aperture"] and f["throat_cells_across"] < 4
        assert f"{f['throat_cells_across']:.2f} fluid cells across" in f["warnings"][-1]
    assert last["contact_area_fraction"] > 0.5 and last["cells_across"] < 1
    area, across, _ = last["warnings"]
    assert f"the contact area is {100 * last['contact_area_fraction']:.0f} % of the fracture plane (above 50 %)" in area
    assert "(2.5 x 2.5 mm in the plane)" in area
    n = last["cells_across"]
    assert f"is {n:.2f} fluid cells across ([geometry.fluid] cells 20 um across the fracture)" in across
    assert f"{200 / n ** 2:.0f} % extrapolated" in across and "+3.1 % at 8" in across
    assert all("hydraulic_aperture_error" not in s["fracture"] for s in summary["steps"])
    printed = capsys.readouterr().out
    assert "fracture  no e_h error estimate: no flow through the fracture (e_h = 0)" in printed
    assert printed.count("warning: fracture: the contact area is") == 1
    assert printed.count("warning: fracture: the mean open aperture") == 1
    assert printed.count("warning: fracture: the narrowest throat") == 1


@pytest.mark.parametrize("replace, where, reason", [
    ({"outlet_pressure = 2.0e5": "outlet_pressure = 1.0e6"}, "[flow] outlet_pressure",
     "reaches the smallest confining stress 1e+06 Pa of [loads.2] stress"),
    ({"inlet_pressure = 3.0e5 ": "inlet_velocity = [0.001, 0.0, 0.0] "}, "[flow] inlet_pressure",
     "missing: contact with 'flow' drives the flow by a pressure difference"),
    ({'interface = ["fracture_lower", "fracture_upper"]': 'interface = "fracture_lower"'},
     "[coupling] interface", "the fluid wets the two contact faces"),
    ({'effects = ["elasticity", "contact", "flow"]': 'effects = ["elasticity", "contact", "flow", "dynamics"]'},
     "[loads.2] type", "a platen (stress-controlled load steps) is static: not with 'dynamics'"),
])
def test_refusals_name_file_key_and_reason(tmp_path, capsys, replace, where, reason):
    case = copy_case(CASE, tmp_path, replace)
    assert main(["check", str(case)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene.toml" in err[0] and where in err[0] and reason in err[0], err


def test_check_states_which_variant_runs(capsys):
    """The flow solver (contact + flow) or the fluid at rest (contact + fluid_pressure)."""
    assert main(["check", str(CASE)]) == 0
    out = capsys.readouterr().out
    assert "hydro-mechanical fracture (flow solver chorin, not the fluid at rest of 'fluid_pressure')" in out
    assert "open_pressure_trace" in out and "figures       fracture per step" in out
    assert main(["check", str(CASES / "fracture_open_by_pressure")]) == 0
    assert "the fluid at rest in the fracture (the cheap variant" in capsys.readouterr().out
