"""``varcouple study CASE --vary KEY=VALUES [--vary ...]``: the scene run over the product of
the values, each run through the same path as ``varcouple run`` into its own directory under
the study's, and what each run bought for its time.

Before anything runs: the number of runs is counted from the values alone and refused above
``--max-runs`` (no combination is built first); every combination is validated as a scene (the
values are set in the scene's TOML data first, :mod:`coupler.scene.overrides`), so a bad key or
value is one line naming it; what the error is measured on is checked against each run's plan
(:mod:`coupler.run.compared`); the count and an estimate of the time are printed (the rule of
:data:`RUN_SECONDS`, then scaled by the runs done). A run that fails is recorded with its status;
the study goes on. ``study.json`` (rewritten atomically when a run starts and ends) holds the
study's ``status``, ``planned`` runs, the machine's ``load_average`` before and after and one
record per run started: ``values``, ``status``, ``seconds`` (``total`` and per phase), ``cost``
(cells and vertices of every participant's mesh, from the run's summary) and ``error``
(:mod:`coupler.run.compared`). ``study.png`` draws error against wall time and against cost (of a
figure, the figure too), with two or more --vary keys one linked series per value of the first:
each model's accuracy-cost frontier (:func:`series_of`).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from pathlib import Path

from coupler import scene as scenes
from coupler.errors import CouplerError, SceneError, one_line, run_status
from coupler.output.plots import save_figure
from coupler.output.report import write_study_page
from coupler.output.results import read_summary, write_summary
from coupler.plan.plan import make_plan
from coupler.protocol.transport import new_run_id
from coupler.run.compared import Compared
from coupler.run.execute import execute
from coupler.run.outdir import OutputLock, prepare
from coupler.run.preflight import estimate
from coupler.scene.overrides import parse_vary
from transfer import TransferError

STUDY = "study.json"
PLOT = "study.png"
#: the runs a study starts without --max-runs
MAX_RUNS = 100
#: the rule of thumb a study's time is estimated with before it runs: seconds per run (starting its
#: participants) and per cell and time step (the cells of every participant, [time] steps): within a
#: factor of a few of single runs of the shipped cases (not a benchmark), enough to tell minutes from days.
RUN_SECONDS = (3.0, 1.0e-3)


def combinations(varies: list[str], max_runs: int = MAX_RUNS) -> list[dict]:
    """``--vary`` arguments -> one ``{key: value}`` per run: the product of the values, the
    last key varying fastest; SceneError, before any is built, when they are more than `max_runs`."""
    parsed = [parse_vary(text) for text in varies]
    keys = [key for key, _ in parsed]
    twice = {key for key in keys if keys.count(key) > 1}
    if twice:
        raise SceneError(f"--vary {sorted(twice)[0]}: given twice; list all its values in one --vary")
    count = math.prod(len(values) for _, values in parsed)
    if count > max_runs:
        sizes = " x ".join(f"{len(values)} {key}" for key, values in parsed)
        raise SceneError(f"--vary: {count:,} runs ({sizes}) exceed the limit of {max_runs:,} runs (--max-runs): "
                         f"vary fewer values, or give --max-runs {count} to run them all")
    return [dict(zip(keys, values)) for values in itertools.product(*(values for _, values in parsed))]


def _distinct(values: list) -> list:
    return [v for i, v in enumerate(values) if v not in values[:i]]


def _label(values: dict) -> str:
    return ", ".join(f"{key}={json.dumps(value)}" for key, value in values.items())


def plan(case, varies: list[str], output=None, max_runs: int = MAX_RUNS, log=print):
    """The scene of `case`, the study's directory and per run (name, values, validated scene);
    a line every 10 s while validating."""
    values_of_runs = combinations(varies, max_runs)
    base = scenes.load(case)
    directory = Path(output) if output is not None else Path(base.output_dir) / "study"
    runs, said = [], time.monotonic()
    for i, values in enumerate(values_of_runs, start=1):
        name = f"run_{i:02d}"
        try:
            runs.append((name, values, scenes.load(case, output=directory / name, overrides=values)))
        except SceneError as exc:
            raise SceneError(f"--vary {_label(values)}: {exc}") from None
        if time.monotonic() - said > 10:
            log(f"study: validated {i:,} of {len(values_of_runs):,} runs")
            said = time.monotonic()
    return base, directory, runs


def run_seconds(scene) -> tuple[float, int]:
    """The estimated seconds of one run of `scene` (:data:`RUN_SECONDS`) and its cells (of every
    participant, from the scene: :func:`coupler.run.preflight.estimate`)."""
    cells = sum(part.cells for part in estimate(scene))
    return RUN_SECONDS[0] + RUN_SECONDS[1] * cells * scene.time["steps"], cells


def _duration(seconds: float) -> str:
    for unit, scale in (("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= 2 * scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds:.3g} s"


def cost(summary: dict) -> dict | None:
    """Cells and vertices of every participant's mesh (the run's ``sizes``) and their totals."""
    sizes = summary.get("sizes")
    if not sizes:
        return None
    return {"cells": sum(s["cells"] for s in sizes.values()), "vertices": sum(s["vertices"] for s in sizes.values()),
            "participants": sizes}


def _short(value) -> str:
    """A --vary value as a legend shows it: a table's keys and values, anything else as TOML/JSON."""
    if isinstance(value, dict):
        return ", ".join(f"{k}={_short(v)}" for k, v in value.items())
    return value if isinstance(value, str) else json.dumps(value)


