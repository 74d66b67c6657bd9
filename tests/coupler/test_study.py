"""``varcouple study``: --vary parsed and applied to the scene's TOML before validation (a bad
key or value is one line naming it, and nothing runs), the runs counted before any is built and
refused above --max-runs, the product of the values run each in its own directory, study.json
with the study's status and planned runs and per run status, seconds, cost and error (the
[check]'s, the relative L2 difference of a field or the per-step relative error of a figure
against the most accurate run), every run recorded however the study ends, the PNG and the page."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

import meshio
import numpy as np
import pytest

from coupler import scene as scenes
from coupler.cli import main
from coupler.errors import EXIT_CODES, SceneError
from coupler.plan.plan import make_plan
from coupler.run import study as study_module
from coupler.run.compared import Compared, difference, figure_errors
from coupler.run.study import combinations, plan
from coupler.scene.overrides import apply, parse_vary
from transfer.generate import box_tetrahedra
from vc_helpers import CASES, NEEDS_GMSH, copy_case, deliver_stopping_signals, hertz_mesh_file

STANDIN = CASES / "standin_flow"


def test_the_product_of_the_values():
    runs = combinations(['geometry.fluid.shape=[[21,11,7],[21,11,11]]', 'coupling.acceleration=["aitken","iqn-ils"]'])
    assert runs == [{"geometry.fluid.shape": [21, 11, 7], "coupling.acceleration": "aitken"},
                    {"geometry.fluid.shape": [21, 11, 7], "coupling.acceleration": "iqn-ils"},
                    {"geometry.fluid.shape": [21, 11, 11], "coupling.acceleration": "aitken"},
                    {"geometry.fluid.shape": [21, 11, 11], "coupling.acceleration": "iqn-ils"}]


@pytest.mark.parametrize("text, message", [
    ("coupling.acceleration", r"--vary 'coupling.acceleration': give KEY=VALUES"),
    ("coupling..x=[1]", r"give KEY=VALUES"),
    ("coupling.tolerance=[1e-6,", r"--vary coupling.tolerance: '\[1e-6,' is not a TOML value"),
    ("coupling.tolerance=1e-6", r"--vary coupling.tolerance: give the values as a non-empty TOML array"),
    ("coupling.tolerance=[]", r"non-empty TOML array"),
])
def test_bad_vary_arguments(text, message):
    with pytest.raises(SceneError, match=message):
        parse_vary(text)


def test_a_key_given_twice():
    with pytest.raises(SceneError, match=r"--vary time.steps: given twice"):
        combinations(["time.steps=[1]", "time.steps=[2]"])


def test_apply_sets_nested_keys_and_array_entries():
    data = {"loads": [{"type": "dirichlet"}, {"type": "pressure", "value": 1.0}], "time": {"dt": 1.0}}
    apply(data, "coupling.acceleration", "aitken")
    apply(data, "loads.2.value", 3.0)
    apply(data, "geometry.fluid.shape", [1, 2, 3])
    assert data["coupling"] == {"acceleration": "aitken"} and data["loads"][1]["value"] == 3.0
    assert data["geometry"]["fluid"]["shape"] == [1, 2, 3]
    with pytest.raises(SceneError, match=r"--vary loads.3.value: \[loads\] has entries 1 to 2, got '3'"):
        apply(data, "loads.3.value", 1.0)
    with pytest.raises(SceneError, match=r"--vary loads.value: loads is an array of tables: name an entry"):
        apply(data, "loads.value", 1.0)
    with pytest.raises(SceneError, match=r"--vary time.dt.x: time.dt is a value \(1.0\), not a table"):
        apply(data, "time.dt.x", 1.0)


@pytest.mark.parametrize("vary, message", [
    ('coupling.acceleraton=["aitken"]', r'--vary coupling.acceleraton="aitken": .*scene.toml: \[coupling\] '
                                        r'acceleraton: unknown key; known keys: acceleration'),
    ('coupling.acceleration=["aitken", "newton"]', r'--vary coupling.acceleration="newton": .*scene.toml: '
                                                   r"\[coupling\] acceleration: unknown value 'newton'"),
    ('geometry.fluid.shape=[[21, 11]]', r"--vary geometry.fluid.shape=\[21, 11\]: .*\[geometry.fluid\] shape: "
                                        r"must be a list of 3 positive integers"),
])
def test_every_run_is_validated_before_anything_runs(tmp_path, capsys, vary, message):
    with pytest.raises(SceneError, match=message):
        plan(CASES / "small_fracture", [vary], tmp_path / "study")
    assert main(["study", str(CASES / "small_fracture"), "--vary", vary, "-o", str(tmp_path / "study")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("varcouple: error: --vary ") and err.count("\n") == 1
    assert not (tmp_path / "study").exists()


def _vtu(path, mesh, u):
    meshio.write(path, meshio.Mesh(mesh.points, [("tetra", mesh.cells)], point_data={"displacement": u}))


def test_difference_on_the_reference_mesh(tmp_path):
    """An affine field carried by L2 projection is reproduced (eq. 1-3): the difference from the
    reference is exactly the added constant's, measured with the reference mesh's mass matrix."""
    from transfer import FunctionSpace

    coarse, fine = box_tetrahedra((3, 3, 3), jitter=0.2, seed=1), box_tetrahedra((5, 4, 6), jitter=0.2, seed=2)
    a = np.array([[1.0, 0.5, -2.0], [0.3, 1.0, 0.0], [0.0, -0.7, 1.5]])
    f = lambda x: x @ a + np.array([0.1, 0.2, 0.3])  # noqa: E731
    shift = np.array([0.01, 0.0, -0.02])
    _vtu(tmp_path / "ref.vtu", fine, f(fine.points))
    _vtu(tmp_path / "run.vtu", coarse, f(coarse.points) + shift)
    M = FunctionSpace(fine, "P1").mass_matrix()
    ref = f(fine.points)
    expected = np.sqrt(sum(shift[c] ** 2 * M.sum() for c in range(3)) / sum(ref[:, c] @ (M @ ref[:, c])
                                                                           for c in range(3)))
    assert difference(tmp_path / "run.vtu", tmp_path / "ref.vtu", "displacement") == pytest.approx(expected, rel=1e-8)
    _vtu(tmp_path / "same.vtu", fine, ref + shift)  # same mesh: taken as is
    assert difference(tmp_path / "same.vtu", tmp_path / "ref.vtu", "displacement") == pytest.approx(expected, rel=1e-12)
    _vtu(tmp_path / "zero.vtu", fine, 0 * ref)
    assert difference(tmp_path / "run.vtu", tmp_path / "zero.vtu", "displacement") is None


def _study(tmp_path, case, *varies):
    out = tmp_path / "study"
    code = main(["study", str(case), *[a for v in varies for a in ("--vary", v)], "-o", str(out)])
    return code, out, json.loads((out / "study.json").read_text())


def test_small_fracture_with_two_grid_shapes(tmp_path):
    code, out, study = _study(tmp_path, CASES / "small_fracture", "geometry.fluid.shape=[[21,11,7],[21,11,11]]")
    assert code == 0 and [run["status"] for run in study["runs"]] == ["completed", "completed"]
    assert study["status"] == "completed" and study["compared"] == {"kind": "field", "name": "solid.displacement"}
    first, second = study["runs"]
    assert first["values"] == {"geometry.fluid.shape": [21, 11, 7]} and study["check"] is None
    assert second["cost"]["cells"] - first["cost"]["cells"] == 21 * 11 * (11 - 7)  # the same solid
    assert second["cost"]["participants"]["fluid"]["cells"] == 21 * 11 * 11
    assert study["error"]["reference"] == "run_02" and study["error"]["field"] == "solid.displacement"
    assert second["error"] == 0.0 and 1e-3 < first["error"] < 0.5  # measured: 5.5 %
    for run in study["runs"]:
        assert run["seconds"]["total"] > 0 and {"fluid", "solid", "transfer"} <= set(run["seconds"])
        assert (out / run["directory"] / "summary.json").is_file() and (out / run["directory"] / "fluid_0001.vtu").is_file()
    assert (out / "study.png").stat().st_size > 0 and "run_02" in (out / "index.html").read_text()


@NEEDS_GMSH
def test_hertz_with_two_mesh_sizes_reports_its_check(tmp_path):
    case = copy_case(CASES / "hertz", tmp_path)
    for h in (0.08, 0.06):
        hertz_mesh_file(case / f"hertz_h{h}.msh", radius=1.0, h_contact=h, h_far=0.3, refine_radius=0.25)
    code, out, study = _study(tmp_path, case, 'geometry.solid.mesh=["hertz_h0.08.msh", "hertz_h0.06.msh"]')
    assert study["check"] == "hertz" and "kind hertz" in study["error"]["against"]
    coarse, fine = study["runs"]
    assert coarse["cost"]["cells"] < fine["cost"]["cells"]
    for run in study["runs"]:
        assert run["status"] == "completed" and run["check"]["kind"] == "hertz" and run["check"]["radius"] == 1.0
        assert run["error"] == run["check"]["error"] == max(run["check"]["error_a"], run["check"]["error_p0"])
    assert fine["check"]["error_p0"] < coarse["check"]["error_p0"]
    assert code == (0 if all(run["check"]["passed"] for run in study["runs"]) else 1)
    assert (out / "study.png").is_file()


def test_a_knob_without_a_mesh_change_and_a_failed_run(tmp_path):
    """Acceleration and iteration cap on the stand-in loop: the capped runs do not converge and
    are recorded as such (the study goes on, exit 1); the others are compared with the longest
    run of equal cost."""
    code, out, study = _study(tmp_path, CASES / "standin_flow", 'coupling.acceleration=["aitken","iqn-ils"]',
                              "coupling.max_iterations=[2, 50]")
    assert code == 1 and study["status"] == "runs_failed" and study["planned"]["runs"] == 4
    statuses = {(r["values"]["coupling.acceleration"], r["values"]["coupling.max_iterations"]): r for r in study["runs"]}
    for acceleration in ("aitken", "iqn-ils"):
        capped, free = statuses[(acceleration, 2)], statuses[(acceleration, 50)]
        assert capped["status"] == "not_converged" and "did not converge" in capped["message"] and capped["error"] is None
        assert free["status"] == "completed" and free["error"] is not None and free["error"] < 1e-6
    reference = study["error"]["reference"]
    assert next(r for r in study["runs"] if r["name"] == reference)["error"] == 0.0
    assert len({r["cost"]["cells"] for r in study["runs"]}) == 1
    assert study["vary"] == {"coupling.acceleration": ["aitken", "iqn-ils"], "coupling.max_iterations": [2, 50]}


# -- the size of a study (issue 26, item 4) ------------------------------------------
def test_a_huge_product_is_refused_before_any_combination_is_built(tmp_path, capsys, monkeypatch):
    """10^6 combinations: refused from the count alone, naming --max-runs, no scene loaded (the
    product once validated for 180 s and 1.45 GB)."""
    loads = []
    monkeypatch.setattr(study_module.scenes, "load", lambda *a, **k: loads.append(k) or pytest.fail(
        "a scene was loaded before the runs were counted"))
    values = "[" + ", ".join(str(i) for i in range(1, 1001)) + "]"
    code = main(["study", str(STANDIN), "--vary", f"time.steps={values}", "--vary",
                 f"coupling.max_iterations={values}", "-o", str(tmp_path / "study")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "1,000,000 runs (1000 time.steps x 1000 coupling.max_iterations) exceed the limit of 100 runs " \
           "(--max-runs)" in err and "--max-runs 1000000" in err
    assert not loads and not (tmp_path / "study").exists()


def test_max_runs_raises_the_limit():
    varies = ["time.steps=[1, 2, 3]", "coupling.max_iterations=[5, 6]"]
    with pytest.raises(SceneError, match=r"--vary: 6 runs \(3 time.steps x 2 coupling.max_iterations\) exceed "
                                         r"the limit of 5 runs \(--max-runs\)"):
        combinations(varies, max_runs=5)
    assert len(combinations(varies, max_runs=6)) == 6
    assert len(combinations(["time.steps=" + str(list(range(1, 101)))])) == 100  # the default limit


def test_the_estimate_follows_the_stated_rule():
    scene = scenes.load(STANDIN)
    seconds, cells = study_module.run_seconds(scene)
    assert cells == 6 * 4 * 4 * 3 + 10 * 10 * 10  # the solid's tets and the fluid's cells
    a, b = study_module.RUN_SECONDS
    assert seconds == pytest.approx(a + b * cells * scene.time["steps"])


# -- what is compared is checked before any run (issue 26 item 8, issue 27 item 4) ---
@pytest.mark.parametrize("case, options, message", [
    (STANDIN, ["--figure", "fracture.hydraulic_aperture"], r"--figure fracture.hydraulic_aperture: run_01 "
     r"\(coupling.max_iterations=30\): the plan has no per-step 'fracture' figures \(its per-step figures: none"),
    (STANDIN, ["--figure", "figures.solidd.stress"], r"--figure figures.solidd.stress: .*the plan has no participant "
     r"'solidd' \(it has solid, fluid\)"),
    (STANDIN, ["--figure", "fracture..x"], r"--figure 'fracture..x': give the dotted path of a number"),
    (STANDIN, ["--field", "solidd.displacement"], r"--field solidd.displacement: .*no participant 'solidd'"),
    (STANDIN, ["--field", "displacement"], r"--field 'displacement': give participant.field"),
    (STANDIN, ["--field", "solid.displacement", "--figure", "max_displacement"], r"give one of them"),
    (CASES / "hm_fracture", ["--figure", "fracture"], r"--figure fracture: a table of figures, not a number"),
])
def test_a_bad_figure_or_field_is_refused_before_any_run(tmp_path, capsys, monkeypatch, case, options, message):
    monkeypatch.setattr(study_module, "execute", lambda *a, **k: pytest.fail("a run started"))
    out = tmp_path / "study"
    code = main(["study", str(case), "--vary", "coupling.max_iterations=[30, 31]", *options, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert re.search(message, err), err
    assert not out.exists()


def test_the_plan_vouches_for_a_monitor_and_a_crossing_field():
    hm = make_plan(scenes.load(CASES / "hm_fracture"))
    figure = Compared.of(None, "fracture.hydraulic_aperture", None)
    figure.check_plan(hm, "run_01")
    assert figure.pending  # its name inside the table: checked on the first run's summary
    field = Compared.of("fluid.pressure", None, None)
    field.check_plan(hm, "run_01")
    assert not field.pending  # it crosses to the solid: the plan says the fluid writes it


def test_a_figure_not_in_the_first_run_is_refused_before_the_next(tmp_path):
    steps = [{"step": 0, "t": 1.0, "fracture": {"hydraulic_aperture": 8.8e-5, "percolating": True}}]
    compared = Compared.of(None, "fracture.hydraulic_apertur", None)
    with pytest.raises(SceneError, match=r"--figure fracture.hydraulic_apertur: not in run_01's summary.json, "
                                         r"step 0: fracture has no 'hydraulic_apertur' \(it has \['hydraulic_"
                                         r"aperture', 'percolating'\]\)"):
        compared.check_run(tmp_path, {"steps": steps}, "run_01")
    compared = Compared.of(None, "fracture.percolating", None)
    with pytest.raises(SceneError, match=r"step 0: True is not a number"):
        compared.check_run(tmp_path, {"steps": steps}, "run_01")
    compared = Compared.of(None, "fracture.hydraulic_aperture", None)
    compared.check_run(tmp_path, {"steps": []}, "run_01")  # no step yet: still to be found
    assert compared.pending
    compared.check_run(tmp_path, {"steps": steps}, "run_02")
    assert not compared.pending


def test_a_field_not_written_stops_the_study_after_the_first_run(tmp_path, capsys):
    """A field the plan cannot vouch for is looked for in the first run's files: not there, the
    study stops before the second run (it was found only after every run)."""
    code = main(["study", str(STANDIN), "--vary", "coupling.max_iterations=[30, 31]", "--field",
                 "solid.displacment", "-o", str(tmp_path / "study")])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2 and err.startswith("varcouple: error: --field solid.displacment: ") and "no field " \
        "'displacment'" in err, err
    study = json.loads((tmp_path / "study" / "study.json").read_text())
    assert study["status"] == "invalid" and study["planned"]["runs"] == 2
    assert [(r["name"], r["status"]) for r in study["runs"]] == [("run_01", "completed")]
    assert not (tmp_path / "study" / "run_02").exists()


# -- studies on a figure (issue 27, item 4) ---------------------------------------------
def test_figure_errors_per_step_at_the_reference_times():
    ref = [{"t": 1.0, "a": {"b": 2.0}}, {"t": 2.0, "a": {"b": 4.0}}, {"t": 3.0, "a": {"b": 0.0}},
           {"t": 4.0, "a": {"b": 1.0}}]
    run = [{"t": 2.0, "a": {"b": 3.0}}, {"t": 1.0 + 1e-12, "a": {"b": 2.5}}, {"t": 3.0, "a": {"b": 1.0}}]
    assert figure_errors(run, ref, "a.b") == [pytest.approx(0.25), pytest.approx(0.25), None, None]


def test_a_study_of_a_figure(tmp_path, capsys):
    """The relative error of max_displacement per step against the reference run, recomputed
    here from the runs' own summaries; the count and the estimate printed before the first run."""
    code = main(["study", str(STANDIN), "--vary", "solvers.fluid.pressure=[1.0e5, 1.2e5]", "--figure",
                 "max_displacement", "-o", str(tmp_path / "study")])
    out = capsys.readouterr().out
    assert code == 0, out
    first = out.index("run_01 of 2")
    assert re.search(r"study: 2 runs of .*scene.toml \(at most 100: --max-runs\), 1,288 to 1,288 cells each; "
                     r"about 16.3 s by the rule 3 s \+ 1 ms per cell and step a run", out[:first]), out
    study = json.loads((tmp_path / "study" / "study.json").read_text())
    assert study["status"] == "completed" and study["planned"]["runs"] == 2
    assert all(len(study["load_average"][when]) == 3 for when in ("before", "after"))
    assert study["compared"] == {"kind": "figure", "name": "max_displacement"}
    reference = study["error"]["reference"]
    assert study["error"]["figure"] == "max_displacement" and study["error"]["t"] == pytest.approx(
        [0.01, 0.02, 0.03, 0.04])
    ref = [s["max_displacement"] for s in json.loads((tmp_path / "study" / reference / "summary.json").read_text())
           ["steps"]]
    for run in study["runs"]:
        own = [s["max_displacement"] for s in json.loads((tmp_path / "study" / run["name"] / "summary.json")
                                                          .read_text())["steps"]]
        assert run["figure"] == own
        assert run["errors"] == pytest.approx([abs(f - r) / abs(r) for f, r in zip(own, ref)], rel=1e-12)
        assert run["error"] == pytest.approx(max(run["errors"]))
        assert (run["error"] == 0.0) == (run["name"] == reference)
    other = next(run for run in study["runs"] if run["name"] != reference)
    assert other["error"] > 0.01  # the pressures differ by 20 %
    assert (tmp_path / "study" / "study.png").stat().st_size > 0


