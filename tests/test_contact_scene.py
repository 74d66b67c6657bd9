"""The `contact` effect in scenes: [contact] keys validated with clear errors, the
plan, the solid participant solving load steps with contact (in process), a
scene without contact never building contact operators, and `varcouple run
cases/hertz` end to end (slow)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gmsh")

from coupler.coupled_run import participant_config  # noqa: E402
from coupler.errors import SceneError  # noqa: E402
from coupler.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402

from vc_helpers import copy_case  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HERTZ = ROOT / "cases" / "hertz"


def hertz_copy(tmp_path, replace=None):
    return copy_case(HERTZ, tmp_path, replace)


def test_plan_of_the_hertz_scene():
    scene = load(HERTZ)
    assert scene.contact == {"slave": "slave", "master": "block_top", "solver": "active_set", "tolerance": 1e-10,
                             "max_iterations": 100, "search_distance": 0.1, "max_normal_angle": 45.0}
    plan = make_plan(scene)
    assert [p.name for p in plan.participants] == ["solid"]
    assert "dual basis on the slave" in plan.couplings[0].operator
    assert "2 load steps" in plan.iteration
    config = participant_config(scene, "solid")
    assert config["contact"]["master"] == "block_top" and config["steps"] == 2


@pytest.mark.parametrize("replace, message", [
    ({'solver = "active_set"': 'solver = "newton"'}, r"\[contact\] solver: .*newton"),
    ({'master = "block_top"': 'master = "nope"'}, r"\[contact\] master: unknown boundary 'nope'"),
    ({'master = "block_top"': 'master = "slave"'}, r"\[contact\] master: the same boundary as slave"),
    ({'effects = ["elasticity", "contact"]': 'effects = ["elasticity"]'},
     r"\[contact\] slave: a \[contact\] table needs the effect 'contact'"),
    ({'effects = ["elasticity", "contact"]': 'effects = ["elasticity", "contact", "dynamics"]',
      "steps = 2": "steps = 2\ndt = 1.0"}, r"'contact' with 'dynamics' is not supported"),
    ({"search_distance = 0.1": "search_distance = -1.0"}, r"\[contact\] search_distance: must be positive"),
    ({"[contact]": "[contact]\nfriction = 0.3"}, r"\[contact\].*friction"),
])
def test_bad_contact_tables(tmp_path, replace, message):
    with pytest.raises(SceneError, match=message):
        load(hertz_copy(tmp_path, replace))


def test_contact_effect_without_table(tmp_path):
    case = hertz_copy(tmp_path)
    scene = (case / "scene.toml").read_text()
    (case / "scene.toml").write_text(scene[:scene.index("[contact]")] + scene[scene.index("[time]"):])
    with pytest.raises(SceneError, match=r"\[contact\] slave: missing: the effect 'contact' needs"):
        load(case)


def _advance(config, steps):
    from solid_fenicsx.participant import SolidParticipant

    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p, [p.advance(w, 0, float(w), 1.0, {}) for w in range(steps)]


def test_solid_participant_ramps_the_load_with_contact():
    scene = load(HERTZ)
    p, outs = _advance(participant_config(scene, "solid"), 2)
    assert p.contact is not None
    from coupler.protocol import CONTACT_STATS

    stats = [dict(zip(CONTACT_STATS, o["contact_stats"].data)) for o in outs]
    assert stats[0]["force_z"] > 0 and stats[1]["force_z"] > 2 * stats[0]["force_z"]  # a stiffening contact
    u = outs[1]["displacement"].data
    assert np.isclose(u[:, 2].min(), -0.02)
    pressure = outs[1]["contact_pressure"].data
    assert pressure.shape == (len(u),) and pressure.max() == pytest.approx(stats[1]["max_pressure"])


def test_a_scene_without_contact_never_builds_contact_operators(monkeypatch):
    import solid_fenicsx.contact as contact
    import solid_fenicsx.mortar as mortar

    def forbidden(*args, **kwargs):
        raise AssertionError("contact operators built for a scene without contact")

    monkeypatch.setattr(contact.Contact, "__init__", forbidden)
    monkeypatch.setattr(mortar, "mortar", forbidden)
    scene = load(ROOT / "cases" / "block_compression")
    assert scene.contact is None and "contact" not in participant_config(scene, "solid")
    p, outs = _advance(participant_config(scene, "solid"), 1)
    assert p.contact is None and "contact_stats" not in outs[0]


@pytest.mark.slow
def test_varcouple_run_hertz(tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(HERTZ), "--output", str(out)],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    last = summary["steps"][-1]["contact"]
    assert last["min_gap"] > -1e-10 and last["force_z"] > 0
    assert (out / "solid_0001.vtu").exists()
