"""Scene input of the solid's load steps and geometry generators: the platen (stress-controlled
load steps), loads given per step, ``[geometry.solid] generator`` with its parameters, and the
fluid in a fracture with contact; every error one line naming the scene file, table, key and
reason."""

from __future__ import annotations

import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.plan.plan import make_plan
from coupler.scene import load
from vc_helpers import CASES, copy_case

CLOSURE = CASES / "fracture_closure"
FIGURE12 = CASES / "fracture_open_by_pressure"
STRESSES = "stress = [1.0e6, 2.0e6, 4.0e6, 6.0e6, 10.0e6, 15.0e6, 20.0e6]   # [Pa], one load step each"


def test_steps_come_from_the_per_step_loads():
    scene = load(FIGURE12)
    assert scene.time["steps"] == 2
    platen, lower = scene.loads[1], scene.loads[2]
    assert platen.per_step and platen.value == [2e6, 2e6] and platen.settings["tolerance"] == 1e-3
    assert lower.type == "fluid_pressure" and lower.per_step and lower.value == [0.0, 1e6]
    config = make_plan(scene).participant("solid").config
    generator = config["generator"]
    assert generator["name"] == "fracture_specimen" and generator["parameters"]["lattice"] == [16, 16, 5]
    assert generator["parameters"]["seed"] == 5 and generator["parameters"]["ratio"] == 2  # defaults filled in
    assert config["loads"][1] == {"type": "platen", "key": "[loads.2]", "boundary": "top", "value": [2e6, 2e6],
                                  "components": ["x", "y", "z"], "tolerance": 1e-3, "max_iterations": 20,
                                  "method": "search", "area": 0.01168986626400762}
    assert {"fracture_lower", "fracture_upper", "top", "bottom"} <= set(scene.solid.boundaries)


@pytest.mark.parametrize("case, replace, message", [
    (CLOSURE, {STRESSES: "stress = 2.0e6"}, "[loads.2] stress: must be a non-empty list of finite numbers, one per step"),
    (CLOSURE, {STRESSES: "stress = [1.0e6, -2.0e6]"}, "[loads.2] stress: mean normal stresses are compressive"),
    (CLOSURE, {STRESSES: "stress = [1.0e6]\nvalue = 1.0"}, "[loads.2] value: a platen is stress-controlled"),
    (CLOSURE, {"boundary = \"bottom\"": "boundary = \"bottom\"\ntolerance = 0.1"},
     "[loads.1] tolerance: only platen loads have it"),
    (CLOSURE, {"[contact]": "[[loads]]\ntype = \"platen\"\nboundary = \"bottom\"\nstress = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, "
                           "7.0]\n\n[contact]"}, "[[loads]]: more than one platen"),
    (CLOSURE, {"[contact]": "[time]\nsteps = 3\n\n[contact]"},
     "[loads.2] stress: 7 values, one per step, but [time] steps is 3 steps"),
    (FIGURE12, {"value = [0.0, 1.0e6]            # no fluid, then 1 MPa [Pa]": "value = [0.0, 1.0e6, 1.0e6]"},
     "[loads.2] stress: 2 values, one per step, but another load has 3 steps"),
    (FIGURE12, {"boundary = \"fracture_upper\"\nvalue = [0.0, 1.0e6]": "boundary = \"fracture_upper\"\nvalue = [0.0, 2.0e6]"},
     "[loads.3] value: the fluid in the fracture presses on both contact faces: give the same fluid_pressure on "
     "'fracture_upper' too"),
    (CLOSURE, {"generator = \"fracture_specimen\"": "generator = \"sphere\""},
     "[geometry.solid] generator: unknown value 'sphere'; use one of 'fracture_specimen', 'hertz'"),
    (CLOSURE, {"seed = 5": "seed = 5\ncolour = 1"},
     "[geometry.solid.parameters] colour: unknown parameter of generator 'fracture_specimen'; known: shape"),
    (CLOSURE, {"lattice = [16, 16, 5]": "lattice = [16, 16]"},
     "[geometry.solid.parameters] lattice: must be a list of 3 integers, got [16, 16]"),
    (CLOSURE, {"generator = \"fracture_specimen\"": "generator = \"fracture_specimen\"\nmesh = \"scene.toml\""},
     "[geometry.solid] generator: give one of a mesh file, the box keys (lower, upper, shape) or a generator"),
    (CLOSURE, {"generator = \"fracture_specimen\"": "generator = \"fracture_specimen\"\nboundaries = { top = \"z > 0\" }"},
     "[geometry.solid.boundaries] top: the generator names a face 'top' already"),
])
def test_bad_scene_is_one_line_naming_the_key(tmp_path, capsys, case, replace, message):
    copy = copy_case(case, tmp_path, replace)
    with pytest.raises(SceneError) as err:
        load(copy)
    assert str(copy / "scene.toml") in str(err.value) and message in str(err.value), str(err.value)
    assert main(["check", "--quick", str(copy)]) == 2
    assert message in capsys.readouterr().err


def test_parameters_without_a_generator(tmp_path):
    case = copy_case(CASES / "cube_obstacle", tmp_path, {"shape = [25, 25, 25]": "shape = [25, 25, 25]\n"
                                                         "parameters = { cells = 3 }"})
    with pytest.raises(SceneError, match=r"\[geometry.solid\] parameters: parameters of no generator"):
        load(case)


def test_a_platen_is_static(tmp_path):
    case = copy_case(CASES / "fracture_closure", tmp_path, {"effects = [\"elasticity\", \"contact\"]":
                                                            "effects = [\"elasticity\", \"dynamics\"]",
                                                            "[contact]": "[time]\ndt = 1.0\nsteps = 7\n\n[contact]"})
    text = (case / "scene.toml").read_text()
    (case / "scene.toml").write_text(text[:text.index("[contact]")])
    with pytest.raises(SceneError, match=r"\[loads.2\] type: a platen \(stress-controlled load steps\) is static: "
                                         r"not with 'dynamics'"):
        load(case)
