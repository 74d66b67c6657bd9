"""The obstacle cases (cases/cube_obstacle, cases/rock_obstacle) through ``varcouple check``
and ``varcouple run``: outputs, physics checks and clean errors on bad scene files."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from coupler.cli import main
from coupler.scene import SceneError, load
from vc_helpers import CASES



def copy_case(name, tmp_path, replace=()):
    case = tmp_path / name
    case.mkdir()
    text = (CASES / name / "scene.toml").read_text()
    for old, new in replace:
        assert old in text, old
        text = text.replace(old, new)
    (case / "scene.toml").write_text(text)
    return case


def test_check_prints_the_plan_of_every_obstacle_case(capsys):
    for name, runs in [("cube_obstacle", "2 levels on [6, 6, 6] cells, 3 levels on [13, 13, 13] cells, 4 levels"),
                       ("cube_obstacle_large", "5 levels on [51, 51, 51] cells"),
                       ("rock_obstacle", "4 levels on [48, 48, 16] cells")]:
        assert main(["check", str(CASES / name)]) == 0
        out = capsys.readouterr().out
        assert "valid" in out and runs in out and "multilevel" in out, out


def test_cube_case_two_levels_writes_vtu_png_and_summary(tmp_path, capsys):
    case = copy_case("cube_obstacle", tmp_path, [("cells = [6, 13, 25]", "cells = [6]"),
                                                 ("levels = [2, 3, 4]", "levels = [2]")])
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0
    assert f"results in {out}" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["convergence.png", "solution_L2.vtu", "solution_L2_grid0.vtu",
                                                     "summary.json"]
    assert meshio.read(out / "solution_L2_grid0.vtu").point_data["kept"].sum() == 4**3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["case"] == "cube_obstacle" and summary["method"] == "multilevel"
    (run,) = summary["runs"]
    assert run["dofs"] == 3 * 7**3 and run["converged"] and run["final_step"] < 1e-12
    mesh = meshio.read(out / "solution_L2.vtu")
    u, contact = mesh.point_data["displacement"], mesh.point_data["contact"].astype(bool)
    bottom = mesh.points[:, 2] == 0.0
    # the whole bottom is pushed onto the plane and stays on it (no penetration, no gap)
    assert np.array_equal(contact, bottom) and run["max_penetration"] == 0.0
    np.testing.assert_allclose(u[bottom, 2], 0.0, atol=1e-15)
    # the plane pushes up, with the force the top face applies
    force = mesh.point_data["contact_force"]
    assert np.all(force[bottom, 2] >= 0) and run["contact_force_z"] > 0


def test_rock_case_touches_at_asperities_only(tmp_path):
    case = copy_case("rock_obstacle", tmp_path, [("cells = [[48, 48, 16]]", "cells = [[16, 16, 6]]"),
                                                 ("levels = [4]", "levels = [3]"),
                                                 ("coarse_shape = [6, 6, 2]", "coarse_shape = [4, 4, 2]")])
    assert main(["run", str(case)]) == 0
    (run,) = json.loads((case / "results" / "summary.json").read_text())["runs"]
    assert run["converged"] and run["max_penetration"] == 0.0
    mesh = meshio.read(case / "results" / "solution_L3.vtu")
    contact = mesh.point_data["contact"].astype(bool)
    assert 0 < contact.sum() == run["contact_nodes"]
    z = mesh.points[:, 2]
    on_bottom_face = z < z.min() + 4 * 5e-4 + 1e-12  # within the rough face's height range
    assert np.all(on_bottom_face[contact]) and contact.sum() < 0.5 * on_bottom_face.sum()
    # touching points are on the plane: z + u_z = the plane (min z) exactly
    deformed = z + mesh.point_data["displacement"][:, 2]
    np.testing.assert_allclose(deformed[contact], z.min(), atol=1e-15)
    assert deformed.min() >= z.min() - 1e-15


@pytest.mark.parametrize("replace, words", [
    (("size = 0.01", "size = 0.01\ncolour = 1"), ["[body] colour", "unknown key"]),
    (("levels = [2, 3, 4]", "levels = [2, 3]"), ["[hierarchy] levels", "2 entries", "3"]),
    (("levels = [2, 3, 4]", "levels = [2, 3, 3]"), ["[hierarchy] levels", "listed twice"]),
    (("shape = \"cube\"", "shape = \"sphere\""), ["[body] shape", "'sphere'"]),
    (("E = 1.0e10", "E = -1.0"), ["[material] E", "positive"]),
    (("displacement = [0.0, 0.0, -3.0e-4]", "displacement = [0.0, -3.0e-4]"), ["[obstacle] displacement", "3 finite numbers"]),
    (("method = \"multilevel\"", "method = \"jacobi\""), ["[solver] method", "'jacobi'"]),
    (("[output]", "[outputs]"), ["[outputs]", "unknown table"]),
])
def test_bad_scene_files_name_file_table_and_key(tmp_path, capsys, replace, words):
    case = copy_case("cube_obstacle", tmp_path, [replace])
    with pytest.raises(SceneError) as err:
        load(case)
    message = str(err.value)
    assert str(case / "scene.toml") in message
    for word in words:
        assert word in message, (word, message)
    # the command line prints it as one line and exits 2, for check and run alike
    for command in ("check", "run"):
        assert main([command, str(case)]) == 2
        assert capsys.readouterr().err == f"varcouple: error: {' '.join(message.split())}\n"
    assert not (case / "results").exists()