# -- every run recorded however the study ends (issue 26, item 8) -----------------------
def test_an_interrupt_after_the_run_wrote_its_summary_keeps_the_run(tmp_path, monkeypatch):
    """Ctrl-C while the first run writes its pictures (its summary says completed): the run is
    recorded with that status and the interrupt, the study says interrupted, the plan 2 runs."""
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("coupler.run.runner.publish", interrupted)
    out = tmp_path / "study"
    code = main(["study", str(STANDIN), "--vary", "coupling.max_iterations=[30, 31]", "-o", str(out)])
    assert code == EXIT_CODES["interrupted"]
    study = json.loads((out / "study.json").read_text())
    (run,) = study["runs"]
    assert run["name"] == "run_01" and run["status"] == "completed" and run["cost"]["cells"] == 1288
    assert run["message"].startswith("interrupted (SIGINT, Ctrl-C) after the run's summary.json said 'completed'")
    assert study["status"] == "interrupted" and study["planned"] == {"runs": 2, "estimated_seconds": pytest.approx(
        2 * (3.0 + 1e-3 * 1288 * 4))}
    assert json.loads((out / "run_01" / "summary.json").read_text())["status"] == "completed"


@pytest.mark.parametrize("sig, code, status", [(signal.SIGINT, 130, "interrupted"),
                                               (signal.SIGTERM, 143, "terminated")], ids=["ctrl_c", "sigterm"])
