"""The `contact` effect in scenes: [contact] keys validated with clear errors, the
plan, the solid participant solving load steps with contact (in process), a
scene without contact never building contact operators, and `varcouple run
cases/hertz` end to end (slow)."""

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("gmsh")

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.errors import SceneError  # noqa: E402
from coupler.scene import load  # noqa: E402

from vc_helpers import ROOT, copy_case  # noqa: E402

HERTZ = ROOT / "cases" / "hertz"


def hertz_copy(tmp_path, replace=None):
    return copy_case(HERTZ, tmp_path, replace)


def test_plan_of_the_hertz_scene():
    scene = load(HERTZ)
    assert scene.contact == {"slave": "slave", "master": "block_top", "solver": "active_set", "tolerance": 1e-10,
                             "max_iterations": 100, "search_distance": 0.1, "max_normal_angle": 45.0}
    plan = make_plan(scene)
    assert [p.name for p in plan.participants] == ["solid"]
    assert plan.exchanges == [] and "dual basis on the slave" in plan.tasks[0]
    assert "2 load steps" in plan.iteration
    config = make_plan(scene).participant("solid").config
    assert config["contact"]["master"] == "block_top" and config["steps"] == 2


@pytest.mark.parametrize("replace, message", [
    ({'solver = "active_set"': 'solver = "newton"'}, r"\[contact\] solver: .*newton"),
    ({'master = "block_top"': 'master = "nope"'}, r"\[contact\] master: unknown boundary 'nope'"),
    ({'master = "block_top"': 'master = "slave"'}, r"\[contact\] master: the same boundary as slave"),
    ({'effects = ["elasticity", "contact"]': 'effects = ["elasticity"]'},
     r"\[contact\]: needs the effect 'contact'"),
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
    """The participant and, per load step, (outputs, solve reports, figures)."""
    from solid_fenicsx.participant import SolidParticipant

    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p, [(p.advance(w, 0, float(w), 1.0, {}), *p.take_reports()) for w in range(steps)]


def test_solid_participant_ramps_the_load_with_contact():
    scene = load(HERTZ)
    p, steps = _advance(make_plan(scene).participant("solid").config, 2)
    assert p.contact is not None
    for _, (report,), figures in steps:
        assert report.solver == "contact active_set" and report.converged
        assert report.iterations == figures["iterations"] >= 1 and report.residual <= report.tolerance == 1e-10
    first, last = steps[0][2], steps[1][2]
    assert first["force_z"] > 0 and last["force_z"] > 2 * first["force_z"]  # a stiffening contact
    assert last["krylov_iterations"] > 0 and 0 < last["area_fraction"] < 1 and last["min_gap"] > -1e-10
    u = steps[1][0]["displacement"].data
    assert np.isclose(u[:, 2].min(), -0.02)
    pressure = steps[1][0]["contact_pressure"].data
    assert pressure.shape == (len(u),) and pressure.max() == pytest.approx(last["max_pressure"])


def test_contact_fields_are_zero_off_contact_and_balance_the_load():
    """The vertex fields of a Hertz step: pressure exactly 0 where in_contact is 0 (inactive
    slave nodes had up to 0.19 Pa), the slave face and its mortar weights D_kk, so that
    sum(pressure * mortar_weight) is the normal contact force (the active normal multipliers
    of the QP), along the slave normals the force figures, balanced by the load's reaction."""
    import dolfinx.fem

    p, steps = _advance(make_plan(load(HERTZ)).participant("solid").config, 2)
    out, _, figures = steps[-1]
    pressure, in_contact, slave, weight = (out[k].data for k in ("contact_pressure", "in_contact", "slave",
                                                                 "mortar_weight"))
    assert all(np.all(np.isfinite(f)) for f in (pressure, in_contact, slave, weight))
    m = p.contact.mortar
    assert slave.sum() == len(m.slave.nodes) and set(np.unique(slave)) == set(np.unique(in_contact)) == {0.0, 1.0}
    assert np.all(slave[in_contact == 1] == 1) and in_contact.sum() == figures["active_nodes"]
    assert np.all(pressure[in_contact == 0] == 0.0) and pressure.max() > 0 and pressure.min() == 0.0
    assert np.all(weight[slave == 0] == 0.0) and weight.sum() == pytest.approx(m.weights.sum(), rel=1e-14)
    qp = p.contact.problem()
    lam = qp.multiplier(p.contact.x)
    closed = p.contact.x[p.contact.normal_dofs] >= qp.upper[p.contact.normal_dofs] - 1e-9 * 0.02
    normal_force = lam[p.contact.normal_dofs][closed].sum()
    assert (pressure * weight).sum() == pytest.approx(normal_force, rel=1e-10)
    normals = dolfinx.fem.Function(p.solver.V)
    normals.x.array.reshape(-1, 3)[p.contact.dofs[m.slave.nodes]] = m.normals  # faces: input numbering
    force = -((pressure * weight)[:, None] * p.solver.vertices.gather(normals)).sum(axis=0)
    assert force == pytest.approx([figures["force_x"], figures["force_y"], figures["force_z"]], rel=1e-10)
    assert p.contact.elasticity.boundary_force("load")[2] == pytest.approx(-force[2], rel=1e-9)  # 3.7e-12 measured


def test_a_coupling_iteration_starts_from_the_previous_contact_solution():
    """restore_state (before every coupling iteration after the first) keeps the contact's
    start: the second iteration of a window with the same inputs starts at the first's
    solution and needs one active-set iteration (from the window's start it took 5)."""
    from solid_fenicsx.participant import SolidParticipant

    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(make_plan(load(HERTZ)).participant("solid").config)
    p.save_state(0)
    first = [p.advance(0, 0, 0.0, 1.0, {}), *p.take_reports()]
    p.restore_state(0)
    second = [p.advance(0, 1, 0.0, 1.0, {}), *p.take_reports()]
    (cold,), (warm,) = first[1], second[1]
    assert cold.iterations >= 3 and warm.iterations == 1 and warm.converged
    assert second[2]["force_z"] == pytest.approx(first[2]["force_z"], rel=1e-9)
    assert np.allclose(second[0]["displacement"].data, first[0]["displacement"].data, rtol=0, atol=1e-9 * 0.02)


def test_an_unconverged_contact_solve_is_reported():
    """[contact] max_iterations = 1: the step returns its (finite) iterate and reports the
    active-set solve unconverged, its criterion above the tolerance."""
    config = make_plan(load(HERTZ)).participant("solid").config
    config["contact"] = {**config["contact"], "max_iterations": 1}
    _, [(out, (report,), figures)] = _advance(config, 1)
    assert (report.solver, report.converged, report.iterations) == ("contact active_set", False, 1)
    assert report.residual > 1e3 * report.tolerance and report.detail.startswith("iteration limit")
    assert figures["iterations"] == 1 and np.all(np.isfinite(out["displacement"].data))


def test_a_scene_without_contact_never_builds_contact_operators(monkeypatch):
    import solid_fenicsx.contact as contact
    import solid_fenicsx.mortar as mortar

    def forbidden(*args, **kwargs):
        raise AssertionError("contact operators built for a scene without contact")

    monkeypatch.setattr(contact.Contact, "__init__", forbidden)
    monkeypatch.setattr(mortar, "mortar", forbidden)
    scene = load(ROOT / "cases" / "block_compression")
    assert scene.contact is None and "contact" not in make_plan(scene).participant("solid").config
    p, [(out, (report,), figures)] = _advance(make_plan(scene).participant("solid").config, 1)
    assert p.contact is None and "contact_pressure" not in out and figures == {}
    assert report.solver == "LU static" and report.converged


def varcouple_run(case, out):
    """`varcouple run case --output out`: the finished process and its summary.json."""
    run = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(case), "--output", str(out)],
                         capture_output=True, text=True, timeout=600)
    return run, json.loads((out / "summary.json").read_text())


