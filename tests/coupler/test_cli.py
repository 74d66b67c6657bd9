"""The varcouple command line: ``transfer`` between mesh files, ``run`` of a scene, errors."""

import json
import shutil
import subprocess
import sys

import meshio
import numpy as np
import pytest

from transfer.generate import box_hexahedra, box_tetrahedra

from cli_helpers import assert_clean_error, run_cli
from vc_helpers import ROOT

DEMO = ROOT / "cases" / "transfer_demo"


def linear(points):
    return 0.5 + points @ np.array([1.0, -2.0, 3.0])


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    """A jittered tet source with point and cell fields, a hex target, a far-away target."""
    d = tmp_path_factory.mktemp("meshes")
    src = box_tetrahedra((3, 3, 3), jitter=0.2, seed=4)
    dst = box_hexahedra((4, 4, 4))
    far = box_tetrahedra((1, 1, 1), lower=(3, 3, 3), upper=(4, 4, 4))
    lin = linear(src.points)
    meshio.write(d / "src.vtu", meshio.Mesh(
        src.points, [("tetra", src.cells)],
        point_data={"T": lin, "u": np.column_stack([lin, -lin, 2 * lin])},
        cell_data={"k": [np.full(src.num_cells, 7.0)],
                   "kv": [np.tile([1.0, -2.0, 3.0], (src.num_cells, 1))]}))
    meshio.write(d / "dst.vtu", meshio.Mesh(dst.points, [("hexahedron", dst.cells)]))
    meshio.write(d / "far.vtu", meshio.Mesh(far.points, [("tetra", far.cells)]))
    return d