def series_of(study: dict) -> list[tuple[str | None, list[dict]]]:
    """The runs grouped for the plot: with two or more --vary keys, one series per value of the
    first (e.g. a model) holding its runs over the others (e.g. its resolutions), linked in the
    plot; with one key, one series of points, unlinked. Runs without an error or a cost are left out."""
    runs = [run for run in study["runs"] if run.get("error") is not None and run.get("cost")]
    keys = list(study.get("vary", {}))
    if len(keys) < 2:
        return [(None, runs)]
    first = keys[0]
    return [(f"{first}={_short(value)}", [run for run in runs if run["values"][first] == value])
            for value in study["vary"][first]]


def study_plot(path: Path, study: dict) -> None:
    """Error against wall time and against cost (cells), one point per run with an error; of a
    figure, one series per step of the reference (its error at that step) and a first panel of the
    figure itself against wall time. With two or more --vary keys each value of the first is one
    colour, its runs linked in order of the x axis: the accuracy-cost frontier of each (e.g. each
    fluid model over its resolutions, :func:`series_of`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    against = study["error"]
    groups = series_of(study)
    runs = [run for _, members in groups for run in members]
    reference = next((run for run in study["runs"] if run["name"] == against.get("reference")), None)
    tolerance = next((run["check"]["tolerance"] for run in study["runs"] if run.get("check")), None)
    times = against.get("t") if "figure" in against else None
    steps = [(f"step {s} (t = {t:g})", s) for s, t in enumerate(times)] if times else [(None, None)]
    grouped = groups[0][0] is not None
    wall = (lambda r: r["seconds"]["total"], "wall time [s]")
    panels = [(wall, "error"), ((lambda r: r["cost"]["cells"], "cost [cells of all participants]"), "error")]
    if times:
        panels.insert(0, (wall, "figure"))
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4))
    for ax, ((x, xlabel), quantity) in zip(axes, panels):
        for g, (group, members) in enumerate(groups):
            for k, (step, s) in enumerate(steps):
                if quantity == "figure":
                    y = lambda run, s=s: _at(run.get("figure"), s)  # noqa: E731
                else:
                    y = (lambda run, s=s: run["errors"][s]) if times else (lambda run: run["error"])
                # a figure may be 0 (no flow); an error of 0 (the reference) is not on log axes
                points = sorted((x(run), y(run)) for run in members
                                if y(run) is not None and (quantity == "figure" or y(run) > 0))
                if not points:
                    continue
                colour, marker = (f"C{g}", "os^vD<>"[k % 7]) if grouped else (f"C{k}", "o")
                name = ", ".join(n for n in (group, step) if n) or None
                draw = ax.plot if quantity == "figure" else ax.loglog
                draw(*zip(*points), marker=marker, ls="-" if grouped else "", color=colour, label=name)
                if quantity == "figure":
                    ax.set_xscale("log")
        for run in runs:
            at = run["error"] if quantity == "error" else _at(run.get("figure"), -1)
            if at:
                ax.annotate(run["name"], (x(run), at), fontsize=7, xytext=(3, 3), textcoords="offset points",
                            color="k" if run["status"] == "completed" else "C3")
        if reference is not None:
            ax.axvline(x(reference), color="k", ls=":", lw=1, label=f"reference {reference['name']}")
        if tolerance is not None and not times and quantity == "error":
            ax.axhline(tolerance, color="k", ls="--", lw=0.8, label=f"[check] tolerance {tolerance:g}")
        if ax is axes[0] and ax.get_legend_handles_labels()[0]:
            ax.legend(handles=_legend(ax, groups, steps) if grouped else None, fontsize=6)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(against["figure"] if quantity == "figure" else "")
        ax.grid(True, which="both", alpha=0.3)
    if not runs:
        axes[0].text(0.5, 0.5, "no run with an error to draw", transform=axes[0].transAxes, ha="center")
    axes[-2].set_ylabel(f"relative error of {against['figure']}" if times else
                        f"relative L2 difference of {against['field']}" if "field" in against and reference else
                        f"error ([check] {study['check']})" if study["check"] else "error")
    fig.suptitle(f"{study['case']}: error against {against['against']}"
                 + (f"\n{reference['name']}: {_short_values(reference)}" if reference else ""), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def _at(values: list | None, step: int):
    """The value of a run's `step` (None where the run has none: it stopped earlier)."""
    return values[step] if values and -len(values) <= step < len(values) else None


