"""Coupled scenes and their plans: only the effects asked for are simulated,
and every bad scene gives one error naming the file, the key and the reason."""

import textwrap

import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.plan.plan import make_plan
from coupler.scene import load

BASE = """
[physics]
effects = {effects}

[geometry.solid]
lower = [0, 0, 0]
upper = [1, 1, 1]
shape = [2, 2, 2]

[geometry.solid.boundaries]
crack = "(z > 0.99) & (x < 0.5)"

[materials.solid]
E = 1e10
nu = 0.25

[[loads]]
type = "dirichlet"
boundary = "zmin"
"""


def write(tmp_path, text):
    (tmp_path / "scene.toml").write_text(textwrap.dedent(text))
    return tmp_path


def scene_text(effects, extra=""):
    return BASE.format(effects=effects) + extra


FLUID = """
[geometry.fluid]
lower = [-0.5, -0.5, -0.5]
upper = [1.5, 1.5, 1.5]
shape = [8, 8, 8]

[time]
dt = 0.01
steps = 3

[solvers.fluid]
participant = "replay_fluid"

[coupling]
interface = "crack"
"""
FLUID_PRESSURE = """
[[loads]]
type = "fluid_pressure"
boundary = "crack"
value = 1e6
"""


def test_elasticity_alone_starts_the_solid_alone(tmp_path):
    plan = make_plan(load(write(tmp_path, scene_text('["elasticity"]'))))
    assert [p.name for p in plan.participants] == ["solid"]
    assert plan.exchanges == [] and not plan.implicit
    summary = plan.as_dict()
    assert summary["participants"][0]["kind"] == "solid_fenicsx"
    assert set(summary) >= {"participants", "effects", "exchanges"}


def test_static_fluid_pressure_is_a_load_without_fluid_solver(tmp_path):
    scene = load(write(tmp_path, scene_text('["elasticity", "fluid_pressure"]', FLUID_PRESSURE)))
    plan = make_plan(scene)
    assert [p.name for p in plan.participants] == ["solid"]
    assert any("static fluid pressure" in line and "crack" in line for line in plan.loads)


def test_flow_and_deformation_start_both_and_couple_them(tmp_path):
    plan = make_plan(load(write(tmp_path, scene_text('["elasticity", "flow"]', FLUID))))
    assert [p.name for p in plan.participants] == ["solid", "fluid"]
    crossing = {(tuple(e.sources), e.target, e.operator, e.accelerated) for e in plan.exchanges}
    # quasi-static: the pressure is the accelerated interface quantity, the solid fraction follows the
    # deformed solid, and no solid velocity reaches the grid (the solid is at rest in each step)
    assert crossing == {(("fluid.pressure",), "solid.pressure", "pressure_trace", True),
                        (("solid.displacement",), "fluid.solid_fraction", "solid_fraction", False)}
    assert plan.implicit and "implicit" in plan.iteration


def test_a_moving_solid_sends_its_velocity_to_the_grid(tmp_path):
    plan = make_plan(load(write(tmp_path, scene_text('["elasticity", "dynamics", "flow"]', FLUID))))
    velocity = [e for e in plan.exchanges if e.target == "fluid.solid_velocity"]
    assert len(velocity) == 1 and velocity[0].operator == "solid_velocity" and velocity[0].step == "6"
    assert plan.participant("solid").config["dynamic"]


def test_check_prints_the_plan(tmp_path, capsys):
    case = write(tmp_path, scene_text('["elasticity", "fluid_pressure"]', FLUID_PRESSURE))
    assert main(["check", str(case)]) == 0
    out = capsys.readouterr().out
    assert "participant   solid: solid_fenicsx" in out
    assert "fluid" not in out.split("participant")[-1].split("\n")[0]
    assert "exchanges     none" in out


def test_nearly_incompressible_gets_a_note(tmp_path):
    text = scene_text('["elasticity"]').replace("nu = 0.25", "nu = 0.499")
    plan = make_plan(load(write(tmp_path, text)))
    assert any("incompressible" in n and "degree = 2" in n for n in plan.notes)


BAD = [
    ('["elasticity", "flow"]', "", "[geometry] fluid", "no fluid domain"),
    ('["dynamics"]', "", "[physics] effects", "'dynamics' needs 'elasticity'"),
    ('["elasticity", "magic"]', "", "[physics] effects", "unknown value 'magic'"),
    ('["elasticity", "fluid_pressure"]', "", "[physics] effects", "fluid_pressure"),
    ('["elasticity"]', '\n[[loads]]\ntype = "pressure"\nboundary = "roof"\nvalue = 1.0\n',
     "[loads.2] boundary", "unknown boundary 'roof'"),
    ('["elasticity"]', '\n[solvers.solid]\nparticipant = "abaqus"\n', "[solvers.solid] participant",
     "unknown value 'abaqus'"),
    ('["elasticity"]', '\n[coupling]\nacceleration = "newton"\n', "[coupling] acceleration", "unknown value"),
    ('["elasticity", "flow"]', FLUID.replace('interface = "crack"', 'interface = "roof"'), "[coupling] interface",
     "unknown boundary 'roof'"),
    ('["elasticity"]', '\n[time]\ndt = -1.0\n', "[time] dt", "must be positive"),
    ('["elasticity"]', '\n[weather]\nrain = 1\n', "unknown table [weather]", ""),
    ('["elasticity", "dynamics"]', "", "[time] dt", "missing"),
]


@pytest.mark.parametrize("effects, extra, where, reason", BAD)
def test_bad_scenes_name_file_key_and_reason(tmp_path, capsys, effects, extra, where, reason):
    case = write(tmp_path, scene_text(effects, extra))
    with pytest.raises(SceneError) as info:
        load(case)
    message = str(info.value)
    assert str(case / "scene.toml") in message and where in message and reason in message
    assert main(["check", str(case)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("varcouple: error: ") and "Traceback" not in err


def test_contact_needs_its_table(tmp_path):
    """The effect 'contact' exists now (tests/test_contact_scene.py); without a [contact]
    table naming the two boundaries the scene is refused."""
    with pytest.raises(SceneError, match=r"\[contact\] slave: missing: the effect 'contact' needs a \[contact\]"):
        load(write(tmp_path, scene_text('["elasticity", "contact"]')))


def test_missing_supports_are_an_error(tmp_path):
    text = scene_text('["elasticity"]').replace('type = "dirichlet"\nboundary = "zmin"',
                                                'type = "pressure"\nboundary = "zmax"\nvalue = 1.0')
    with pytest.raises(SceneError, match="no dirichlet load"):
        load(write(tmp_path, text))


def test_shipped_cases_are_valid(capsys):
    for case in ("cases/block_compression", "cases/transfer_demo", "cases/plates_fsi"):
        assert main(["check", case]) == 0, capsys.readouterr().err
