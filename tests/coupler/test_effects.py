"""Effects are rules, one module each (coupler/plan/effects): a new effect is one module.

The dummy effect below is such a module, written here and registered for the test: it owns a
table ([dummy] scale), checks it when the scene is read, and adds an exchange that carries
the solid's displacement to the fluid's grid by the pseudo-L2 projection; nothing else of
the coupler knows it, and the generic runner executes it."""

import json
import types

import meshio
import numpy as np
import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.plan import effects
from coupler.plan.plan import Exchange, make_plan
from coupler.scene import load
from coupler.scene.tables import Table
from vc_helpers import CASES, copy_case


def dummy_rule() -> types.ModuleType:
    rule = types.ModuleType("dummy")
    rule.NAME, rule.DESCRIPTION, rule.ORDER = "dummy", "a test effect: the displacement on the grid", 9
    rule.TABLES = {"dummy": {"scale": "a positive number"}}

    def parse(scene, data):
        t = Table(scene.path, "dummy", data.get("dummy", {}), rule.TABLES["dummy"])
        scene.effect_settings["dummy"] = {"scale": t.number("scale", positive=True)}

    def plan(scene, plan):
        plan.exchanges.append(Exchange(["solid.displacement"], "fluid.displacement_on_grid", "pseudo_l2", "6",
                                       description=f"scale {scene.effect_settings['dummy']['scale']:g}"))

    rule.parse, rule.plan = parse, plan
    return rule


@pytest.fixture
def with_dummy(monkeypatch):
    monkeypatch.setitem(effects.RULES, "dummy", dummy_rule())


def scene_with_dummy(tmp_path, extra="[dummy]\nscale = 2.0\n"):
    case = copy_case(CASES / "standin_flow", tmp_path, {'"dynamics", "flow"]': '"dynamics", "flow", "dummy"]',
                                                      "steps = 4": "steps = 2"})
    (case / "scene.toml").write_text((case / "scene.toml").read_text() + "\n" + extra)
    return case


def test_a_dummy_effect_validates_its_table_and_plans_its_exchange(tmp_path, with_dummy):
    scene = load(scene_with_dummy(tmp_path))
    assert scene.effect_settings["dummy"] == {"scale": 2.0}
    plan = make_plan(scene)
    assert plan.exchanges[-1].target == "fluid.displacement_on_grid" and plan.exchanges[-1].operator == "pseudo_l2"
    with pytest.raises(SceneError, match=r"\[dummy\] scale: must be positive"):
        load(scene_with_dummy(tmp_path / "bad", "[dummy]\nscale = -1.0\n"))


def test_a_dummy_effect_runs_through_the_generic_runner(tmp_path, with_dummy, capsys):
    out = tmp_path / "out"
    assert main(["run", str(scene_with_dummy(tmp_path)), "--output", str(out)]) == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exchanges"][-1]["operator"] == "pseudo_l2"
    solid, fluid = meshio.read(out / "solid_0001.vtu"), meshio.read(out / "fluid_0001.vtu")
    on_grid = fluid.cell_data["displacement_on_grid"][0]
    # the spring solid moves uniformly in z: the projection reproduces that constant in the cells it fills
    uz = solid.point_data["displacement"][:, 2]
    assert np.ptp(uz) < 1e-12 * abs(uz).max()
    filled = fluid.cell_data["solid_fraction"][0] > 1 - 1e-12
    np.testing.assert_allclose(on_grid[filled, 2], uz[0], rtol=1e-12)
    assert np.all(on_grid[fluid.cell_data["solid_fraction"][0] == 0] == 0)


def test_an_effect_table_without_its_effect_is_refused(tmp_path, with_dummy):
    case = copy_case(CASES / "standin_flow", tmp_path)
    (case / "scene.toml").write_text((case / "scene.toml").read_text() + "\n[dummy]\nscale = 2.0\n")
    with pytest.raises(SceneError, match=r"\[dummy\]: needs the effect 'dummy'"):
        load(case)
