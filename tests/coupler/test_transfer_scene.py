"""A transfer is a plan without processes (coupler/plan/effects/transfer.py): mesh files served in
the coupler's process, one exchange per method, the generic output, and [check] kind =
"exact_transfer" (coupler/checks/exact_transfer.py)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import meshio
import numpy as np
import pytest

from cli_helpers import CHECK, TRANSFER_SCENE, assert_clean_error, run_cli, transfer_case as case, write_mesh
from coupler.errors import SceneError
from coupler.plan.plan import make_plan
from coupler.run import runner
from coupler.protocol.wire import Field
from coupler.scene import load
from coupler.standins import MeshFileParticipant
from transfer.generate import box_tetrahedra
from vc_helpers import CASES

def test_the_plan_serves_the_files_in_process():
    plan = make_plan(load(CASES / "transfer_demo"))
    assert [(p.name, p.kind, p.in_process) for p in plan.participants] == [
        ("source", "mesh_file", True), ("target_l2", "mesh_file", True), ("target_pseudo_l2", "mesh_file", True)]
    assert [(e.sources, e.target, e.operator, e.options) for e in plan.exchanges] == [
        (["source.pressure"], f"target_{m}.pressure", m, {"kind": "point", "fill": "nan", "threads": 1})
        for m in ("l2", "pseudo_l2")]
    assert not plan.implicit and plan.participants[0].config["file"].endswith("rock_block.vtu")


def test_a_transfer_opens_no_session_and_starts_no_process(tmp_path, capsys, monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a plan without processes opened a zenoh session or a launcher")

    monkeypatch.setattr(runner, "CouplerSession", refuse)
    monkeypatch.setattr(runner, "Launcher", refuse)
    code, _, err = run_cli(capsys, "run", case(tmp_path, check=CHECK.format(exact="1 + x - 2*y + 3*z",
                                                                            tolerance=1e-12)), "-o", tmp_path / "out")
    assert code == 0, err
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    for m in s["check"]["methods"].values():  # a linear field: both methods reproduce it
        assert m["relative_l2_error"] < 1e-13 and m["max_error"] < 1e-12
    out = meshio.read(tmp_path / "out" / "target_l2_0000.vtu")
    np.testing.assert_allclose(out.point_data["T"], 1 + out.points @ [1.0, -2.0, 3.0], atol=1e-12)
    assert out.point_data["covered"].min() == 1


def test_a_cell_field_is_written_per_cell(tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", case(tmp_path, field="k"), "-o", tmp_path / "out")
    assert code == 0, err
    out = meshio.read(tmp_path / "out" / "target_pseudo_l2_0000.vtu")
    np.testing.assert_allclose(out.cell_data["k"][0], 7.0, rtol=1e-12)
    assert out.cell_data["covered"][0].min() == 1 and "k" not in out.point_data


def test_a_cell_field_plans_files_whose_rows_are_cells(tmp_path):
    """The source and every target of a P0/Q0 field are served with location 'cells'; a file's part
    (rank 1 of 2, as on a coupler of 2 ranks) says so and gives its field and ``covered`` at its own
    cells, the rows its ``cell_ids`` name."""
    plan = make_plan(load(case(tmp_path, field="k")))
    assert [p.config.get("location") for p in plan.participants] == ["cells"] * 3
    source = box_tetrahedra((2, 2, 2))
    path = write_mesh(tmp_path / "cells.vtu", source, cell_data={"c": np.arange(source.num_cells, dtype=float)})
    part = MeshFileParticipant()
    part.bind("r1", "source", SimpleNamespace(Get_rank=lambda: 1, Get_size=lambda: 2,
                                              allgather=lambda digest: [digest, digest]))  # rank 0 read the same
    part.configure({"file": str(path), "field": "c", "location": "cells"})
    header, geometry = part.geometry()
    cells = np.asarray(geometry["cell_ids"])
    assert header["location"] == "cells" and 0 < len(cells) < source.num_cells
    out = part.advance(0, 0, 0.0, 1.0, {"c": Field("c", np.r_[np.nan, np.ones(len(cells) - 1)])})
    np.testing.assert_array_equal(out["c"].data, cells)
    np.testing.assert_array_equal(out["covered"].data, np.r_[0, np.ones(len(cells) - 1)])
    with pytest.raises(ValueError, match="location must be 'points' or 'cells', got 'cell'"):
        part.configure({"file": str(path), "location": "cell"})


def test_where_the_source_does_not_reach_the_target_is_nan_and_not_covered(tmp_path, capsys):
    """A target twice as long as the source: the uncovered half is NaN, the errors are over the
    covered dofs and cells only (a linear field: exact there)."""
    target = box_tetrahedra((4, 2, 2), upper=(2, 1, 1))
    check = CHECK.format(exact="1 + x - 2*y + 3*z", tolerance=1e-12)
    code, _, err = run_cli(capsys, "run", case(tmp_path, check=check, target=target), "-o", tmp_path / "out")
    assert code == 0, err
    out = meshio.read(tmp_path / "out" / "target_l2_0000.vtu")
    covered, T = out.point_data["covered"], out.point_data["T"]
    np.testing.assert_array_equal(covered == 1, out.points[:, 0] <= 1 + 1e-12)
    assert np.isnan(T[covered == 0]).all() and np.isfinite(T[covered == 1]).all()
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    projection = s["steps"][0]["projections"]["target_l2.T"]
    assert projection["uncovered_dofs"] == int((covered == 0).sum()) and projection["covered_fraction"] < 1
    assert s["check"]["passed"] and s["check"]["error"] < 1e-13


def test_a_check_beyond_its_tolerance_exits_1(tmp_path, capsys):
    code, stdout, _ = run_cli(capsys, "run", case(tmp_path, check=CHECK.format(exact="1 + x - 2*y + 3*z + 0.1*x*y",
                                                                                 tolerance=1e-6)))
    assert code == 1 and "transfer against exact: l2 L2 error" in stdout and "FAIL" in stdout


@pytest.mark.parametrize("field, check, words", [
    ("T", CHECK.format(exact="1 + x", tolerance=0.1) + "radius = 1.0\n", ["[check] radius", "unknown key"]),
    ("T", CHECK.format(exact="log(x - 5)", tolerance=0.1), ["[check] exact", "not finite at every source point"]),
    ("T", CHECK.format(exact="arctan2(x)", tolerance=0.1), ["[check] exact", "cannot evaluate"]),
    ("nope", "", ["[transfer] field", "no field 'nope'"]),
])
def test_bad_transfer_scenes_name_the_key(tmp_path, capsys, field, check, words):
    code, _, err = run_cli(capsys, "run", case(tmp_path, field=field, check=check))
    assert_clean_error(code, err, "scene.toml", *words)


def test_exact_transfer_needs_a_transfer_and_a_scalar_field(tmp_path):
    src = box_tetrahedra((2, 2, 2))
    write_mesh(tmp_path / "src.vtu", src, {"u": src.points})
    write_mesh(tmp_path / "dst.vtu", box_tetrahedra((3, 3, 3)))
    (tmp_path / "scene.toml").write_text(TRANSFER_SCENE.format(field="u") + CHECK.format(exact="x", tolerance=0.1))
    with pytest.raises(SceneError, match=r"\[check\] exact: is a scalar expression but field 'u' has shape \(3,\)"):
        load(tmp_path)
    text = (CASES / "block_compression" / "scene.toml").read_text().split("[check]")[0]
    (tmp_path / "scene.toml").write_text(text + CHECK.format(exact="x", tolerance=0.1))
    with pytest.raises(SceneError, match=r"\[check\] kind: 'exact_transfer' compares a transfer: needs the effect"):
        load(tmp_path)


def test_the_picture_shows_the_source_and_each_target(tmp_path, capsys):
    case = tmp_path / "case"
    case.mkdir()
    for name in ("rock_block.vtu", "target_block.vtu"):
        (case / name).write_bytes((CASES / "transfer_demo" / name).read_bytes())
    text = (CASES / "transfer_demo" / "scene.toml").read_text()
    (case / "scene.toml").write_text(text.replace('directory = "results"', 'directory = "results"\npictures = true'))
    code, _, err = run_cli(capsys, "run", case)
    assert code == 0, err
    s = json.loads((case / "results" / "summary.json").read_text())
    assert s["pictures"] == ["transfer.png"] and "pictures_error" not in s
    from PIL import Image

    width, height = Image.open(case / "results" / "transfer.png").size
    assert width == 3 * height  # the source and two targets side by side
