"""``varcouple study CASE --vary KEY=VALUES [--vary ...]``: the scene run over the product of
the values, each run through the same path as ``varcouple run`` into its own directory under
the study's, and what each run bought for its time.

Every combination is validated as a scene before anything runs (the values are set in the
scene's TOML data first, :mod:`coupler.scene.overrides`), so a bad key or value is one line
naming it. A run that fails is recorded with its status; the study goes on. ``study.json``
holds one record per run: ``values``, ``status``, ``seconds`` (``total`` and per phase),
``cost`` (cells and vertices of every participant's mesh, from the run's summary) and
``error``: the scene's ``[check]`` error when the scene has one, else the relative L2
difference of a field (default the solid's displacement at the last step) from the reference
run, the most accurate one (the largest cost; among equal costs the longest), the field
carried onto the reference's mesh by L2 projection (paper eq. 1-3) and measured with the
reference mesh's mass matrix. ``study.png`` draws error against wall time and against cost.
"""

from __future__ import annotations

import itertools
import json
import time
from pathlib import Path

import numpy as np

from coupler import scene as scenes
from coupler.errors import CouplerError, SceneError, one_line, run_status
from coupler.output.report import write_study_page
from coupler.output.results import write_summary
from coupler.protocol.transport import new_run_id
from coupler.run.execute import execute
from coupler.run.outdir import OutputLock, prepare
from coupler.run.projection import project
from coupler.scene.overrides import parse_vary
from transfer import TransferError
from transfer.meshfile import MeshFile

STUDY = "study.json"
PLOT = "study.png"


def combinations(varies: list[str]) -> list[dict]:
    """``--vary`` arguments -> one ``{key: value}`` per run: the product of the values, the
    last key varying fastest."""
    parsed = [parse_vary(text) for text in varies]
    keys = [key for key, _ in parsed]
    twice = {key for key in keys if keys.count(key) > 1}
    if twice:
        raise SceneError(f"--vary {sorted(twice)[0]}: given twice; list all its values in one --vary")
    return [dict(zip(keys, values)) for values in itertools.product(*(values for _, values in parsed))]


def _distinct(values: list) -> list:
    return [v for i, v in enumerate(values) if v not in values[:i]]


def _label(values: dict) -> str:
    return ", ".join(f"{key}={json.dumps(value)}" for key, value in values.items())


def plan(case, varies: list[str], output=None):
    """The scene of `case`, the study's directory and per run (name, values, validated scene)."""
    base = scenes.load(case)
    directory = Path(output) if output is not None else Path(base.output_dir) / "study"
    runs = []
    for i, values in enumerate(combinations(varies), start=1):
        name = f"run_{i:02d}"
        try:
            runs.append((name, values, scenes.load(case, output=directory / name, overrides=values)))
        except SceneError as exc:
            raise SceneError(f"--vary {_label(values)}: {exc}") from None
    return base, directory, runs


def cost(summary: dict) -> dict | None:
    """Cells and vertices of every participant's mesh (the run's ``sizes``) and their totals."""
    sizes = summary.get("sizes")
    if not sizes:
        return None
    return {"cells": sum(s["cells"] for s in sizes.values()), "vertices": sum(s["vertices"] for s in sizes.values()),
            "participants": sizes}


def _last_file(directory: Path, participant: str) -> Path | None:
    files = sorted(directory.glob(f"{participant}_[0-9][0-9][0-9][0-9].vtu"))
    return files[-1] if files else None


def difference(file: Path, reference: Path, name: str) -> float | None:
    """||u - u_ref|| / ||u_ref|| in L2 on the reference's mesh: the field `name` of `file`
    carried there by L2 projection (taken as is when both files have the same mesh), the norm
    that of the reference's mass matrix over the dofs the projection covers. None when the
    reference field is zero."""
    run, ref = MeshFile.read(file), MeshFile.read(reference)
    u, u_ref = run.field(name), ref.field(name)
    space = ref.space(u_ref.kind)
    same = (run.mesh.cells.shape == ref.mesh.cells.shape and np.array_equal(run.mesh.cells, ref.mesh.cells)
            and np.array_equal(run.mesh.points, ref.mesh.points))
    if same:
        values, covered = u.values, np.ones(space.num_dofs, bool)
    else:
        p = project(u, run.space(u.kind), space, "l2")
        values, covered = p.values, p.covered
    mass = space.mass_matrix()[covered][:, covered]
    d = (values - u_ref.values)[covered].reshape(int(covered.sum()), -1)
    r = u_ref.values[covered].reshape(int(covered.sum()), -1)
    norm = float(np.sum(r * (mass @ r)))
    return float(np.sqrt(max(float(np.sum(d * (mass @ d))), 0.0) / norm)) if norm > 0 else None


