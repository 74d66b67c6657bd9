"""What a finished (or failed) run leaves for people besides its data: the pictures of what
it simulated and its report page, timed as the phase ``pictures``. Rendering is offscreen and
never decides a run's status: a failure to render is written into the summary and the page."""

from __future__ import annotations

import time
from pathlib import Path

from .plots import apertures_plot, figures_plot, solver_convergence
from .report import write_page
from .results import write_summary

def publish(out: Path, summary: dict, pictures: bool, log=print) -> Path:
    """Render the pictures of the run in `out` (when `pictures`), write its report page; returns it.

    This is post-processing of the written files on one process after the coupling (rank 0 of a
    coupler on several ranks), not a gather inside the run: the pictures read each series' last
    file, on several ranks the ``.pvtu`` of the ranks' pieces joined into one mesh
    (:func:`coupler.output.drawing.read`, docs/scaling.md step 5). A mesh too large for one
    process: ``[output] pictures = false``."""
    rendered = []
    if pictures and summary.get("steps"):
        start = time.perf_counter()
        try:
            from .pictures import render

            rendered = render(out, summary.get("effects", []))
        except Exception as exc:  # noqa: BLE001 - a picture must not turn a run into a failure
            summary["pictures_error"] = f"{type(exc).__name__}: {exc}"
            log(f"warning: pictures not rendered: {summary['pictures_error']}")
        summary.setdefault("phases_seconds", {})["pictures"] = time.perf_counter() - start
        summary["pictures"] = [p.file for p in rendered]
        summary["picture_figures"] = {p.file: p.figures for p in rendered if p.figures}
        write_summary(out, summary)
    if pictures:
        solver_convergence(out / "convergence.png", summary.get("steps", []))
    figures_plot(out / "figures.png", summary.get("steps", []), summary.get("check", {}).get("curves"))
    apertures_plot(out / "apertures.png", summary.get("steps", []))
    page = write_page(out, summary, rendered)
    log(f"report: {page}")
    return page
