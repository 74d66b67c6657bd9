"""Plots of a run, drawn with matplotlib's Agg backend (no display needed): the coupling
residuals per iteration and the inner solvers' convergence histories."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def residual_plot(path: Path, result) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for step in result.steps:
        ax.semilogy(range(1, len(step.residuals) + 1), step.residuals, marker="o", ms=3,
                    label=f"step {step.window}" if len(result.steps) <= 10 else None)
    ax.axhline(result.tolerance, color="k", ls="--", lw=0.8, label="tolerance")
    ax.set_xlabel("coupling iteration")
    ax.set_ylabel("relative interface residual (mass-weighted L2)")
    ax.set_title(f"fixed-point residuals ({result.accelerator.get('name', '')})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def solver_convergence(path: Path, steps: list[dict]) -> bool:
    """The criterion of every inner solve that reports its history, per iteration, one line per
    step (e.g. the nonsmooth multilevel method's step length); False when none does."""
    curves = [(f"{name}: {r['solver']}, step {s['step']}", r["history"], r["tolerance"])
              for s in steps for name, reports in s.get("solves", {}).items() for r in reports if r.get("history")]
    if not curves:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for label, history, _ in curves:
        ax.semilogy(range(1, len(history) + 1), np.abs(np.asarray(history, float)), marker="o", ms=2,
                    label=label if len(curves) <= 10 else None)
    for tolerance in sorted({t for _, _, t in curves if isinstance(t, float)}):
        ax.axhline(tolerance, color="k", ls="--", lw=0.8)
    ax.set_xlabel("iteration")
    ax.set_ylabel("the solver's criterion")
    ax.set_title("inner solver convergence (dashed: tolerance)")
    if len(curves) <= 10:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True