def errors(study: dict, directory: Path, field: str) -> None:
    """Each run's ``error``: its [check]'s when the scene has one, else its difference in
    `field` (``participant.name``) from the reference run."""
    runs = study["runs"]
    if study["check"]:
        study["error"] = {"against": f"the scene's [check] (kind {study['check']})"}
        for run in runs:
            run["error"] = run["check"]["error"] if run.get("check") else None
        return
    done = [run for run in runs if run["status"] == "completed" and run["cost"]]
    if not done:
        study["error"] = {"against": "no completed run to compare with"}
        return
    reference = max(done, key=lambda run: (run["cost"]["cells"], run["seconds"]["total"]))
    participant, name = field.split(".", 1)
    study["error"] = {"against": "the reference run (the largest cost; among equal costs the longest)",
                      "reference": reference["name"], "field": field,
                      "norm": "relative L2 on the reference's mesh, the field carried there by L2 projection"}
    ref_file = _last_file(directory / reference["directory"], participant)
    for run in runs:
        file = _last_file(directory / run["directory"], participant)
        run["error"] = None if run not in done or file is None or ref_file is None else \
            difference(file, ref_file, name)


def study_plot(path: Path, study: dict) -> None:
    """Error against wall time and against cost (cells), one point per run with an error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [run for run in study["runs"] if run.get("error") and run.get("cost")]
    reference = next((run for run in study["runs"] if run["name"] == study["error"].get("reference")), None)
    tolerance = next((run["check"]["tolerance"] for run in study["runs"] if run.get("check")), None)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, x, label in ((axes[0], lambda r: r["seconds"]["total"], "wall time [s]"),
                         (axes[1], lambda r: r["cost"]["cells"], "cost [cells of all participants]")):
        for run in runs:
            ax.loglog(x(run), run["error"], "o", color="C0" if run["status"] == "completed" else "C3")
            ax.annotate(run["name"], (x(run), run["error"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
        if reference is not None:
            ax.axvline(x(reference), color="k", ls=":", lw=1, label=f"reference {reference['name']}")
        if tolerance is not None:
            ax.axhline(tolerance, color="k", ls="--", lw=0.8, label=f"[check] tolerance {tolerance:g}")
        if reference is not None or tolerance is not None:
            ax.legend(fontsize=7)
        ax.set_xlabel(label)
        ax.grid(True, which="both", alpha=0.3)
    if not runs:
        axes[0].text(0.5, 0.5, "no run with an error to draw", transform=axes[0].transAxes, ha="center")
    axes[0].set_ylabel(f"relative L2 difference of {study['error']['field']}" if reference else
                       f"error ([check] {study['check']})" if study["check"] else "error")
    fig.suptitle(f"{study['case']}: error against {study['error']['against']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_study(case, varies: list[str], output=None, field: str = "solid.displacement", log=print) -> dict:
    """Run the study; write and return study.json's content."""
    if field.count(".") < 1:
        raise CouplerError(f"--field {field!r}: give participant.field, e.g. solid.displacement")
    base, directory, runs = plan(case, varies, output)
    lock = OutputLock(directory, new_run_id())
    prepare(directory, "--output" if output is not None else f"{base.path}: [output] directory")
    study = {"case": str(base.case_dir), "scene": str(base.path), "description": getattr(base, "description", ""),
             "vary": {key: _distinct([values[key] for _, values, _ in runs]) for key in runs[0][1]},
             "check": base.check["kind"] if getattr(base, "check", None) else None, "runs": []}
    with lock:
        try:
            for name, values, scene in runs:
                log(f"{name}: {_label(values)}")
                study["runs"].append(_one_run(name, values, scene, lambda line, n=name: log(f"  [{n}] {line}")))
                write_summary(directory, study, STUDY)
        finally:
            errors(study, directory, field)
            write_summary(directory, study, STUDY)
            study_plot(directory / PLOT, study)
            write_study_page(directory, study, PLOT)
    for run in study["runs"]:
        error = "-" if run.get("error") is None else f"{run['error']:.3e}"
        cells = "-" if not run["cost"] else f"{run['cost']['cells']:,}"
        log(f"{run['name']}  {run['status']:<13} {run['seconds']['total']:8.1f} s  cells {cells:>9}  error {error}"
            f"  {_label(run['values'])}")
    log(f"study: {directory / STUDY}, {directory / PLOT}; error against {study['error']['against']}"
        + (f": {study['error']['reference']}" if "reference" in study["error"] else ""))
    return study


def _one_run(name: str, values: dict, scene, log) -> dict:
    start = time.perf_counter()
    record = {"name": name, "directory": name, "values": values}
    try:
        summary = execute(scene, f"study run {name}", log=log)
        record["status"] = summary.get("status", "completed")
    except (CouplerError, TransferError, OSError) as exc:
        record.update(status=run_status(exc), message=one_line(exc))
        log(f"{record['status']}: {record['message']}")
        file = Path(scene.output_dir) / "summary.json"
        summary = json.loads(file.read_text()) if file.is_file() else {}
    record["seconds"] = {"total": time.perf_counter() - start, **summary.get("phases_seconds", {})}
    record["cost"] = cost(summary)
    record["check"] = summary.get("check")
    return record
