"""The Chorin fluid as a participant (protocol verbs, state in memory, solve reports), its scene
keys, and the coupled cases run with it by swapping the one ``participant`` line: against the
figures the OpenFOAM fluid gave (tests/data/case_figures.json)."""

from __future__ import annotations

import json
import shutil

import meshio
import numpy as np
import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.plan.plan import make_plan
from coupler.protocol.wire import Field
from coupler.scene import load
from fluid_chorin.participant import ChorinParticipant
from vc_helpers import CASES, ROOT, copy_case, load_bench

CHORIN = {'participant = "openfoam"': 'participant = "chorin"', "max_iterations = 3000\n": ""}
RECORDED = json.loads((ROOT / "tests" / "data" / "case_figures.json").read_text())


def channel_participant(**extra) -> ChorinParticipant:
    """A 2D channel 8 x 6 cells, pressure driven (creeping flow), with a block in its lower third."""
    p = ChorinParticipant()
    p.configure({"grid": {"origin": [0, 0, 0], "spacing": [1e-3, 1e-3, 1e-3], "shape": [8, 6, 1]},
                 "inlet": {"pressure": 1.0}, "outlet": {"pressure": 0.0},
                 "boundaries": {"zmin": "empty", "zmax": "empty"}, "rho": 1000.0, "mu": 0.1, **extra})
    return p


def inputs(fraction, velocity=None):
    n = fraction.size
    return {"solid_fraction": Field("solid_fraction", fraction), "solid_velocity":
            Field("solid_velocity", np.zeros((n, 3)) if velocity is None else velocity)}


def test_announce_geometry_and_the_outputs_of_an_advance():
    p = channel_participant()
    a = p.announce()
    assert a["provides"] == ["pressure", "velocity"] and a["accepts"] == ["solid_fraction", "solid_velocity", "inlet_pressure"]
    header, arrays = p.geometry()
    assert header["grid"] == {"origin": [0.0, 0.0, 0.0], "spacing": [1e-3] * 3, "shape": [8, 6, 1]}
    # one rank: its part is the whole grid (docs/protocol.md, "Parts")
    assert np.array_equal(arrays["cell_ids"], np.arange(48)) and np.array_equal(arrays["input_ids"], np.arange(48))
    f = np.zeros(48)
    f[:16] = 1.0  # two solid rows
    out = p.advance(0, 0, 0.0, 1.0, inputs(f))
    assert out["pressure"].units == "Pa" and out["pressure"].data.shape == (48,)
    assert out["velocity"].units == "m/s" and out["velocity"].data.shape == (48, 3)
    u = out["velocity"].data[:, 0].reshape(6, 8)
    assert u[2:].min() > 0 and np.abs(u[:2]).max() < 1e-3 * u.max()  # flow above the block, none in it
    solves, _ = p.take_reports()
    assert [s.solver for s in solves[:2]] == ["chorin pseudo-time", "pressure Poisson (Cholesky)"]
    assert len(solves) == 2  # no coarse solve: error_estimate is off by default (test_chorin_coarsened.py)
    assert all(s.converged for s in solves) and solves[0].residual < solves[0].tolerance == 1e-7
    with pytest.raises(ValueError, match=r"input 'solid_fraction' has shape \(47,\), expected \(48,\)"):
        p.advance(0, 1, 0.0, 1.0, inputs(np.zeros(47)))


def test_an_unconverged_pseudo_time_solve_is_reported_not_raised():
    p = channel_participant(max_iterations=3)
    p.advance(0, 0, 0.0, 1.0, inputs(np.zeros(48)))
    solve = p.take_reports()[0][0]
    assert not solve.converged and solve.iterations == 3 and solve.residual > solve.tolerance
    assert "limit of 3 pseudo-time steps" in solve.detail


def test_a_repeated_window_after_restore_state_gives_identical_outputs():
    """Transient, in memory: save_state(1), advance, restore_state(1), advance again with the same
    inputs: the same fields bit for bit; a step that does not start at the state's time raises."""
    p = channel_participant(transient=True, dt=1e-3, tolerance=1e-10)
    f = np.zeros(48)
    f[:16] = 1.0
    v = np.zeros((48, 3))
    v[:16, 0] = 1e-3
    p.advance(0, 0, 0.0, 1e-3, inputs(f, v))
    p.save_state(1)
    first = p.advance(1, 0, 1e-3, 1e-3, inputs(f, 2 * v))
    assert p.take_reports()[0][0].solver == "chorin time stepping"
    p.restore_state(1)
    again = p.advance(1, 1, 1e-3, 1e-3, inputs(f, 2 * v))
    for name in ("pressure", "velocity"):
        assert np.array_equal(first[name].data, again[name].data)
    with pytest.raises(ValueError, match="restore_state"):
        p.advance(5, 0, 5e-3, 1e-3, inputs(f, v))
    with pytest.raises(KeyError, match="no state saved for window 7"):
        p.restore_state(7)