# -- varcouple / --help / --version ------------------------------------------------
def test_help_subprocess():
    res = subprocess.run([sys.executable, "-m", "coupler.cli", "--help"], capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert res.returncode == 0, res.stderr
    assert "transfer" in res.stdout and "run" in res.stdout


def test_version_and_usage(capsys):
    code, out, _ = run_cli(capsys, "--version")
    assert code == 0 and out.startswith("varcouple ")
    code, _, err = run_cli(capsys)  # no subcommand: argparse usage error
    assert code == 2 and "Traceback" not in err
    code, _, err = run_cli(capsys, "transfer", "a.vtu", "b.vtu", "-o", "c.vtu", "-f", "T", "--method", "l3")
    assert code == 2 and "invalid choice" in err


# -- varcouple transfer ------------------------------------------------------------------
@pytest.mark.parametrize("method", ["l2", "pseudo_l2"])
def test_transfer_point_field(meshes, tmp_path, capsys, method):
    out = tmp_path / "out.vtu"
    code, stdout, err = run_cli(capsys, "transfer", meshes / "src.vtu", meshes / "dst.vtu",
                                "--field", "T", "-o", out, "--method", method)
    assert code == 0, err
    assert "conservation error" in stdout and "covered 100.00%" in stdout and method in stdout
    res = meshio.read(out)
    assert set(res.point_data) >= {"T", "covered"} and "T" not in res.cell_data
    assert res.cells[0].type == "hexahedron"
    # the linear field is in Q1: both projections reproduce it exactly
    np.testing.assert_allclose(res.point_data["T"], linear(res.points), atol=1e-10)
    assert np.all(res.point_data["covered"] == 1)


def test_transfer_vector_and_cell_fields(meshes, tmp_path, capsys):
    out = tmp_path / "u.vtu"
    code, _, err = run_cli(capsys, "transfer", meshes / "src.vtu", meshes / "dst.vtu", "-f", "u", "-o", out)
    assert code == 0, err
    u = meshio.read(out).point_data["u"]
    assert u.shape == (125, 3)  # 5 x 5 x 5 points of the hex target
    np.testing.assert_allclose(u[:, 1], -u[:, 0], atol=1e-12)

    out = tmp_path / "k.vtu"
    code, stdout, err = run_cli(capsys, "transfer", meshes / "src.vtu", meshes / "dst.vtu", "-f", "kv",
                                "-o", out, "--method", "pseudo_l2", "--threads", "2")
    assert code == 0, err
    assert "P0" in stdout and "Q0" in stdout
    res = meshio.read(out)
    assert "kv" in res.cell_data and "kv" not in res.point_data and "covered" in res.cell_data
    kv = res.cell_data["kv"][0]
    assert kv.shape == (64, 3)
    np.testing.assert_allclose(kv, np.tile([1.0, -2.0, 3.0], (64, 1)), atol=1e-12)  # constants are exact
    assert np.all(res.cell_data["covered"][0] == 1)


def test_transfer_partial_overlap_is_nan(meshes, tmp_path, capsys):
    half = box_tetrahedra((2, 2, 2), lower=(0.5, 0, 0), upper=(1.5, 1, 1))
    meshio.write(tmp_path / "half.vtu", meshio.Mesh(half.points, [("tetra", half.cells)]))
    out = tmp_path / "out.vtu"
    code, stdout, err = run_cli(capsys, "transfer", meshes / "src.vtu", tmp_path / "half.vtu", "-f", "k",
                                "-o", out)
    assert code == 0, err
    res = meshio.read(out)
    k, cov = res.cell_data["k"][0], res.cell_data["covered"][0]
    assert 0 < cov.sum() < len(cov) and "uncovered" in stdout
    assert np.all(np.isnan(k[cov == 0])) and np.allclose(k[cov == 1], 7.0)


def test_transfer_disjoint_meshes(meshes, tmp_path, capsys):
    out = tmp_path / "out.vtu"
    code, _, err = run_cli(capsys, "transfer", meshes / "src.vtu", meshes / "far.vtu", "-f", "T", "-o", out)
    assert_clean_error(code, err, "do not overlap", "src.vtu", "far.vtu")
    assert not out.exists()


def test_transfer_input_errors(meshes, tmp_path, capsys):
    out = tmp_path / "out.vtu"
    code, _, err = run_cli(capsys, "transfer", meshes / "src.vtu", meshes / "dst.vtu", "-f", "nope", "-o", out)
    assert_clean_error(code, err, "'nope'", "src.vtu")
    code, _, err = run_cli(capsys, "transfer", tmp_path / "missing.vtu", meshes / "dst.vtu", "-f", "T", "-o", out)
    assert_clean_error(code, err, "missing.vtu", "not found")
    (tmp_path / "bad.vtu").write_text("<VTKFile garbage")
    code, _, err = run_cli(capsys, "transfer", tmp_path / "bad.vtu", meshes / "dst.vtu", "-f", "T", "-o", out)
    assert_clean_error(code, err, "bad.vtu", "cannot read")
    wedge = meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1.0]]),
                        [("wedge", np.array([[0, 1, 2, 3, 4, 5]]))])
    meshio.write(tmp_path / "wedge.vtu", wedge)
    code, _, err = run_cli(capsys, "transfer", meshes / "src.vtu", tmp_path / "wedge.vtu", "-f", "T", "-o", out)
    assert_clean_error(code, err, "wedge.vtu", "unsupported cell type", "wedge")
    code, _, err = run_cli(capsys, "transfer", meshes / "src.vtu", meshes / "dst.vtu", "-f", "T",
                           "-o", tmp_path / "out.unknownext")
    assert_clean_error(code, err, "out.unknownext", "format")
    assert not out.exists()


