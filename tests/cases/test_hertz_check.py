"""The Hertz [check] at another sphere (R = 0.5 m on the same block, 0.02 m contact cells,
the same platen push): its contact radius and peak pressure are compared with Hertz theory
for R, E and nu of that scene."""

from __future__ import annotations

import json

import pytest

from coupler.checks.hertz import theory
from coupler.cli import main
from vc_helpers import CASES, NEEDS_GMSH, copy_case, hertz_mesh_file

SLAVE_R1 = 'slave = "(z > 1e-12) & (z < 0.3) & (abs(sqrt(x**2 + y**2 + (z - 1)**2) - 1) < 0.05)"'
SLAVE_R05 = 'slave = "(z > 1e-12) & (z < 0.15) & (abs(sqrt(x**2 + y**2 + (z - 0.5)**2) - 0.5) < 0.025)"'


@NEEDS_GMSH
def test_hertz_check_at_half_the_radius(tmp_path, capsys):
    case = copy_case(CASES / "hertz", tmp_path, {SLAVE_R1: SLAVE_R05, "radius = 1.0": "radius = 0.5"})
    hertz_mesh_file(case / "hertz.msh", radius=0.5, half_width=1.0, depth=1.0, h_contact=0.02, h_far=0.3,
                    refine_radius=0.15, grading_radius=1.0)
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0
    check = json.loads((out / "summary.json").read_text())["check"]
    assert check["kind"] == "hertz" and check["radius"] == 0.5 and check["passed"]
    E, nu = 1e9, 0.3
    assert (check["a_hertz"], check["p0_hertz"]) == pytest.approx(theory(check["force"], 0.5, E, nu), rel=1e-12)
    assert check["error_a"] < 0.03 and check["error_p0"] < 0.08  # measured: 1.6 %, 5.9 %
    assert check["error"] == max(check["error_a"], check["error_p0"])
    # the sphere's radius matters: Hertz for R = 1 m is 26 % off the measured contact radius
    assert abs(check["a"] / theory(check["force"], 1.0, E, nu)[0] - 1) > 0.2
    assert "check: Hertz (R = 0.5 m" in capsys.readouterr().out