def _legend(ax, groups, steps) -> list:
    """One entry per series (its colour), one per step (its marker) and the axis's other lines
    (the reference): not each series' line per step."""
    from matplotlib.lines import Line2D

    own = [line for line in ax.get_lines() if line.get_linestyle() != "-" and not line.get_label().startswith("_")]
    return ([Line2D([], [], color=f"C{g}", label=group) for g, (group, _) in enumerate(groups)]
            + [Line2D([], [], color="k", marker="os^vD<>"[k % 7], ls="", label=step) for k, (step, _) in
               enumerate(steps) if step] + own)


def _short_values(run: dict) -> str:
    return "; ".join(f"{key}={_short(value)}" for key, value in run["values"].items())


def run_study(case, varies: list[str], output=None, field: str | None = None, figure: str | None = None,
              max_runs: int | None = None, log=print) -> dict:
    """Run the study (at most `max_runs` runs, default :data:`MAX_RUNS`); write and return
    study.json's content. The error of each run is that of `figure` (a dotted path of
    summary.json's steps), else of `field`, else the scene's [check], else of the solid's
    displacement (:mod:`coupler.run.compared`)."""
    max_runs = max_runs or MAX_RUNS
    base, directory, runs = plan(case, varies, output, max_runs, log)
    compared = Compared.of(field, figure, base.check["kind"] if getattr(base, "check", None) else None)
    estimates = []
    for name, values, scene in runs:
        compared.check_plan(make_plan(scene), f"{name} ({_label(values)})")
        estimates.append(run_seconds(scene))
    planned = sum(seconds for seconds, _ in estimates)
    cells = [c for _, c in estimates]
    log(f"study: {len(runs)} run{'s' * (len(runs) > 1)} of {base.path} (at most {max_runs}: --max-runs), "
        f"{min(cells):,} to {max(cells):,} cells each; about {_duration(planned)} by the rule "
        f"{RUN_SECONDS[0]:g} s + {1e3 * RUN_SECONDS[1]:g} ms per cell and step a run")
    lock = OutputLock(directory, new_run_id())
    prepare(directory, "--output" if output is not None else f"{base.path}: [output] directory")
    study = {"case": str(base.case_dir), "scene": str(base.path), "description": getattr(base, "description", ""),
             "status": "running", "planned": {"runs": len(runs), "estimated_seconds": planned},
             "vary": {key: _distinct([values[key] for _, values, _ in runs]) for key in runs[0][1]},
             "check": base.check["kind"] if getattr(base, "check", None) else None,
             "compared": {"kind": compared.kind, "name": compared.name},
             "load_average": {"before": os.getloadavg()}, "runs": []}
    with lock:
        try:
            done = 0.0
            for i, (name, values, scene) in enumerate(runs):
                log(f"{name} of {len(runs)}: {_label(values)}")
                record = {"name": name, "directory": name, "values": values, "status": "running",
                          "seconds": {"total": 0.0}, "cost": None, "check": None}
                study["runs"].append(record)
                write_summary(directory, study, STUDY)
                summary = _one_run(record, scene, lambda line, n=name: log(f"  [{n}] {line}"))
                write_summary(directory, study, STUDY)
                compared.check_run(directory / name, summary, name)
                done += estimates[i][0]
                left = sum(seconds for seconds, _ in estimates[i + 1:])
                if left:
                    measured = sum(run["seconds"]["total"] for run in study["runs"]) / done
                    log(f"study: {i + 1} of {len(runs)} runs done; about {_duration(measured * left)} left "
                        f"(the estimate times {measured:.2g}, as measured so far)")
            passed = all(run["status"] == "completed" and (run["check"] or {}).get("passed", True)
                         for run in study["runs"])
            study["status"] = "completed" if passed else "runs_failed"
        except BaseException as exc:
            study.update(status=run_status(exc), message=_why(exc))
            for run in study["runs"]:
                if run["status"] == "running":  # stopped before its own run began
                    run["status"] = study["status"]
            raise
        finally:
            study["load_average"]["after"] = os.getloadavg()  # the runs' seconds are as loaded as the machine
            write_summary(directory, study, STUDY)  # the status first: the runs are kept whatever follows
            _conclude(study, directory, compared)
    for run in study["runs"]:
        error = "-" if run.get("error") is None else f"{run['error']:.3e}"
        cells = "-" if not run["cost"] else f"{run['cost']['cells']:,}"
        log(f"{run['name']}  {run['status']:<13} {run['seconds']['total']:8.1f} s  cells {cells:>9}  error {error}"
            f"  {_label(run['values'])}")
    log(f"study: {directory / STUDY}, {directory / PLOT}; error against {study['error']['against']}"
        + (f": {study['error']['reference']}" if "reference" in study["error"] else ""))
    return study


