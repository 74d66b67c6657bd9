"""The participant-agnostic coupling loop: mass-weighted convergence, checkpoints, failures, explicit mode."""

from __future__ import annotations

import copy
import io
import json

import numpy as np
import pytest

from coupler.coupling.acceleration import IQNILS, Aitken, ConstantRelaxation
from coupler.coupling.convergence import ConvergenceMonitor, concatenate_weights, dof_weights, interface_residual, relative_residual
from coupler.coupling.loop import CouplingDiverged, CouplingError, NonFiniteInterface, TimeWindow, run_coupled
from coupler.output.progress import ProgressBar, format_seconds


class StatefulParticipant:
    """A mock pair of solvers whose H depends on an internal state that every call advances.

    Like a real participant, ``advance`` integrates its state over the window
    from wherever the state is: calling it twice without restoring gives a
    different answer. ``save``/``restore`` keep one copy per window.
    """

    def __init__(self, n=12, seed=0):
        rng = np.random.default_rng(seed)
        self.K = rng.standard_normal((n, n)) / np.sqrt(n)
        self.G = -1.2 * np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)  # added-mass-like
        self.state = {"u": rng.standard_normal(n), "v": np.zeros(n)}
        self.checkpoints = {}
        self.log = []  # (window, iteration, x, Hx)
        self.saves, self.restores = 0, 0

    def iterate(self, window, iteration, x):
        u, v = self.state["u"], self.state["v"]
        v = v + window.dt * (np.tanh(self.K @ u) + x)
        u = u + window.dt * v
        self.state = {"u": u, "v": v}
        Hx = self.G @ v + np.sin(window.t_end)
        self.log.append((window.index, iteration, x.copy(), Hx.copy()))
        return Hx

    def save(self, window):
        self.saves += 1
        self.checkpoints[window.index] = copy.deepcopy(self.state)

    def restore(self, window):
        self.restores += 1
        self.state = copy.deepcopy(self.checkpoints[window.index])


def run_participant(accelerator, steps=4, seed=0, **kw):
    p = StatefulParticipant(seed=seed)
    result = run_coupled(steps, 0.1, p.iterate, np.zeros(12), accelerator, tolerance=1e-10, max_iterations=100,
                         checkpoint=p, **kw)
    return p, result


# ---------------------------------------------------------------------------------- checkpoint determinism


def test_restore_makes_a_repeated_window_identical():
    p = StatefulParticipant()
    w = TimeWindow(0, 0.0, 0.1)
    x = np.linspace(-1, 1, 12)
    p.save(w)
    first = p.iterate(w, 0, x)
    state_after = copy.deepcopy(p.state)
    drifted = p.iterate(w, 1, x)  # no restore: the state moved on
    assert np.linalg.norm(drifted - first) > 1e-3
    p.restore(w)
    again = p.iterate(w, 1, x)
    np.testing.assert_allclose(again, first, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p.state["u"], state_after["u"], rtol=0, atol=1e-12)


@pytest.mark.parametrize("make", [lambda: Aitken(0.3), lambda: IQNILS(0.3, reuse=2, filter_eps=1e-10)],
                         ids=["aitken", "iqn-ils"])
def test_loop_with_checkpoints_is_deterministic(make):
    p, result = run_participant(make())
    assert result.all_converged and result.completed
    assert p.saves == 4 and p.restores == result.total_iterations - 4
    # the whole run again from scratch: identical iterates
    q, again = run_participant(make())
    assert again.iterations == result.iterations
    for (wa, ka, xa, ha), (wb, kb, xb, hb) in zip(p.log, q.log):
        assert (wa, ka) == (wb, kb)
        np.testing.assert_allclose(xb, xa, rtol=0, atol=1e-12)
        np.testing.assert_allclose(hb, ha, rtol=0, atol=1e-12)
    # replay window 2 from its checkpoint: every iteration gives the H(x) recorded in the run
    window = TimeWindow(2, 0.2, 0.30000000000000004)
    recorded = [(x, Hx) for (w, k, x, Hx) in p.log if w == 2]
    assert len(recorded) >= 2
    for x, Hx in recorded:
        p.restore(window)
        np.testing.assert_allclose(p.iterate(window, 0, x), Hx, rtol=0, atol=1e-12)