@pytest.mark.slow
def test_varcouple_run_hertz(tmp_path):
    run, summary = varcouple_run(HERTZ, tmp_path / "out")
    assert run.returncode == 0 and summary["status"] == "completed", run.stderr
    last = summary["steps"][-1]["figures"]["solid"]
    assert last["min_gap"] > -1e-10 and last["force_z"] > 0
    assert (tmp_path / "out" / "solid_0001.vtu").exists()


def test_varcouple_run_stops_on_an_unconverged_contact_solve(tmp_path):
    """The coupler side: exit 3, status not_converged, stderr naming solver, step and residual."""
    case = hertz_copy(tmp_path, {"search_distance = 0.1": "search_distance = 0.1\nmax_iterations = 1"})
    run, summary = varcouple_run(case, tmp_path / "out")
    assert run.returncode == 3 and summary["status"] == "not_converged", run.stderr
    (step,) = summary["steps"]
    (report,) = step["solves"]["solid"]
    assert report["solver"] == "contact active_set" and not report["converged"] and report["iterations"] == 1
    assert report["residual"] > report["tolerance"] == 1e-10
    assert any("time step 0" in line and "contact active_set did not converge" in line
               and f"residual {report['residual']:.3g}" in line for line in run.stderr.splitlines()), run.stderr