def test_a_signal_during_a_run_records_it_and_the_study(tmp_path, sig, code, status):
    out = tmp_path / "study"
    proc = subprocess.Popen([sys.executable, "-m", "coupler.cli", "study", str(STANDIN), "--vary",
                             "time.steps=[100000, 100001]", "-o", str(out)], preexec_fn=deliver_stopping_signals,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if json.loads((out / "run_01" / "summary.json").read_text()).get("steps"):
                break
        except (OSError, ValueError):
            pass
        time.sleep(0.05)
    proc.send_signal(sig)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    study = json.loads((out / "study.json").read_text())
    (run,) = study["runs"]
    assert run["name"] == "run_01" and run["status"] == status and run["seconds"]["total"] > 0
    assert json.loads((out / "run_01" / "summary.json").read_text())["status"] == status
    assert study["status"] == status and study["planned"]["runs"] == 2
    assert "study: 2 runs of" in stdout and re.search(r"about [0-9.]+ days", stdout)  # the count and the estimate


def test_a_runs_record_takes_its_own_summary_not_one_left_there(tmp_path):
    """The summary a study run is recorded from is the one with its run id: another run's summary
    written in the same directory a moment before (a rerun into a kept directory) is not taken
    (before: told apart by the file's time, within a second)."""
    from coupler.output.results import write_summary
    from coupler.run.study import _own_summary

    write_summary(tmp_path, {"run_id": "earlier", "status": "completed"})
    assert _own_summary(tmp_path, "this") == {}
    write_summary(tmp_path, {"run_id": "this", "status": "failed"})
    assert _own_summary(tmp_path, "this")["status"] == "failed"


# -- the accuracy-cost frontier of two models (issue 29, item 4) -------------------------
def _frontier_study(models=("reynolds", "chorin"), across=(22, 43, 87)) -> dict:
    """A study.json of two --vary keys, a model and the cells across, on a figure at two steps:
    the finest run of the second model the reference, e_h and time fabricated."""
    runs = []
    for m, model in enumerate(models):
        for a, n in enumerate(across):
            figure = [(1.2 if model == "reynolds" else 1.0 + 0.5 / n) * e for e in (1e-4, 8e-5)]
            runs.append({"name": f"run_{len(runs) + 1:02d}", "directory": f"run_{len(runs) + 1:02d}",
                         "values": {"solvers.fluid.participant": model, "geometry.fluid.shape": [16, 16, n]},
                         "status": "completed", "seconds": {"total": (1 + 10 * m) * (1 + a)},
                         "cost": {"cells": 960 + 256 * n}, "check": None, "figure": figure})
    reference = runs[-1]
    for run in runs:
        run["errors"] = [abs(f / r - 1) for f, r in zip(run["figure"], reference["figure"])]
        run["error"] = max(run["errors"])
    return {"case": "hm_fracture", "check": None, "runs": runs,
            "vary": {"solvers.fluid.participant": list(models), "geometry.fluid.shape": [[16, 16, n] for n in across]},
            "error": {"against": "the reference run", "reference": reference["name"],
                      "figure": "fracture.hydraulic_aperture", "t": [1.0, 2.0]}}


def _drawn(monkeypatch, tmp_path, study):
    """study_plot's figure, kept instead of saved; the PNG written all the same."""
    figures = []
    saved = study_module.save_figure
    monkeypatch.setattr(study_module, "save_figure", lambda fig, path, **kw: (figures.append(fig),
                                                                              saved(fig, path, **kw)))
    study_module.study_plot(tmp_path / "study.png", study)
    assert (tmp_path / "study.png").stat().st_size > 0
    return figures[0]


def test_two_models_draw_one_line_per_model_and_step(monkeypatch, tmp_path):
    """Each panel (e_h, its error against wall time, against cells) has per model and step one
    line linking the model's runs in order of the x axis; the reference's error (0) is not on the
    log axes, its e_h is."""
    study = _frontier_study()
    figure, error, cost = _drawn(monkeypatch, tmp_path, study).axes
    for ax, per_model in ((figure, 3), (error, 3), (cost, 3)):
        lines = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
        labels = sorted(line.get_label() for line in lines)
        assert labels == sorted(f"solvers.fluid.participant={m}, step {s} (t = {t:g})"
                                for m in ("reynolds", "chorin") for s, t in enumerate((1.0, 2.0)))
        for line in lines:
            x = list(line.get_xdata())
            assert x == sorted(x) and len(x) == (per_model - (ax is not figure and "chorin" in line.get_label()))
            model = line.get_label().split("=")[1].split(",")[0]
            assert len({line.get_color() for line in lines if model in line.get_label()}) == 1
    chorin = [line for line in figure.get_lines() if "chorin, step 0" in line.get_label()][0]
    assert list(chorin.get_ydata()) == [run["figure"][0] for run in study["runs"][3:]]
    assert "reference run_06" in [line.get_label() for line in error.get_lines()]


def test_one_key_draws_points_unlinked(monkeypatch, tmp_path):
    """One --vary key: points per step, no line between runs that need not be a sequence."""
    study = _frontier_study(models=("chorin",))
    study["vary"].pop("solvers.fluid.participant")
    _, error, _ = _drawn(monkeypatch, tmp_path, study).axes
    drawn = [line for line in error.get_lines() if line.get_marker() == "o"]
    assert len(drawn) == 2 and all(line.get_linestyle() == "None" for line in drawn)


def test_a_run_with_fewer_steps_is_drawn_where_it_has_them(monkeypatch, tmp_path):
    """A run that recorded the first step only (its figure one value, its second error None)."""
    study = _frontier_study()
    short = study["runs"][0]
    short["figure"], short["errors"] = short["figure"][:1], [short["errors"][0], None]
    figure, error, _ = _drawn(monkeypatch, tmp_path, study).axes
    for ax in (figure, error):
        first = [line for line in ax.get_lines() if line.get_label().endswith("reynolds, step 0 (t = 1)")][0]
        second = [line for line in ax.get_lines() if line.get_label().endswith("reynolds, step 1 (t = 2)")][0]
        assert len(first.get_xdata()) == 3 and len(second.get_xdata()) == 2


def test_a_figure_of_zero_is_drawn_on_the_figure_panel(monkeypatch, tmp_path):
    """e_h = 0 (a fracture closed to the flow) is a value of the figure, drawn; its error is not 0."""
    study = _frontier_study()
    study["runs"][0]["figure"][0] = 0.0
    study["runs"][0]["errors"][0] = 1.0
    figure, _, _ = _drawn(monkeypatch, tmp_path, study).axes
    first = [line for line in figure.get_lines() if line.get_label().endswith("reynolds, step 0 (t = 1)")][0]
    assert 0.0 in list(first.get_ydata()) and len(first.get_xdata()) == 3
