"""The shipped solid cases run end to end (coupler + dolfinx participant as
processes over zenoh) and match their analytical solutions."""

import json
import shutil

import meshio
import numpy as np
import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case



def run_case(tmp_path, name, replace=None):
    case = copy_case(CASES / name, tmp_path, replace)
    out = tmp_path / "out"
    code = main(["run", str(case), "--output", str(out)])
    return code, out, json.loads((out / "summary.json").read_text())


def test_block_compression_matches_uniaxial_stress(tmp_path):
    code, out, s = run_case(tmp_path, "block_compression")
    assert code == 0 and s["status"] == "completed"
    assert [p["name"] for p in s["participants"]] == ["solid"] and s["exchanges"] == []
    assert s["check"]["passed"] and s["check"]["error"] < 1e-6
    # independently of [check]: the exact solution at every vertex of the output
    m = meshio.read(out / "solid_0000.vtu")
    x, u = m.points, m.point_data["displacement"]
    exact = np.column_stack([0.25e6 * x[:, 0], 0.25e6 * x[:, 1], -1e6 * x[:, 2]]) / 1e10
    assert np.abs(u - exact).max() <= 1e-6 * np.abs(exact).max()
    np.testing.assert_allclose(m.point_data["von_mises"], 1e6, rtol=1e-6)


def test_block_compression_on_two_ranks(tmp_path):
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not found")
    code, out, s = run_case(tmp_path, "block_compression",
                            {'participant = "solid_fenicsx"': 'participant = "solid_fenicsx"\nranks = 2'})
    assert code == 0 and s["check"]["passed"] and s["participants_announced"]["solid"]["ranks"] == 2


def test_pressurized_fracture_opening_matches_sneddon(tmp_path):
    code, out, s = run_case(tmp_path, "pressurized_fracture")
    assert code == 0
    assert [p["name"] for p in s["participants"]] == ["solid"]  # no fluid solver for a static pressure
    assert any("no fluid solver" in load for load in s["loads"])
    assert s["check"]["passed"] and s["check"]["error"] < 0.05
    m = meshio.read(out / "solid_0000.vtu")
    centre = np.argmin(np.linalg.norm(m.points, axis=1))
    opening = 2 * m.point_data["displacement"][centre, 2]
    sneddon = 8 * (1 - 0.25**2) * 1e6 * 0.1 / (np.pi * 1e10)
    assert abs(opening / sneddon - 1) < 0.05


def test_a_wrong_expected_solution_fails_the_check(tmp_path, capsys):
    code, out, s = run_case(tmp_path, "block_compression", {'kind = "uniaxial"': 'z = "-2e6 * z / 1e10"'})
    assert code == 1 and not s["check"]["passed"] and s["check"]["kind"] == "expression"
    assert s["check"]["error"] == pytest.approx(0.5)
    assert "FAIL" in capsys.readouterr().out


def test_uniaxial_check_takes_its_parameters_from_the_scene(tmp_path, capsys):
    """Another modulus, Poisson ratio, pressure and loaded face (x): the check follows the scene."""
    code, out, s = run_case(tmp_path, "block_compression", {
        "E = 1.0e10": "E = 3.0e9", "nu = 0.25": "nu = 0.1", 'boundary = "zmax"\nvalue = 1.0e6':
        'boundary = "xmax"\nvalue = 2.0e6'})
    assert code == 0 and s["check"]["passed"] and s["check"]["error"] < 1e-6
    assert s["check"]["kind"] == "uniaxial" and s["check"]["stress"] == -2e6 and s["check"]["axis"] == "x"
    m = meshio.read(out / "solid_0000.vtu")
    x, u = m.points, m.point_data["displacement"]
    exact = np.column_stack([-2e6 * x[:, 0], 0.2e6 * x[:, 1], 0.2e6 * x[:, 2]]) / 3e9
    assert np.abs(u - exact).max() <= 1e-6 * np.abs(exact).max()
    assert "check: uniaxial stress -2e+06 Pa along x: displacement error" in capsys.readouterr().out


def test_sneddon_check_takes_its_parameters_from_the_scene(tmp_path):
    code, out, s = run_case(tmp_path, "pressurized_fracture", {
        "E = 1.0e10": "E = 2.0e10", "nu = 0.25": "nu = 0.2", "value = 1.0e6": "value = 2.0e6"})
    assert code == 0 and s["check"]["passed"] and s["check"]["kind"] == "sneddon"
    sneddon = 8 * (1 - 0.2**2) * 2e6 * 0.1 / (np.pi * 2e10)
    assert s["check"]["opening_centre"] == pytest.approx(sneddon, rel=1e-12) and s["check"]["vertices"] == 25
    m = meshio.read(out / "solid_0000.vtu")
    centre = np.argmin(np.linalg.norm(m.points, axis=1))
    assert abs(2 * m.point_data["displacement"][centre, 2] / sneddon - 1) < 0.05


def test_nearly_incompressible_rock_warns(tmp_path, capsys):
    """nu = 0.499 with P1: the plan advises P2 and the solid logs its LockingWarning."""
    case = tmp_path / "block"
    shutil.copytree(CASES / "block_compression", case, ignore=shutil.ignore_patterns("results"))
    scene = (case / "scene.toml").read_text().split("# uniaxial stress")[0]  # no [check]: P1 locks
    (case / "scene.toml").write_text(scene.replace("nu = 0.25", "nu = 0.499"))
    assert main(["run", str(case), "--output", str(tmp_path / "out")]) == 0
    assert "nearly incompressible" in capsys.readouterr().out
    log = (tmp_path / "out" / "logs" / "solid.log").read_text()
    assert "LockingWarning" in log


def test_dynamic_block_steps_in_time(tmp_path):
    """With the effect 'dynamics' the solid steps in time (Newmark): the suddenly
    loaded block moves, with a velocity, and overshoots the static displacement."""
    scene_changes = {'effects = ["elasticity"]': 'effects = ["elasticity", "dynamics"]',
                     "[output]": "[time]\ndt = 2e-5\nsteps = 6\n\n[output]"}
    case = tmp_path / "block"
    shutil.copytree(CASES / "block_compression", case, ignore=shutil.ignore_patterns("results"))
    scene = (case / "scene.toml").read_text().split("# uniaxial stress")[0]
    for old, new in scene_changes.items():
        scene = scene.replace(old, new)
    (case / "scene.toml").write_text(scene)
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert len(s["steps"]) == 6
    moved = [step["max_displacement"] for step in s["steps"]]
    assert moved[0] > 0 and max(moved) > moved[0]
    m = meshio.read(out / "solid_0002.vtu")
    assert np.abs(m.point_data["velocity"]).max() > 0
    assert (out / "solid.pvd").read_text().count("<DataSet") == 6
