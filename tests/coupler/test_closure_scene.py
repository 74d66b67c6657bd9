"""``varcouple check|run`` on ``[closure]`` scenes (coupler/closure_case.py): the fracture
closure case of paper 4.1 on a coarse cylinder through the CLI, its outputs and physics
(closure and contact area grow, the curve stiffens, mean stress over pi r^2), and typed
errors naming file, table and key."""

import json
from pathlib import Path

import numpy as np
import pytest

from coupler import cli
from coupler import scene as scenes
from coupler.errors import SceneError
from vc_helpers import CASES

CASE = CASES / "fracture_closure"

COARSE = """
[closure]
shape = "cylinder"
size = 0.122
lattice = [8, 8, 3]
stresses = [1, 5, 20]
faces_at = [5]
von_mises_at = [20]
"""


def write_scene(tmp_path, text) -> Path:
    case = tmp_path / "case"
    case.mkdir(exist_ok=True)
    (case / "scene.toml").write_text(text)
    return case


def test_check_prints_the_plan_of_the_case(capsys):
    assert cli.main(["check", str(CASE)]) == 0
    out = capsys.readouterr().out
    assert "cylinder, diameter 0.122 m" in out and "16 x 16 x 5, upper 8 x 8 x 5" in out
    assert "1, 2, 4, 6, 10, 15, 20 MPa" in out


def test_run_coarse_cylinder(tmp_path, capsys):
    case = write_scene(tmp_path, COARSE)
    out = tmp_path / "out"
    assert cli.main(["run", str(case), "-o", str(out)]) == 0
    names = {"closure_curve.png", "closure_table.md", "fracture_face_5MPa.vtu", "von_mises_20MPa.vtu",
             "summary.json"}
    assert names <= {f.name for f in out.iterdir()}
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["outputs"]) == names
    assert summary["specimen"]["area"] == pytest.approx(np.pi * 0.061 ** 2)
    steps = summary["steps"]
    stress = np.array([s["stress"] for s in steps])
    closure = np.array([s["closure"] for s in steps])
    assert np.allclose(stress, [1e6, 5e6, 20e6], rtol=5e-3)
    assert np.all(np.diff(closure) > 0) and np.all(np.diff(summary["area_fraction"]) > 0)
    stiffness = np.diff(stress) / np.diff(closure)
    assert stiffness[1] > stiffness[0]
    assert closure[-1] < summary["initial_mean_aperture"]
    assert summary["bandis"]["k_ni"] > 0 and closure[-1] < summary["bandis"]["d_max"]
    import meshio

    face = meshio.read(out / "fracture_face_5MPa.vtu")
    radius = np.hypot(face.points[:, 0] - 0.061, face.points[:, 1] - 0.061)
    assert radius.max() == pytest.approx(0.061, rel=1e-9)  # the lower face is a disc
    assert {"gap", "contact_pressure", "in_contact"} <= set(face.point_data)
    assert "von_mises" in meshio.read(out / "von_mises_20MPa.vtu").cell_data


@pytest.mark.slow
def test_run_the_case(tmp_path):
    """The committed case as users run it (about 50 s)."""
    assert cli.main(["run", str(CASE), "-o", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["steps"]) == 7 and np.all(np.diff(summary["area_fraction"]) > 0)


@pytest.mark.parametrize("text, message", [
    (COARSE + "radius = 1\n", "[closure] radius: unknown key"),
    (COARSE.replace('"cylinder"', '"sphere"'), "[closure] shape: unknown value 'sphere'"),
    (COARSE.replace("[8, 8, 3]", "[9, 9, 3]"), "[closure] ratio: 2 does not divide"),
    (COARSE.replace("[1, 5, 20]", "[5, 1, 20]"), "[closure] stresses: must be increasing"),
    (COARSE.replace("faces_at = [5]", "faces_at = [3]"), "[closure] faces_at: [3]: every value must be one of"),
    (COARSE + "solver = 'newton'\n", "[closure] solver: unknown value 'newton'"),
    (COARSE + "nu = 0.5\n", "[closure] nu: must lie in"),
    (COARSE + "[solid]\n", "unknown table [solid]"),
])
def test_bad_scene_is_a_typed_error_naming_the_key(tmp_path, capsys, text, message):
    case = write_scene(tmp_path, text)
    with pytest.raises(SceneError) as err:
        scenes.load(case)
    assert str(case / "scene.toml") in str(err.value) and message in str(err.value)
    assert cli.main(["check", str(case)]) == 2
    assert message in capsys.readouterr().err