def test_without_checkpoint_the_iteration_chases_a_moving_target():
    """The same stateful participant without save/restore: H changes at every call, no convergence."""
    p = StatefulParticipant()
    with pytest.raises(CouplingDiverged):
        run_coupled(2, 0.1, p.iterate, np.zeros(12), IQNILS(0.3, filter_eps=1e-10), tolerance=1e-10,
                    max_iterations=40)


# ------------------------------------------------------------------------------------- mass-weighted norm


def test_mass_weighted_residual_differs_from_euclidean_for_nonuniform_masses():
    rng = np.random.default_rng(0)
    x, Hx = rng.standard_normal(8), rng.standard_normal(8)
    m = rng.uniform(0.01, 10, 8)
    weighted = relative_residual(x, Hx, m)
    expected = np.sqrt(np.sum(m * (Hx - x) ** 2) / np.sum(m * Hx ** 2))
    assert weighted == pytest.approx(expected, rel=1e-14)
    assert abs(weighted - relative_residual(x, Hx)) > 1e-3
    # a uniform mass is the Euclidean norm up to a factor that cancels in the relative residual
    assert relative_residual(x, Hx, np.full(8, 3.7)) == pytest.approx(relative_residual(x, Hx), rel=1e-14)
    res = interface_residual(x, Hx, m)
    assert res.absolute == pytest.approx(np.sqrt(np.sum(m * (Hx - x) ** 2)))
    assert interface_residual(np.zeros(3), np.zeros(3)).relative == 0.0  # 0/0: converged, not NaN


def test_vector_field_weights_repeat_the_nodal_mass():
    m = np.array([1.0, 2.0, 3.0])
    np.testing.assert_array_equal(dof_weights(m, 3), [1, 1, 1, 2, 2, 2, 3, 3, 3])
    np.testing.assert_array_equal(dof_weights(m, 2, "blocked"), [1, 2, 3, 1, 2, 3])
    np.testing.assert_array_equal(concatenate_weights(m, [5.0]), [1, 2, 3, 5])
    with pytest.raises(ValueError):
        relative_residual(np.zeros(3), np.ones(3), [1.0, 1.0])
    with pytest.raises(ValueError):
        ConvergenceMonitor(1e-6, weights=[1.0, -2.0])


def test_loop_measures_and_decides_with_the_mass_weighted_norm():
    """Slow dofs carry most of the mass: the weighted residual stays large longer than the Euclidean one."""
    n = 20
    rates = np.where(np.arange(n) < 4, 0.8, 0.1)  # 4 slowly converging dofs ...
    masses = np.where(np.arange(n) < 4, 100.0, 0.01)  # ... on heavy nodes (e.g. a coarse part of the interface)
    x_star = np.random.default_rng(1).uniform(1, 2, n)
    calls = []

    def iterate(window, k, x):
        Hx = x_star + rates * (x - x_star)
        calls.append((x.copy(), Hx.copy()))
        return Hx

    euclidean = run_coupled(1, 1.0, iterate, np.zeros(n), ConstantRelaxation(1.0), tolerance=1e-3,
                            max_iterations=200)
    measured, calls[:] = calls[:], []
    weighted = run_coupled(1, 1.0, iterate, np.zeros(n), ConstantRelaxation(1.0), tolerance=1e-3,
                           max_iterations=200, weights=masses)
    assert weighted.iterations[0] > euclidean.iterations[0]
    assert weighted.norm.startswith("mass-weighted")
    # the recorded residuals are the mass-weighted ones of the iterates actually passed to H
    for (x, Hx), r in zip(calls, weighted.residual_histories[0]):
        assert r == pytest.approx(relative_residual(x, Hx, masses), rel=1e-14)
    for (x, Hx), r in zip(measured, euclidean.residual_histories[0]):
        assert r == pytest.approx(relative_residual(x, Hx), rel=1e-14)
    assert weighted.residual_histories[0][-1] <= 1e-3 < weighted.residual_histories[0][-2]


