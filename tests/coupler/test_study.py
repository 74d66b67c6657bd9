"""``varcouple study``: --vary parsed and applied to the scene's TOML before validation (a bad
key or value is one line naming it, and nothing runs), the product of the values run each in
its own directory, study.json with status, seconds, cost and error (the [check]'s, or the
relative L2 difference from the most accurate run), the PNG and the page."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.run.study import combinations, difference, plan
from coupler.scene.overrides import apply, parse_vary
from transfer.generate import box_tetrahedra
from vc_helpers import CASES, NEEDS_GMSH, copy_case, hertz_mesh_file


def test_the_product_of_the_values():
    runs = combinations(['geometry.fluid.shape=[[21,11,7],[21,11,11]]', 'coupling.acceleration=["aitken","iqn-ils"]'])
    assert runs == [{"geometry.fluid.shape": [21, 11, 7], "coupling.acceleration": "aitken"},
                    {"geometry.fluid.shape": [21, 11, 7], "coupling.acceleration": "iqn-ils"},
                    {"geometry.fluid.shape": [21, 11, 11], "coupling.acceleration": "aitken"},
                    {"geometry.fluid.shape": [21, 11, 11], "coupling.acceleration": "iqn-ils"}]


@pytest.mark.parametrize("text, message", [
    ("coupling.acceleration", r"--vary 'coupling.acceleration': give KEY=VALUES"),
    ("coupling..x=[1]", r"give KEY=VALUES"),
    ("coupling.tolerance=[1e-6,", r"--vary coupling.tolerance: '\[1e-6,' is not a TOML value"),
    ("coupling.tolerance=1e-6", r"--vary coupling.tolerance: give the values as a non-empty TOML array"),
    ("coupling.tolerance=[]", r"non-empty TOML array"),
])
def test_bad_vary_arguments(text, message):
    with pytest.raises(SceneError, match=message):
        parse_vary(text)


def test_a_key_given_twice():
    with pytest.raises(SceneError, match=r"--vary time.steps: given twice"):
        combinations(["time.steps=[1]", "time.steps=[2]"])


def test_apply_sets_nested_keys_and_array_entries():
    data = {"loads": [{"type": "dirichlet"}, {"type": "pressure", "value": 1.0}], "time": {"dt": 1.0}}
    apply(data, "coupling.acceleration", "aitken")
    apply(data, "loads.2.value", 3.0)
    apply(data, "geometry.fluid.shape", [1, 2, 3])
    assert data["coupling"] == {"acceleration": "aitken"} and data["loads"][1]["value"] == 3.0
    assert data["geometry"]["fluid"]["shape"] == [1, 2, 3]
    with pytest.raises(SceneError, match=r"--vary loads.3.value: \[loads\] has entries 1 to 2, got '3'"):
        apply(data, "loads.3.value", 1.0)
    with pytest.raises(SceneError, match=r"--vary loads.value: loads is an array of tables: name an entry"):
        apply(data, "loads.value", 1.0)
    with pytest.raises(SceneError, match=r"--vary time.dt.x: time.dt is a value \(1.0\), not a table"):
        apply(data, "time.dt.x", 1.0)


@pytest.mark.parametrize("vary, message", [
    ('coupling.acceleraton=["aitken"]', r'--vary coupling.acceleraton="aitken": .*scene.toml: \[coupling\] '
                                        r'acceleraton: unknown key; known keys: acceleration'),
    ('coupling.acceleration=["aitken", "newton"]', r'--vary coupling.acceleration="newton": .*scene.toml: '
                                                   r"\[coupling\] acceleration: unknown value 'newton'"),
    ('geometry.fluid.shape=[[21, 11]]', r"--vary geometry.fluid.shape=\[21, 11\]: .*\[geometry.fluid\] shape: "
                                        r"must be a list of 3 positive integers"),
])
def test_every_run_is_validated_before_anything_runs(tmp_path, capsys, vary, message):
    with pytest.raises(SceneError, match=message):
        plan(CASES / "small_fracture", [vary], tmp_path / "study")
    assert main(["study", str(CASES / "small_fracture"), "--vary", vary, "-o", str(tmp_path / "study")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("varcouple: error: --vary ") and err.count("\n") == 1
    assert not (tmp_path / "study").exists()


def _vtu(path, mesh, u):
    meshio.write(path, meshio.Mesh(mesh.points, [("tetra", mesh.cells)], point_data={"displacement": u}))


def test_difference_on_the_reference_mesh(tmp_path):
    """An affine field carried by L2 projection is reproduced (eq. 1-3): the difference from the
    reference is exactly the added constant's, measured with the reference mesh's mass matrix."""
    from transfer import FunctionSpace

    coarse, fine = box_tetrahedra((3, 3, 3), jitter=0.2, seed=1), box_tetrahedra((5, 4, 6), jitter=0.2, seed=2)
    a = np.array([[1.0, 0.5, -2.0], [0.3, 1.0, 0.0], [0.0, -0.7, 1.5]])
    f = lambda x: x @ a + np.array([0.1, 0.2, 0.3])  # noqa: E731
    shift = np.array([0.01, 0.0, -0.02])
    _vtu(tmp_path / "ref.vtu", fine, f(fine.points))
    _vtu(tmp_path / "run.vtu", coarse, f(coarse.points) + shift)
    M = FunctionSpace(fine, "P1").mass_matrix()
    ref = f(fine.points)
    expected = np.sqrt(sum(shift[c] ** 2 * M.sum() for c in range(3)) / sum(ref[:, c] @ (M @ ref[:, c])
                                                                           for c in range(3)))
    assert difference(tmp_path / "run.vtu", tmp_path / "ref.vtu", "displacement") == pytest.approx(expected, rel=1e-8)
    _vtu(tmp_path / "same.vtu", fine, ref + shift)  # same mesh: taken as is
    assert difference(tmp_path / "same.vtu", tmp_path / "ref.vtu", "displacement") == pytest.approx(expected, rel=1e-12)
    _vtu(tmp_path / "zero.vtu", fine, 0 * ref)
    assert difference(tmp_path / "run.vtu", tmp_path / "zero.vtu", "displacement") is None


def _study(tmp_path, case, *varies):
    out = tmp_path / "study"
    code = main(["study", str(case), *[a for v in varies for a in ("--vary", v)], "-o", str(out)])
    return code, out, json.loads((out / "study.json").read_text())


def test_small_fracture_with_two_grid_shapes(tmp_path):
    code, out, study = _study(tmp_path, CASES / "small_fracture", "geometry.fluid.shape=[[21,11,7],[21,11,11]]")
    assert code == 0 and [run["status"] for run in study["runs"]] == ["completed", "completed"]
    first, second = study["runs"]
    assert first["values"] == {"geometry.fluid.shape": [21, 11, 7]} and study["check"] is None
    assert second["cost"]["cells"] - first["cost"]["cells"] == 21 * 11 * (11 - 7)  # the same solid
    assert second["cost"]["participants"]["fluid"]["cells"] == 21 * 11 * 11
    assert study["error"]["reference"] == "run_02" and study["error"]["field"] == "solid.displacement"
    assert second["error"] == 0.0 and 1e-3 < first["error"] < 0.5  # measured: 5.5 %
    for run in study["runs"]:
        assert run["seconds"]["total"] > 0 and {"fluid", "solid", "transfer"} <= set(run["seconds"])
        assert (out / run["directory"] / "summary.json").is_file() and (out / run["directory"] / "fluid_0001.vtu").is_file()
    assert (out / "study.png").stat().st_size > 0 and "run_02" in (out / "index.html").read_text()


@NEEDS_GMSH
def test_hertz_with_two_mesh_sizes_reports_its_check(tmp_path):
    case = copy_case(CASES / "hertz", tmp_path)
    for h in (0.08, 0.06):
        hertz_mesh_file(case / f"hertz_h{h}.msh", radius=1.0, h_contact=h, h_far=0.3, refine_radius=0.25)
    code, out, study = _study(tmp_path, case, 'geometry.solid.mesh=["hertz_h0.08.msh", "hertz_h0.06.msh"]')
    assert study["check"] == "hertz" and "kind hertz" in study["error"]["against"]
    coarse, fine = study["runs"]
    assert coarse["cost"]["cells"] < fine["cost"]["cells"]
    for run in study["runs"]:
        assert run["status"] == "completed" and run["check"]["kind"] == "hertz" and run["check"]["radius"] == 1.0
        assert run["error"] == run["check"]["error"] == max(run["check"]["error_a"], run["check"]["error_p0"])
    assert fine["check"]["error_p0"] < coarse["check"]["error_p0"]
    assert code == (0 if all(run["check"]["passed"] for run in study["runs"]) else 1)
    assert (out / "study.png").is_file()


def test_a_knob_without_a_mesh_change_and_a_failed_run(tmp_path):
    """Acceleration and iteration cap on the stand-in loop: the capped runs do not converge and
    are recorded as such (the study goes on, exit 1); the others are compared with the longest
    run of equal cost."""
    code, out, study = _study(tmp_path, CASES / "standin_flow", 'coupling.acceleration=["aitken","iqn-ils"]',
                              "coupling.max_iterations=[2, 50]")
    assert code == 1
    statuses = {(r["values"]["coupling.acceleration"], r["values"]["coupling.max_iterations"]): r for r in study["runs"]}
    for acceleration in ("aitken", "iqn-ils"):
        capped, free = statuses[(acceleration, 2)], statuses[(acceleration, 50)]
        assert capped["status"] == "not_converged" and "did not converge" in capped["message"] and capped["error"] is None
        assert free["status"] == "completed" and free["error"] is not None and free["error"] < 1e-6
    reference = study["error"]["reference"]
    assert next(r for r in study["runs"] if r["name"] == reference)["error"] == 0.0
    assert len({r["cost"]["cells"] for r in study["runs"]}) == 1
    assert study["vary"] == {"coupling.acceleration": ["aitken", "iqn-ils"], "coupling.max_iterations": [2, 50]}