def test_the_scene_selects_chorin_and_checks_its_keys(tmp_path):
    case = copy_case(CASES / "small_fracture", tmp_path / "ok", {**CHORIN, 'penalization = "wall"':
                                                                 'penalization = "wall"\ncfl = 0.4'})
    plan = make_plan(load(case))
    fluid = plan.participant("fluid")
    assert fluid.kind == "chorin" and fluid.module == "fluid_chorin"
    assert fluid.config["cfl"] == 0.4 and fluid.config["tolerance"] == 1e-7 and fluid.config["poisson"] == "auto"
    assert fluid.config["inlet"] == {"velocity": [0.01, 0.0, 0.0]} and fluid.config["transient"] is False
    assert "Chorin projection in pseudo-time" in plan.iteration
    assert fluid.ranks == 1 and fluid.config["slab_axis"] == "longest" and not plan.tasks
    parallel = copy_case(CASES / "small_fracture", tmp_path / "ranks", {**CHORIN, 'penalization = "wall"':
                                                                         'penalization = "wall"\nranks = 3'})
    plan = make_plan(load(parallel))
    assert plan.participant("fluid").ranks == 3  # started by mpirun -n 3
    assert "fluid: chorin on 3 MPI ranks, the grid in slabs along the longest direction" in plan.tasks[0]
    for old, new, match in (('penalization = "wall"', 'poisson = "lu"', r"\[solvers.fluid\] poisson: unknown value"),
                            ('penalization = "wall"', "cfl = 2.0",
                             r"\[solvers.fluid\] cfl: must lie in \(0, 1.0\], got 2.0$"),
                            ('penalization = "wall"', 'slab_axis = "w"',
                             r"\[solvers.fluid\] slab_axis: unknown value 'w'"),
                            ('penalization = "wall"', 'ranks = 6\nslab_axis = "z"',
                             r"scene.toml: \[solvers.fluid\] ranks: 6 ranks need at least 2 cells each along z \(slab_axis "
                             r"'z'\), the grid has 11 \(\[geometry.fluid\] shape\)$"),
                            ('penalization = "wall"', 'penalization = "lubrication"\nranks = 2\nslab_axis = "z"',
                             r"\[solvers.fluid\] slab_axis: penalization 'lubrication': its drag reads whole lines of "
                             r"cells along z \(across the gap\), the slabs along z of 2 ranks would cut them"),
                            ('penalization = "wall"', 'steady = "newton"\nranks = 2',
                             r"\[solvers.fluid\] participant = 'chorin': steady = 'newton' solves on one rank, got "
                             r"ranks = 2: use steady = 'march'")):
        bad = copy_case(CASES / "small_fracture", tmp_path / f"bad_{new.split()[0]}", {**CHORIN, old: new})
        with pytest.raises(SceneError, match=match):
            load(bad)


def pressure_drop(out, step: int) -> float:
    m = meshio.read(out / f"fluid_{step:04d}.vtu")
    p = m.cell_data["pressure"][0].reshape(11, 11, 21)
    fluid = m.cell_data["solid_fraction"][0].reshape(11, 11, 21) < 0.5
    return float(p[..., 0][fluid[..., 0]].mean() - p[..., -1][fluid[..., -1]].mean())


def test_small_fracture_with_chorin_matches_the_openfoam_run(tmp_path):
    """The demo with the one participant line swapped: converged in as many coupling iterations as
    with OpenFOAM ([5, 1]); maximum displacement within 3 % of the OpenFOAM run's recorded figure
    (measured -0.3 %), the largest fluid pressure (the inlet's) within 3 % (measured -1 %), the
    pressure drop between the inlet and outlet columns within 3 % of 553 Pa, the OpenFOAM run's
    (measured -0.8 %)."""
    case = copy_case(CASES / "small_fracture", tmp_path, CHORIN)
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    recorded = RECORDED["small_fracture"]
    assert s["status"] == "completed" and s["iterations"] == recorded["iterations"] == [5, 1]
    for step in (0, 1):
        assert s["steps"][step]["max_displacement"] == pytest.approx(
            recorded["summary"][f"/steps/{step}/max_displacement"], rel=0.03)
    assert s["steps"][0]["solves"]["fluid"][0]["solver"] == "chorin pseudo-time"
    p_max = meshio.read(out / "fluid_0001.vtu").cell_data["pressure"][0].max()
    assert p_max == pytest.approx(recorded["fluid_0001.vtu"]["cell:pressure"][1], rel=0.03)
    assert pressure_drop(out, 1) == pytest.approx(552.8, rel=0.03)