def test_loop_hands_the_weights_to_the_accelerator():
    masses = np.linspace(0.1, 5, 12)
    acc, p = IQNILS(0.3), StatefulParticipant()
    run_coupled(1, 0.1, p.iterate, np.zeros(12), acc, tolerance=1e-8, max_iterations=50, weights=masses,
                checkpoint=p)
    np.testing.assert_array_equal(acc.weights, masses)


# ------------------------------------------------------------------------------------------------ failures


def test_nan_in_H_raises_at_once_naming_step_and_iteration():
    p = StatefulParticipant()
    calls = []

    def iterate(window, k, x):
        calls.append((window.index, k))
        Hx = p.iterate(window, k, x)
        if (window.index, k) == (1, 2):
            Hx[5] = np.nan
            Hx[7] = np.inf
        return Hx

    with pytest.raises(NonFiniteInterface) as info:
        run_coupled(3, 0.1, iterate, np.zeros(12), IQNILS(0.3), tolerance=1e-10, max_iterations=50, checkpoint=p)
    err = info.value
    assert calls[-1] == (1, 2)  # no further call after the bad one
    assert (err.step, err.iteration, err.count, err.first) == (1, 2, 2, 5)
    message = str(err)
    assert "time step 1" in message and "iteration 2" in message and "NaN" in message and "inf" in message
    assert isinstance(err, CouplingError) and len(err.result.steps) == 1  # window 0 completed


def test_wrong_size_from_iterate_is_a_clear_error():
    with pytest.raises(CouplingError, match="iterate returned 3 interface values, expected 4"):
        run_coupled(1, 0.1, lambda w, k, x: np.zeros(3), np.zeros(4))


def test_allow_unconverged_accepts_and_flags_the_step():
    p = StatefulParticipant()
    with pytest.warns(RuntimeWarning, match="did not converge in time step") as caught:
        result = run_coupled(2, 0.1, p.iterate, np.zeros(12), Aitken(0.3), tolerance=1e-14, max_iterations=3,
                             checkpoint=p, allow_unconverged=True)
    assert ["time step 0" in str(w.message) for w in caught] == [True, False]
    assert result.converged == [False, False] and result.iterations == [3, 3] and result.completed
    assert not result.all_converged


# ------------------------------------------------------------------------------ explicit mode, callbacks, io


def test_explicit_mode_calls_iterate_once_per_step():
    p = StatefulParticipant()
    accepted = []
    result = run_coupled(5, 0.1, p.iterate, np.zeros(12), coupling="explicit", checkpoint=p,
                         on_converged=lambda w, x, step: accepted.append((w.index, x)))
    assert result.iterations == [1] * 5 and result.all_converged
    assert p.saves == p.restores == 0
    assert [w for w, _ in accepted] == list(range(5))
    # each window's input is the previous window's output
    for (w, k, x, Hx), (w_next, _, x_next, _) in zip(p.log, p.log[1:]):
        np.testing.assert_array_equal(x_next, Hx)
    np.testing.assert_array_equal(accepted[-1][1], p.log[-1][3])
    # solid-only scenes: no interface at all
    empty = run_coupled(3, 1.0, lambda w, k, x: x, np.zeros(0), coupling="explicit")
    assert empty.iterations == [1, 1, 1]


def test_on_converged_gets_the_accepted_value_and_time_windows():
    p = StatefulParticipant()
    seen = []
    result = run_coupled(3, 0.25, p.iterate, np.zeros(12), IQNILS(0.3), tolerance=1e-8, max_iterations=60,
                         checkpoint=p, on_converged=lambda w, x, step: seen.append((w, x)), t0=1.0)
    assert [(w.index, w.t_start, w.t_end) for w, _ in seen] == [(0, 1.0, 1.25), (1, 1.25, 1.5), (2, 1.5, 1.75)]
    last_H = [Hx for (w, k, x, Hx) in p.log if w == 2][-1]
    np.testing.assert_array_equal(seen[-1][1], last_H)
    np.testing.assert_array_equal(result.x, last_H)