# -- varcouple run -------------------------------------------------------------------------
def test_run_demo(tmp_path, capsys):
    before = sorted(p.relative_to(DEMO) for p in DEMO.rglob("*"))
    before = [p for p in before if p.parts[0] != "results"]
    out = tmp_path / "out"
    (out).mkdir()
    (out / "keep.txt").write_text("not ours")
    code, stdout, err = run_cli(capsys, "run", DEMO, "--output", out)
    assert code == 0, err
    assert "serving source: mesh_file in this process" in stdout and "l2 L2 error 2.924e-02" in stdout
    for name in ("source_0000.vtu", "target_l2_0000.vtu", "target_pseudo_l2_0000.vtu", "summary.json", "index.html"):
        assert (out / name).is_file(), name
    assert (out / "keep.txt").read_text() == "not ours"
    after = [p for p in sorted(p.relative_to(DEMO) for p in DEMO.rglob("*")) if p.parts[0] != "results"]
    assert after == before  # nothing written into the case itself

    summary = json.loads((out / "summary.json").read_text())
    assert [p["name"] for p in summary["participants"]] == ["source", "target_l2", "target_pseudo_l2"]
    assert all(p["in_process"] for p in summary["participants"])
    assert [e["operator"] for e in summary["exchanges"]] == ["l2", "pseudo_l2"]
    check = summary["check"]
    assert check["kind"] == "exact_transfer" and check["passed"] and set(check["methods"]) == {"l2", "pseudo_l2"}
    for method, m in check["methods"].items():
        projected = summary["steps"][0]["projections"][f"target_{method}.pressure"]
        assert projected["covered_fraction"] == 1.0 and projected["conservation_error"] < 1e-10
        assert 0 < m["max_error"] < 0.5
        # the L2 error against exact (2.9e-2, 3.1e-2) exceeds the distance to its interpolant (1.5e-2, 1.7e-2)
        assert 0.02 < m["relative_l2_error"] < 0.04 and 0.01 < m["relative_interpolant_distance"] < 0.02
    assert check["error"] == check["methods"]["pseudo_l2"]["relative_l2_error"]
    assert summary["sizes"]["source"]["cells"] == 1536 and summary["sizes"]["target_l2"]["cells"] == 3630
    assert check["source_max_difference"] < 1e-12

    res = meshio.read(out / "target_l2_0000.vtu")
    assert {"pressure", "covered"} <= set(res.point_data)
    assert len(res.point_data["pressure"]) == summary["sizes"]["target_l2"]["vertices"]


SCENE = """[physics]
effects = ["transfer"]
[transfer]
source = "rock_block.vtu"
target = "target_block.vtu"
field = "pressure"
method = "l2"
"""


@pytest.fixture
def case(tmp_path):
    d = tmp_path / "case"
    d.mkdir()
    for name in ("rock_block.vtu", "target_block.vtu"):
        shutil.copy(DEMO / name, d / name)
    return d


@pytest.mark.parametrize("text, words", [
    ("[transfer\nsource = 'a'\n", ["invalid TOML", "line 1"]),
    (SCENE.replace('field = "pressure"\n', ""), ["[transfer] field", "missing"]),
    (SCENE.replace('"l2"', '"l3"'), ["[transfer] method", "'l3'"]),
    (SCENE.replace('method = "l2"', 'methods = ["l2", "cubic"]'), ["[transfer] methods", "'cubic'"]),
    (SCENE.replace('"rock_block.vtu"', '"a.vtu"'), ["[transfer] source", "file 'a.vtu' not found"]),
    (SCENE.replace('"pressure"', '"temperature"'), ["[transfer] field", "'temperature'"]),
    (SCENE + "sorce = 'x'\n", ["[transfer] sorce", "unknown key"]),
    (SCENE + "[check]\nkind = 'exact_transfer'\nexact = 'foo(x)'\ntolerance = 0.1\n", ["[check] exact", "'foo'"]),
    (SCENE.replace("[physics]\neffects = [\"transfer\"]\n", ""), ["[physics] effects", "effects = [\"transfer\"]"]),
    (SCENE + "threads = 0\n", ["[transfer] threads"]),
    (SCENE + "[output]\ndirectory = 3\n", ["[output] directory"]),
])
def test_run_bad_scene(case, capsys, text, words):
    (case / "scene.toml").write_text(text)
    code, _, err = run_cli(capsys, "run", case)
    assert_clean_error(code, err, str(case / "scene.toml"), *words)
    assert not (case / "results").exists()


def test_run_missing_case(tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", tmp_path / "nothere")
    assert_clean_error(code, err, "nothere", "not found")
    code, _, err = run_cli(capsys, "run", tmp_path)
    assert_clean_error(code, err, "no scene.toml")