def _conclude(study: dict, directory: Path, compared: Compared) -> None:
    """Each run's error, study.json again, the plot and the page. An error measuring the runs
    ends a study that ran to its end; one that is already stopping stops for its own reason."""
    try:
        compared.errors(study, directory)
    except BaseException as exc:
        study["error"] = {"against": f"nothing: {_why(exc)}"}
        ran = study["status"] in ("completed", "runs_failed")
        if ran:
            study.update(status=run_status(exc), message=_why(exc))
        if ran or not isinstance(exc, (CouplerError, TransferError, OSError)):
            raise
    finally:
        write_summary(directory, study, STUDY)
    study_plot(directory / PLOT, study)
    write_study_page(directory, study, PLOT)


def _one_run(record: dict, scene, log) -> dict:
    """Run `scene` into its directory, filling `record` (in the study's list from the start) with
    its status, seconds, cost and check however the run ends; the run's summary. A failure of the
    run is recorded and the study goes on; a signal or anything else is recorded and raised."""
    start, run_id = time.perf_counter(), new_run_id()
    summary = {}
    try:
        summary = execute(scene, f"study run {record['name']}", log=log, run_id=run_id)
        record["status"] = summary.get("status", "completed")
    except (CouplerError, TransferError, OSError) as exc:
        record.update(status=run_status(exc), message=one_line(exc))
        log(f"{record['status']}: {record['message']}")
        summary = _own_summary(Path(scene.output_dir), run_id)
    except BaseException as exc:  # a signal (or a bug): recorded, then the study stops
        summary = _own_summary(Path(scene.output_dir), run_id)
        own = summary.get("status", "running")
        record.update(status=run_status(exc) if own == "running" else own,
                      message=_why(exc) + ("" if own == "running" else
                                               f" after the run's summary.json said {own!r} (its pictures or "
                                               f"page may be missing)"))
        raise
    finally:
        record["seconds"] = {"total": time.perf_counter() - start, **summary.get("phases_seconds", {})}
        record["cost"] = cost(summary)
        record["check"] = summary.get("check")
    return summary


def _own_summary(directory: Path, run_id: str) -> dict:
    """The summary run `run_id` wrote in `directory` (not one an earlier run left there), or {}."""
    summary = read_summary(directory)
    return summary if summary.get("run_id") == run_id else {}


def _why(exc: BaseException) -> str:
    return "interrupted (SIGINT, Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else one_line(exc)
