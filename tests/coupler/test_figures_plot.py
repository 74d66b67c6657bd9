"""figures.png (coupler/output/plots.py): every figure a participant reports that changes over
the steps, one panel each against the step, for any case (a closure test's stress, closure and
contact area per load step), with a check's fitted values drawn over their figure."""

import numpy as np

from coupler.output.plots import figures_plot, varying_figures

STEPS = [{"step": k, "figures": {"solid": {"stress": 1e6 * (k + 1), "closure": 1e-4 * np.sqrt(k + 1), "dofs": 6660,
                                           "seconds": 0.1 * k, **({"active_nodes": 14} if k else {})}}}
         for k in range(3)]


def test_the_figures_that_change_over_the_steps():
    series = varying_figures(STEPS)
    assert list(series) == ["solid.closure", "solid.stress"]  # dofs constant, times left out, nodes in one step only
    assert series["solid.stress"] == [1e6, 2e6, 3e6]
    steps = [{**s, "figures": {"solid": {**s["figures"]["solid"], "active_nodes": 10 + s["step"]}}} for s in STEPS]
    assert varying_figures(steps)["solid.active_nodes"] == [10, 11, 12]
    partial = [{**s, "figures": {"solid": {"active_nodes": 14}}} if s["step"] == 1 else {**s, "figures": {}}
               for s in STEPS]
    assert varying_figures(partial) == {}


def test_the_plot_is_written_when_a_figure_changes(tmp_path):
    assert figures_plot(tmp_path / "figures.png", STEPS, {"solid.closure": [1e-4, 1.4e-4, 1.7e-4]})
    assert (tmp_path / "figures.png").stat().st_size > 0
    assert not figures_plot(tmp_path / "none.png", STEPS[:1]) and not (tmp_path / "none.png").exists()


def test_a_residual_of_exactly_zero_is_named_on_the_residual_plot(tmp_path, monkeypatch):
    """A coupling iteration that changes nothing has residual 0, which a log scale cannot show:
    the plot says so in text (and matplotlib warns of nothing)."""
    import warnings
    from types import SimpleNamespace

    import matplotlib.axes

    from coupler.output.plots import residual_plot

    texts = []
    original = matplotlib.axes.Axes.text
    monkeypatch.setattr(matplotlib.axes.Axes, "text", lambda self, *a, **k: texts.append(a[2]) or original(self, *a, **k))
    result = SimpleNamespace(steps=[SimpleNamespace(window=0, residuals=[0.0]),
                                    SimpleNamespace(window=1, residuals=[0.3, 1e-7])],
                             tolerance=1e-6, accelerator={"name": "aitken"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        residual_plot(tmp_path / "residuals.png", result)
    assert (tmp_path / "residuals.png").stat().st_size > 0
    assert texts == ["residual exactly 0 (not drawn): step 0 it. 1"]
