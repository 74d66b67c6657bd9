"""[check] kinds (coupler/checks): each kind's keys validated where the scene is read, with
errors naming the scene file, [check] and the key; the comparisons against exact solutions."""

from __future__ import annotations

import numpy as np
import pytest

from coupler import checks
from coupler.errors import SceneError
from coupler.scene import load
from transfer.generate import box_tetrahedra
from vc_helpers import CASES, copy_case


def block(tmp_path, check: str):
    """cases/block_compression with `check` as its [check] table."""
    case = copy_case(CASES / "block_compression", tmp_path)
    scene = (case / "scene.toml").read_text().split("# uniaxial stress")[0]
    (case / "scene.toml").write_text(scene + "[check]\n" + check)
    return case


def test_every_kind_declares_the_interface():
    for kind, module in checks.KINDS.items():
        assert module.KIND == kind and module.DESCRIPTION and "tolerance" in module.KEYS
        assert all(callable(getattr(module, f)) for f in ("parse", "evaluate", "describe"))
    assert "expression" in checks.KINDS


@pytest.mark.parametrize("check, message", [
    ('kind = "nope"\ntolerance = 0.1\n', r"\[check\] kind: unknown value 'nope'; use one of .*'expression'"),
    ('z = "z"\ntolerance = 0.1\nradius = 1.0\n', r"\[check\] radius: unknown key; known keys: kind, x, y, z"),
    ('z = "z +"\ntolerance = 0.1\n', r"\[check\] z: invalid expression"),
    ('tolerance = 0.1\n', r"\[check\] z: give the expected displacement"),
    ('z = "z"\n', r"\[check\] tolerance: missing"),
    ('z = "z"\ntolerance = -1\n', r"\[check\] tolerance: must be positive"),
])
def test_bad_check_tables_name_the_key(tmp_path, check, message):
    with pytest.raises(SceneError, match=r"scene.toml: " + message):
        load(block(tmp_path, check))


def test_expression_is_the_default_kind(tmp_path):
    scene = load(block(tmp_path, 'z = "-1e6 * z / 1e10"\ntolerance = 1e-6\n'))
    assert scene.check == {"kind": "expression", "z": "-1e6 * z / 1e10", "tolerance": 1e-6}


def test_expression_check_of_a_result(tmp_path):
    """The largest error over the selected vertices relative to the largest expected value."""
    scene = load(block(tmp_path, 'z = "2 * z"\nwhere = "x < 0.5"\ntolerance = 0.1\n'))
    mesh = box_tetrahedra((2, 2, 2))
    u = np.zeros((mesh.num_points, 3))
    u[:, 2] = 2 * mesh.points[:, 2] + 0.05 * (mesh.points[:, 0] > 0.25)  # off by 0.05 at x = 0.5 and 1 only
    report = checks.evaluate(scene, checks.Result({"solid": mesh}, {"solid": {"displacement": u}}))
    left = mesh.points[:, 0] < 0.5
    assert report == {"kind": "expression", "error": 0.0, "absolute_error": 0.0, "tolerance": 0.1, "passed": True,
                      "vertices": int(left.sum())}
    scene.check["where"] = "x < 0.75"
    report = checks.evaluate(scene, checks.Result({"solid": mesh}, {"solid": {"displacement": u}}))
    assert report["error"] == pytest.approx(0.05 / 2.0) and report["passed"]
    assert "relative on 18 vertices (tolerance 0.1): PASS" in checks.describe(report)
    scene.check["where"] = "x > 2"
    with pytest.raises(Exception, match=r"scene.toml: \[check\] where: 'x > 2' selects no vertex"):
        checks.evaluate(scene, checks.Result({"solid": mesh}, {"solid": {"displacement": u}}))
