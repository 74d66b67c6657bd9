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
    assert {"expression", "uniaxial", "sneddon", "hertz"} <= set(checks.KINDS)


@pytest.mark.parametrize("check, message", [
    ('kind = "nope"\ntolerance = 0.1\n', r"\[check\] kind: unknown value 'nope'; use one of .*'expression'"),
    ('z = "z"\ntolerance = 0.1\nradius = 1.0\n', r"\[check\] radius: unknown key; known keys: kind, x, y, z"),
    ('z = "z +"\ntolerance = 0.1\n', r"\[check\] z: invalid expression"),
    ('tolerance = 0.1\n', r"\[check\] z: give the expected displacement"),
    ('z = "z"\n', r"\[check\] tolerance: missing"),
    ('z = "z"\ntolerance = -1\n', r"\[check\] tolerance: must be positive"),
    ('kind = "uniaxial"\n', r"\[check\] tolerance: missing"),
    ('kind = "uniaxial"\nz = "z"\ntolerance = 0.1\n', r"\[check\] z: unknown key; known keys: kind, tolerance"),
    ('kind = "sneddon"\ntolerance = 0.1\n', r"\[check\] radius: missing \(the crack's radius a \[m\]\)"),
    ('kind = "sneddon"\nradius = 0.1\ncompared = 1.5\ntolerance = 0.1\n', r"\[check\] compared: must lie in"),
    ('kind = "hertz"\nradius = 1.0\ntolerance = 0.1\n', r"\[check\] kind: 'hertz' needs the effect 'contact'"),
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


@pytest.mark.parametrize("replace, message", [
    ({'kind = "sneddon"': 'kind = "uniaxial"', "radius = 0.1\ncompared = 0.8\n": ""},
     r"\[check\] kind: 'uniaxial' needs exactly one load besides the rollers, a pressure on a face; got "
     r"\['fluid_pressure'\]"),
    ({"[solvers.solid]": '[[loads]]\ntype = "pressure"\nboundary = "xsym"\nvalue = 1.0\n\n[solvers.solid]'},
     r"\[check\] kind: 'sneddon' needs exactly one pressure load \(one of fluid_pressure, pressure\) on the "
     r"crack's faces; the scene has 2"),
])
def test_a_kind_that_does_not_fit_the_scene(tmp_path, replace, message):
    with pytest.raises(SceneError, match=r"scene.toml: " + message):
        load(copy_case(CASES / "pressurized_fracture", tmp_path, replace))


def test_uniaxial_needs_rollers(tmp_path):
    case = copy_case(CASES / "block_compression", tmp_path, {'boundary = "ymin"\ncomponents = ["y"]':
                                                             'boundary = "ymin"\ncomponents = ["x", "y"]'})
    with pytest.raises(SceneError, match=r"\[check\] kind: 'uniaxial' needs rollers: .* 'ymin' holds \['x', 'y'\]"):
        load(case)


def test_uniaxial_needs_a_box_face(tmp_path):
    case = copy_case(CASES / "block_compression", tmp_path, {
        'boundary = "zmax"': 'boundary = "top"', "[materials.solid]": '[geometry.solid.boundaries]\ntop = "z > 0.99"'
                                                                      '\n\n[materials.solid]'})
    with pytest.raises(SceneError, match=r"\[check\] kind: 'uniaxial' needs a box .* pressure load on 'top'"):
        load(case)


def test_hertz_fit_recovers_an_exact_hertz_pressure():
    """Nodal pressures p0 sqrt(1 - r^2/a^2) on a fine tilted disc around a shifted centre, with
    their areas as mortar weights: the fit gives a and p0 to round-off, the force is the
    integral of the profile (2/3 pi a^2 p0) to the quadrature error, and Hertz's a and p0 for
    that force agree with the profile's when R, E, nu are those that made it."""
    from coupler.checks.hertz import fit, theory

    F, R, E, nu = 2.0e6, 0.5, 1e9, 0.3
    a, p0 = theory(F, R, E, nu)
    assert p0 == pytest.approx(3 * F / (2 * np.pi * a * a)) and a == pytest.approx(
        (3 * F * R / (4 * E / (2 * (1 - nu**2)))) ** (1 / 3))
    h = a / 200
    s = np.arange(-2 * a, 2 * a + h / 2, h)
    X, Y = np.meshgrid(s, s)
    flat = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    tilt = np.radians(20)
    rotation = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    centre = np.array([0.3, -0.2, 0.1])
    points = flat @ rotation.T + centre
    r2 = X.ravel() ** 2 + Y.ravel() ** 2
    pressure = p0 * np.sqrt(np.clip(1 - r2 / a**2, 0, None))
    measured = fit(points, pressure, np.full(len(points), h * h), "test")
    assert measured["a"] == pytest.approx(a, rel=1e-9) and measured["p0"] == pytest.approx(p0, rel=1e-9)
    assert measured["force"] == pytest.approx(F, rel=1e-3)
    np.testing.assert_allclose(measured["centre"], centre, atol=1e-12)
    assert abs(np.dot(measured["normal"], rotation[:, 2])) == pytest.approx(1.0)
    with pytest.raises(Exception, match="test: 0 slave vertices carry pressure"):
        fit(points, 0 * pressure, np.full(len(points), h * h), "test")


def test_varcouple_check_prints_the_check(capsys):
    from coupler.cli import main

    assert main(["check", "--quick", str(CASES / "hertz")]) == 0
    assert "check         hertz: a sphere pressed onto a block: contact radius and peak pressure against Hertz " \
           "theory (tolerance 0.1)" in capsys.readouterr().out
