"""``index.html``: one self-contained page per run (pictures embedded, inline style, no
script), for a person to read after a run: what the scene is, the plan that ran, how each
step went (coupling iterations, residuals, every inner solve, the case's figures), the
``[check]`` verdict, where the time went, and the pictures. A study gets one page that
links the pages of its runs.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

from transfer.atomic import write_text

PAGE = "index.html"

STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 70em; color: #222; line-height: 1.4; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
.status { display: inline-block; padding: 0.15em 0.6em; border-radius: 0.3em; color: white; font-weight: bold; }
.ok { background: #1b7837; } .bad { background: #b2182b; }
.pictures { display: grid; grid-template-columns: repeat(auto-fill, minmax(30em, 1fr)); gap: 1em; }
figure { margin: 0; } figure img { width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #555; } code { background: #f4f4f4; padding: 0 0.2em; }
"""


class Markup(str):
    """Text already escaped (HTML)."""


def _e(value) -> str:
    return html.escape(str(value))


def _num(x) -> str:
    return f"{x:.4g}" if isinstance(x, float) else _e(x)


def _table(header: list[str], rows: list[list]) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(
        f'<td class="num">{_num(c)}</td>' if isinstance(c, (int, float)) and not isinstance(c, bool)
        else f"<td>{c if isinstance(c, Markup) else _e(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _image(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{_e(path.name)}">'


def _status(summary: dict) -> str:
    status = summary.get("status", "unknown")
    failed_check = not summary.get("check", {}).get("passed", True)
    ok = status == "completed" and not failed_check
    text = status + (", check failed" if failed_check else "")
    return f'<span class="status {"ok" if ok else "bad"}">{_e(text)}</span>'


def _solves(step: dict) -> str:
    parts = []
    for name, reports in step.get("solves", {}).items():
        for r in reports:
            mark = "" if r["converged"] else (" (accepted)" if r["accepted"] else " NOT CONVERGED")
            parts.append(f"{name}: {r['solver']} {r['iterations']} it, {r['residual']:.2g}" if isinstance(
                r["residual"], float) else f"{name}: {r['solver']} {r['iterations']} it")
            parts[-1] += mark
    return "; ".join(parts)


def _steps(summary: dict) -> str:
    steps = summary.get("steps", [])
    if not steps:
        return "<p>No step finished.</p>"
    figures = sorted({f"{name}.{key}" for s in steps for name, fig in s.get("figures", {}).items() for key in fig})
    header = ["step", "t", "coupling iterations", "last residual", "converged", "inner solves",
              "max displacement [m]", *figures]
    rows = []
    for s in steps:
        residual = s["residuals"][-1] if s.get("residuals") else ""
        row = [s.get("step"), s.get("t"), s.get("iterations"), residual, "yes" if s.get("converged") else "NO",
               _solves(s), s.get("max_displacement", "")]
        row += [s.get("figures", {}).get(f.split(".", 1)[0], {}).get(f.split(".", 1)[1], "") for f in figures]
        rows.append(row)
    return _table(header, rows)


def _plan(summary: dict) -> str:
    out = [f"<p>Effects: <b>{_e(', '.join(summary.get('effects', [])))}</b>. {_e(summary.get('iteration', ''))}</p>"]
    if summary.get("participants"):
        out.append(_table(["participant", "kind", "module", "ranks"],
                          [[p["name"], p["kind"], p["module"], p["ranks"]] for p in summary["participants"]]))
    if summary.get("exchanges"):
        out.append(_table(["from", "to", "operator", "step", "accelerated", "how"],
                          [[", ".join(e["sources"]), e["target"], e["operator"], e["step"],
                            "yes" if e["accelerated"] else "", e.get("description", "")] for e in summary["exchanges"]]))
    items = [("load", summary.get("loads", [])), ("task", summary.get("tasks", [])), ("note", summary.get("notes", []))]
    lines = [f"<li><i>{kind}</i>: {_e(text)}</li>" for kind, texts in items for text in texts]
    if lines:
        out.append("<ul>" + "".join(lines) + "</ul>")
    return "".join(out)


def _check(summary: dict) -> str:
    check = summary.get("check")
    if not check:
        return "<p>The scene has no <code>[check]</code>.</p>"
    verdict = "PASS" if check.get("passed") else "FAIL"
    rows = [[k, v] for k, v in check.items() if not isinstance(v, (dict, list))]
    return f"<p><b>{verdict}</b></p>" + _table(["", "value"], rows)


def _phases(summary: dict) -> str:
    phases = summary.get("phases_seconds", {})
    rows = [[name, seconds] for name, seconds in sorted(phases.items(), key=lambda kv: -kv[1])]
    total = summary.get("wall_seconds")
    return _table(["phase", "seconds"], rows) + (f"<p>Wall time {total:.3g} s.</p>" if total else "")


def _files(out: Path) -> str:
    names = sorted(p.name for p in out.glob("*.pvd")) + sorted(p.name for p in out.glob("*.json"))
    links = "".join(f'<li><a href="{_e(n)}">{_e(n)}</a></li>' for n in names)
    logs = sorted(p.name for p in (out / "logs").glob("*.log")) if (out / "logs").is_dir() else []
    links += "".join(f'<li><a href="logs/{_e(n)}">logs/{_e(n)}</a></li>' for n in logs)
    return f"<ul>{links}</ul>"


#: plots a run may write besides its pictures: file -> (title, caption)
PLOTS = {"residuals.png": ("Coupling residuals", "The relative interface residual (mass-weighted L2) of every "
                                                 "coupling iteration of each step, and the tolerance."),
         "convergence.png": ("Inner solver convergence", "The criterion of every inner solve that reports its "
                                                         "history, per iteration of each step."),
         "figures.png": ("Figures per step", "Every figure the participants report that changes over the steps "
                                             "(dashed: the check's fit)."),
         "apertures.png": ("Apertures against stress", "The fracture's mechanical aperture e_m (the mean gap, "
                                                       "contacts as zero), hydraulic aperture e_h (the cubic law's "
                                                       "gap for the measured flow rate; bars: its error estimated "
                                                       "from the fluid grid coarsened 2x across the gap, where the "
                                                       "fluid gives one) and contact area fraction at each confining "
                                                       "stress.")}


def write_page(out: Path, summary: dict, pictures: list) -> Path:
    """Write ``index.html`` in the run's output directory `out`; `pictures` are
    :class:`coupler.output.drawing.Picture` (files in `out`); the run's :data:`PLOTS` are
    shown when they exist."""
    title = Path(summary.get("case", out.name)).name or out.name
    figures = [(p.title, p.caption, out / p.file) for p in pictures]
    figures += [(t, c, out / name) for name, (t, c) in PLOTS.items() if (out / name).is_file()]
    pictures_html = "".join(f"<figure>{_image(path)}<figcaption><b>{_e(t)}</b>. {_e(c)}</figcaption></figure>"
                            for t, c, path in figures if path.is_file())
    error = f"<p><b>Error:</b> {_e(summary['error'])}</p>" if summary.get("error") else ""
    body = (f"<h1>{_e(title)}</h1><p>{_status(summary)} run {_e(summary.get('run_id', ''))}</p>"
            f"<p>{_e(summary.get('description', ''))}</p>{error}"
            f"<h2>Pictures</h2>"
            + (f'<div class="pictures">{pictures_html}</div>' if pictures_html else
               "<p>No pictures (<code>[output] pictures = false</code>).</p>") +
            f"<h2>Check</h2>{_check(summary)}<h2>Plan</h2>{_plan(summary)}<h2>Steps</h2>{_steps(summary)}"
            f"<h2>Time per phase</h2>{_phases(summary)}<h2>Files</h2>{_files(out)}")
    page = (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{_e(title)}</title>'
            f"<style>{STYLE}</style></head><body>{body}</body></html>\n")
    path = out / PAGE
    write_text(path, page)
    return path


def write_study_page(directory: Path, study: dict, plot: str | None = None) -> Path:
    """``index.html`` of a study: its plot and one row per run linking the run's own page."""
    rows = []
    for run in study.get("runs", []):
        link = Markup(f'<a href="{_e(run["directory"])}/{PAGE}">{_e(run["directory"])}</a>') \
            if (directory / run["directory"] / PAGE).is_file() else run["directory"]
        rows.append([link, json.dumps(run.get("values", {})), run.get("status", ""),
                     run.get("seconds", {}).get("total", "") if isinstance(run.get("seconds"), dict) else "",
                     run.get("error", "")])
    image = _image(directory / plot) if plot and (directory / plot).is_file() else ""
    body = (f"<h1>Study of {_e(study.get('case', ''))}</h1><p>{_e(study.get('description', ''))}</p>{image}"
            + _table(["run", "values", "status", "seconds", "error"], rows))
    page = (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>study</title>'
            f"<style>{STYLE}</style></head><body>{body}</body></html>\n")
    path = directory / PAGE
    write_text(path, page)
    return path