def test_linear_extrapolation_predicts_a_smooth_trajectory():
    """x*(t) linear in t: the first-order prediction is exact from the third window on."""
    n = 6
    A = 0.5 * np.eye(n)

    def iterate(w, k, x):
        return A @ x + (1 + w.t_end) * np.ones(n)  # x* = 2 (1 + t) 1

    r0 = run_coupled(6, 0.1, iterate, np.zeros(n), Aitken(0.5), tolerance=1e-10, max_iterations=60)
    r1 = run_coupled(6, 0.1, iterate, np.zeros(n), Aitken(0.5), tolerance=1e-10, max_iterations=60,
                     extrapolation=1)
    assert r1.iterations[2:] < r0.iterations[2:]


def test_summary_is_json_ready_and_progress_bar_writes():
    p = StatefulParticipant()
    stream = io.StringIO()
    bar = ProgressBar(4, label="coupling", stream=stream, enabled=True)
    result = run_coupled(4, 0.1, p.iterate, np.zeros(12), IQNILS(0.3, reuse=1), tolerance=1e-8,
                         max_iterations=60, checkpoint=p, progress=bar)
    summary = json.loads(json.dumps(result.to_dict()))
    assert summary["steps_done"] == 4 and summary["all_converged"]
    assert summary["acceleration"]["name"] == "iqn-ils" and summary["acceleration"]["reuse"] == 1
    assert [s["iterations"] for s in summary["steps"]] == result.iterations
    assert summary["seconds_iterate"] <= summary["seconds"]
    text = stream.getvalue()
    assert "coupling [" in text and "4/4" in text and "100%" in text and "res=" in text
    assert format_seconds(3725) == "1:02:05" and format_seconds(65) == "01:05"
    quiet = io.StringIO()
    with ProgressBar(3, stream=quiet) as auto:  # not a terminal, not asked for: silent
        auto.update(3)
    assert quiet.getvalue() == ""


def test_monitor_summary_records_every_iteration():
    monitor = ConvergenceMonitor(1e-3, abs_tolerance=1e-12)
    monitor.start_window(0, 0.0)
    r1 = monitor.measure(np.zeros(2), np.ones(2))
    r2 = monitor.measure(np.ones(2), np.ones(2) * (1 + 1e-4))
    assert not monitor.is_converged(r1) and monitor.is_converged(r2)
    monitor.end_window(True)
    s = monitor.summary()
    assert s["windows"][0]["iterations"] == 2 and s["windows"][0]["residuals"][0] == 1.0
    assert s["all_converged"] and s["norm"] == "euclidean"
    assert monitor.is_converged(interface_residual(np.zeros(2), np.full(2, 1e-13)))  # absolute floor


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_on_a_terminal_the_progress_line_follows_every_coupling_iteration():
    p = StatefulParticipant()
    terminal = _Terminal()
    bar = ProgressBar(2, label="case", stream=terminal, min_interval=0.0)
    run_coupled(2, 0.1, p.iterate, np.zeros(12), IQNILS(0.3), tolerance=1e-8, max_iterations=60, checkpoint=p,
                progress=bar)
    bar.close()
    frames = terminal.getvalue().split("\r")
    iterations = [f for f in frames if "step 1: iteration" in f]
    assert len(iterations) >= 3 and "residual" in iterations[-1]  # redrawn in place, one frame per iteration
    assert any("step 2: iteration 1," in f for f in frames) and "2/2" in frames[-1]
    assert "<" in iterations[0]  # elapsed < estimated time left


def test_a_window_converges_only_when_its_further_condition_holds():
    """``unmet``: asked once the residual is below tolerance; the window goes on while it gives
    a reason, and the max_iterations message names the last one."""
    asked = []

    def unmet():
        asked.append(len(asked))
        return None if len(asked) > 2 else f"target missed ({len(asked)})"

    result = run_coupled(1, 1.0, lambda window, k, x: np.ones(3), np.ones(3), tolerance=1e-8, max_iterations=10,
                         unmet=unmet)
    assert result.iterations == [3] and asked == [0, 1, 2]
    asked.clear()
    with pytest.raises(CouplingDiverged, match=r"2 iterations \(max_iterations\), the residual is below tolerance "
                                               r"but target missed \(2\)"):
        run_coupled(1, 1.0, lambda window, k, x: np.ones(3), np.ones(3), tolerance=1e-8, max_iterations=2,
                    unmet=unmet)
