"""Plots of a run, drawn with matplotlib's Agg backend (no display needed): the coupling
residuals per iteration and the inner solvers' convergence histories."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from transfer.atomic import atomic_path


def save_figure(fig, path: Path, dpi: int) -> None:
    """Save the matplotlib figure `fig` as `path` (atomically: whole or not at all) and close it."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)


def residual_plot(path: Path, result) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    zeros = []
    for step in result.steps:
        r = np.asarray(step.residuals, float)
        zeros += [(step.window, i + 1) for i in np.flatnonzero(r == 0)]
        ax.semilogy(range(1, len(r) + 1), np.where(r > 0, r, np.nan), marker="o", ms=3,
                    label=f"step {step.window}" if len(result.steps) <= 10 else None)
    ax.axhline(result.tolerance, color="k", ls="--", lw=0.8, label="tolerance")
    if zeros:  # a log scale cannot show them: say so on the plot
        ax.text(0.02, 0.02, "residual exactly 0 (not drawn): " + ", ".join(f"step {w} it. {i}" for w, i in zeros[:6])
                + (" ..." if len(zeros) > 6 else ""), transform=ax.transAxes, fontsize=7)
    ax.set_xlabel("coupling iteration")
    ax.set_ylabel("relative interface residual (mass-weighted L2)")
    ax.set_title(f"fixed-point residuals ({result.accelerator.get('name', '')})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def solver_convergence(path: Path, steps: list[dict]) -> bool:
    """The criterion of every inner solve that reports its history, per iteration, one line per
    step (e.g. the nonsmooth multilevel method's step length); False when none does."""
    curves = [(f"{name}: {r['solver']}, step {s['step']}", np.abs(np.asarray(r["history"], float)), r["tolerance"])
              for s in steps for name, reports in s.get("solves", {}).items() for r in reports if r.get("history")]
    curves = [c for c in curves if (c[1] > 0).any()]  # a criterion of exact zeros has no place on a log axis
    if not curves:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for label, history, _ in curves:
        ax.semilogy(range(1, len(history) + 1), np.where(history > 0, history, np.nan), marker="o", ms=2,
                    label=label if len(curves) <= 10 else None)
    for tolerance in sorted({t for _, _, t in curves if isinstance(t, float)}):
        ax.axhline(tolerance, color="k", ls="--", lw=0.8)
    ax.set_xlabel("iteration")
    ax.set_ylabel("the solver's criterion")
    ax.set_title("inner solver convergence (dashed: tolerance)")
    if len(curves) <= 10:
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    return True


def apertures_plot(path: Path, steps: list[dict]) -> bool:
    """A hydro-mechanical fracture's mechanical and hydraulic apertures e_m and e_h (the
    per-step ``"fracture"`` figures; e_h with bars of its error estimate where the step has one)
    against the confining stress (the platen's), and the contact area fraction on a second axis;
    False when no step has both."""
    rows = [(s["figures"]["solid"]["stress"], s["fracture"]) for s in steps
            if s.get("fracture") and "stress" in s.get("figures", {}).get("solid", {})]
    if not rows:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stress = np.array([r[0] for r in rows]) / 1e6
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(stress, [1e6 * f["mechanical_aperture"] for _, f in rows], "o-", color="#31688e",
            label="mechanical aperture $e_m$")
    error = [1e6 * f.get("hydraulic_aperture_error", np.nan) for _, f in rows]
    ax.errorbar(stress, [1e6 * f["hydraulic_aperture"] for _, f in rows],
                yerr=None if np.all(np.isnan(error)) else error, fmt="s-", color="#35b779", capsize=3,
                label="hydraulic aperture $e_h$" + ("" if np.all(np.isnan(error)) else " (bars: its error estimate)"))
    ax.set_xlabel("confining stress [MPa]")
    ax.set_ylabel("aperture [µm]")
    ax.set_ylim(bottom=0)
    area = ax.twinx()
    area.plot(stress, [100 * f["contact_area_fraction"] for _, f in rows], "^--", color="#7f7f7f",
              label="contact area")
    area.set_ylabel("contact area [%]", color="#7f7f7f")
    area.set_ylim(bottom=0)
    lines = ax.get_legend_handles_labels(), area.get_legend_handles_labels()
    ax.legend(lines[0][0] + lines[1][0], lines[0][1] + lines[1][1], fontsize=8, loc="lower left")
    ax.set_title("apertures against confining stress")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    return True


def varying_figures(steps: list[dict]) -> dict[str, list]:
    """``{"participant.figure": value per step}`` of the figures that change over the steps
    (NaN where a step lacks one), times left out."""
    names = sorted({f"{who}.{name}" for s in steps for who, figures in s.get("figures", {}).items()
                    for name in figures if "seconds" not in name})
    series = {}
    for full in names:
        who, name = full.split(".", 1)
        values = [s.get("figures", {}).get(who, {}).get(name, np.nan) for s in steps]
        finite = [v for v in values if np.isfinite(v)]
        if len(finite) > 1 and np.ptp(finite) > 0:
            series[full] = values
    return series


def figures_plot(path: Path, steps: list[dict], overlays: dict | None = None) -> bool:
    """Every figure the participants report that changes over the steps, one panel each
    against the step (e.g. a closure test's stress, closure and contact area fraction per
    load step); ``overlays`` ``{"participant.figure": values per step}`` are drawn dashed on
    their figure's panel (e.g. a check's fitted law). False when no figure changes."""
    series = varying_figures(steps)
    if not series:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(4, len(series))
    rows = -(-len(series) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.4 * rows), squeeze=False)
    x = [s.get("step", k) for k, s in enumerate(steps)]
    for ax, (name, values) in zip(axes.ravel(), series.items()):
        ax.plot(x, values, "o-", ms=3)
        if overlays and name in overlays:
            ax.plot(x, overlays[name], "k--", lw=1, label="fit")
            ax.legend(fontsize=7)
        ax.set_title(name, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("step", fontsize=7)
    for ax in axes.ravel()[len(series):]:
        ax.set_axis_off()
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    return True