#: the OpenFOAM runs' pressure drop per step (bench/fluids.py: the inlet column's fluid cells less the outlet's)
OPENFOAM_DROP = {"added_mass_heavy": [949.98, 950.12, 950.22, 950.31], "added_mass_light": [949.99, 950.13, 950.24, 950.33]}


def added_mass_with_chorin(tmp_path, case, model):
    """The case with the Chorin fluid and ``solid_velocity = model``: summary, pressure drop per step."""
    case_dir = copy_case(CASES / case, tmp_path, {'participant = "openfoam"': 'participant = "chorin"',
                                                  "substeps = 1": f'substeps = 1\nsolid_velocity = "{model}"'})
    out = tmp_path / "out"
    assert main(["run", str(case_dir), "--output", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "completed"
    return s, [load_bench("fluids").pressure_drop(out, step) for step in range(len(s["steps"]))]


@pytest.mark.parametrize("case", ["added_mass_heavy", "added_mass_light"])
def test_added_mass_cases_with_chorin_bodies_match_the_openfoam_runs(tmp_path, case):
    """With the OpenFOAM fluid's model of the solid velocity (solid_velocity = "bodies": each body
    moves rigidly with its wetted layer's mean) the two fluids solve the same discrete problem:
    maximum displacement and pressure drop per step within 3 % of the OpenFOAM runs (recorded
    figures); measured within 0.004 % and 0.04 %, and as many IQN-ILS iterations (heavy 5, 5, 4, 4
    against 5, 5, 3, 4; light 5, 4, 3, 4 against 5, 5, 4, 4)."""
    s, drops = added_mass_with_chorin(tmp_path, case, "bodies")
    assert "applied per solid body" in " ".join(s["notes"]) and len(s["steps"]) == 4
    recorded = RECORDED[case]["summary"]
    for step, st in enumerate(s["steps"]):
        assert st["max_displacement"] == pytest.approx(recorded[f"/steps/{step}/max_displacement"], rel=1e-3)
        assert st["iterations"] <= recorded[f"/steps/{step}/iterations"] + 1
    assert drops == pytest.approx(OPENFOAM_DROP[case], rel=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("case,low,high", [("added_mass_heavy", -0.11, 0.04), ("added_mass_light", -0.24, -0.02)])
def test_added_mass_cases_with_chorin_per_cell_differ_by_the_model(tmp_path, case, low, high):
    """The default per-cell solid velocity is another model: the channel sees the block's top bend
    (its ends move faster than its middle under the added-mass pressure), a rigid body does not.
    Measured against the OpenFOAM runs, max displacement per step: heavy -9.9, -5.1, -0.5, +2.5 %;
    light -22.2, -14.9, -8.6, -3.3 %; pressure drop heavy -12, +11, -2, +20 %, light -20, +16, -6,
    +32 % (the bending makes the channel's pressure asymmetric). IQN-ILS converges in every step."""
    s, drops = added_mass_with_chorin(tmp_path, case, "cells")
    assert "applied per cell" in " ".join(s["notes"]) and all(st["iterations"] <= 12 for st in s["steps"])
    recorded = RECORDED[case]["summary"]
    diffs = [st["max_displacement"] / recorded[f"/steps/{step}/max_displacement"] - 1
             for step, st in enumerate(s["steps"])]
    assert low < min(diffs) and max(diffs) < high and min(diffs) < -0.03, diffs  # beyond 3 %: a model difference
    assert max(abs(d / p - 1) for d, p in zip(drops, OPENFOAM_DROP[case])) > 0.1


@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")
def test_quick_benchmark_runs_the_three_fluids_side_by_side(tmp_path, capsys):
    bench = load_bench("fluids")
    out = tmp_path / "fluids.json"
    bench.main(["--quick", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "goal small_fracture_speedup" in printed and ("PASS" in printed or "MISS" in printed)
    data = json.loads(out.read_text())
    runs = data["coupled"]["small_fracture"]["runs"]
    assert set(runs) == {"openfoam", "chorin", "reynolds"} and all(r["status"] == "completed" for r in runs.values())
    for r in runs.values():
        assert r["fluid_seconds"] > 0 and 0 < r["fluid_share"] < 1 and r["seconds_per_coupling_iteration"] > 0
    diff = data["coupled"]["small_fracture"]["chorin_against_openfoam"]
    assert abs(diff["pressure_drop_difference"]) < 0.03 and all(abs(d) < 0.03 for d in diff["max_displacement_difference"])
    assert [row["cells_across"] for row in data["plates"]] == [4, 8]
    assert data["goals"]["small_fracture_speedup"]["status"] in ("PASS", "MISS")
