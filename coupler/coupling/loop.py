"""The participant-agnostic time loop with implicit coupling (paper, section 2.3, Steps 1-6).

Each time window ``[t_n, t_n + dt]`` solves the interface fixed point ``x = H(x)``
by iteration. The loop knows nothing of fluids, solids or messaging: the caller
supplies

- ``iterate(window, iteration, x) -> H(x)``: one pass of Steps 1-4 and 6 with the
  interface quantity ``x`` as input (e.g. for the fluid-structure scheme of the
  paper: advance the fluid with the solid velocity ``x`` on the fluid grid,
  project velocity and pressure to the solid mesh, reconstruct the forces,
  advance the solid, project its velocity back: that velocity is ``H(x)``);
- ``checkpoint.save(window)`` / ``checkpoint.restore(window)``: the participants'
  states at the start of the window (``save_state``/``restore_state`` of the
  protocol), so that every iteration of a window starts from the same state;
- ``on_converged(window, x, step)``: called once per window with the accepted
  interface value and the window's :class:`StepRecord`, where the caller writes
  output and advances its participants' clocks.

With ``comm`` (an mpi4py communicator) every coupler rank runs the loop on its own rows of
``x`` (and of the weights): ``iterate`` returns this rank's rows of ``H(x)``, the residual
norms and the accelerator's factors are reduced over the ranks (:mod:`coupler.coupling.row_sums`),
so every rank takes the same decisions (converged, diverged, the next iterate's factors) and
raises the same errors.

The loop does Step 5: it measures the interface residual ``||H(x) - x||_M`` in the
mass-weighted L2 norm (:mod:`coupler.convergence`), stops the window when it is
small relative to ``||H(x)||_M``, and otherwise computes the next iterate with an
accelerator (:mod:`coupler.acceleration`: constant relaxation, Aitken, IQN-ILS).
Per window::

    checkpoint.save(window)
    x = prediction (the converged value of the last window)
    for k = 0, 1, ...:
        if k > 0: checkpoint.restore(window)
        Hx = iterate(window, k, x)                 # NaN/inf -> NonFiniteInterface at once
        if ||Hx - x||_M <= tol ||Hx||_M and unmet() is None: accept Hx, on_converged(window, Hx, step), next window
        x = accelerator.update(x, Hx)
    max_iterations reached -> CouplingDiverged (or accept, when allow_unconverged)

The explicit (one-way) mode calls ``iterate`` once per window and accepts its
output: for solid-only scenes and one-way transfers. The residual
``||H(x) - x||_M`` between consecutive windows is still recorded there for
information.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from coupler.coupling.acceleration import Accelerator, ConstantRelaxation
from coupler.coupling.convergence import ConvergenceMonitor, as_weights
from coupler.coupling.row_sums import RowSums
from coupler.errors import CouplerError, NotConverged

__all__ = ["TimeWindow", "Checkpoint", "StepRecord", "CouplingResult", "CouplingError", "CouplingDiverged",
           "NonFiniteInterface", "run_coupled", "COUPLINGS"]

COUPLINGS = ("implicit", "explicit")


@dataclass(frozen=True)
class TimeWindow:
    """One time window (time step of the coupling): index and interval ``[t_start, t_end]``."""

    index: int
    t_start: float
    t_end: float

    @property
    def dt(self) -> float:
        return self.t_end - self.t_start

    def __str__(self) -> str:
        return f"time step {self.index} (t = {self.t_start:.6g} .. {self.t_end:.6g})"


class Checkpoint(Protocol):
    """Saves and restores the participants' states at the start of a window."""

    def save(self, window: TimeWindow) -> None: ...

    def restore(self, window: TimeWindow) -> None: ...


@dataclass
class StepRecord:
    """What happened in one time window."""

    window: int
    t_start: float
    t_end: float
    iterations: int
    residuals: list[float]  # relative residual ||H(x)-x||_M / ||H(x)||_M per iteration
    abs_residuals: list[float]  # ||H(x)-x||_M per iteration
    converged: bool
    seconds: float  # wall time of the window
    seconds_iterate: float  # in iterate() (the participants and the transfers)
    seconds_acceleration: float  # in the accelerator
    seconds_checkpoint: float  # in checkpoint save/restore

    def to_dict(self) -> dict:
        return {"window": self.window, "t_start": self.t_start, "t_end": self.t_end,
                "iterations": self.iterations, "converged": self.converged,
                "residuals": list(self.residuals), "abs_residuals": list(self.abs_residuals),
                "seconds": self.seconds, "seconds_iterate": self.seconds_iterate,
                "seconds_acceleration": self.seconds_acceleration, "seconds_checkpoint": self.seconds_checkpoint}


@dataclass
class CouplingResult:
    """Per-step iterations, residual histories and converged flags of a coupled run."""

    coupling: str
    tolerance: float
    norm: str
    accelerator: dict
    steps: list[StepRecord] = field(default_factory=list)
    x: np.ndarray | None = None  # the last accepted interface value
    completed: bool = False  # all windows done
    seconds: float = 0.0

    @property
    def iterations(self) -> list[int]:
        return [s.iterations for s in self.steps]

    @property
    def residual_histories(self) -> list[list[float]]:
        return [list(s.residuals) for s in self.steps]

    @property
    def converged(self) -> list[bool]:
        return [s.converged for s in self.steps]

    @property
    def total_iterations(self) -> int:
        return int(sum(self.iterations))

    @property
    def all_converged(self) -> bool:
        return all(self.converged)

    def to_dict(self) -> dict:
        """JSON-ready, for ``summary.json``."""
        its = self.iterations
        return {"coupling": self.coupling, "tolerance": self.tolerance, "norm": self.norm,
                "acceleration": dict(self.accelerator), "completed": self.completed,
                "steps_done": len(self.steps), "total_iterations": self.total_iterations,
                "mean_iterations": float(np.mean(its)) if its else 0.0,
                "max_iterations": int(max(its)) if its else 0,
                "all_converged": self.all_converged, "seconds": self.seconds,
                "seconds_iterate": float(sum(s.seconds_iterate for s in self.steps)),
                "seconds_acceleration": float(sum(s.seconds_acceleration for s in self.steps)),
                "seconds_checkpoint": float(sum(s.seconds_checkpoint for s in self.steps)),
                "steps": [s.to_dict() for s in self.steps]}


class CouplingError(CouplerError):
    """The coupling iteration stopped; ``result`` holds the windows done so far."""

    result: CouplingResult | None = None


class CouplingDiverged(CouplingError, NotConverged):
    """A window did not converge within `max_iterations`, or its residual blew up."""

    def __init__(self, message: str, *, step: int, time: float, iterations: int, residual: float,
                 residuals: list[float], reason: str = "max_iterations"):
        super().__init__(message)
        self.step = step
        self.time = time
        self.iterations = iterations
        self.residual = residual
        self.residuals = residuals
        self.reason = reason


class NonFiniteInterface(CouplingError):
    """``H(x)`` (or the accelerated iterate) contains NaN or infinity."""

    def __init__(self, message: str, *, step: int, time: float, iteration: int, count: int, first: int,
                 where: str):
        super().__init__(message)
        self.step = step
        self.time = time
        self.iteration = iteration
        self.count = count
        self.first = first
        self.where = where


def _check_finite(v: np.ndarray, window: TimeWindow, iteration: int, where: str, rows: RowSums = RowSums()) -> None:
    """Raise NonFiniteInterface on every rank when some rank's rows of `v` hold NaN or inf
    (counts over all ranks, the first bad dof in global numbering: lower ranks' rows first)."""
    finite = np.isfinite(v)
    if not rows.any(not finite.all()):
        return
    bad = np.flatnonzero(~finite)
    local = np.array([bad.size, np.count_nonzero(np.isnan(v)), v.size], dtype=float)
    count, nans, size = (int(c) for c in rows.sum(local))
    offset = rows.offset(v.size)
    first = int(rows.extremum(offset + bad[0] if bad.size else math.inf, "min"))
    kinds = ", ".join(k for k, c in (("NaN", nans), ("inf", count - nans)) if c)
    raise NonFiniteInterface(
        f"{window}, iteration {iteration}: {where} has {count} non-finite values ({kinds}) of {size}, "
        f"first at dof {first}; a participant produced NaN/inf or the coupling blew up",
        step=window.index, time=window.t_start, iteration=iteration, count=count, first=first, where=where)


def _as_interface(v, size: int, window: TimeWindow, iteration: int) -> np.ndarray:
    a = np.asarray(v, dtype=float).ravel()
    if a.size != size:
        raise CouplingError(f"{window}, iteration {iteration}: iterate returned {a.size} interface values, "
                            f"expected {size} (the size of x)")
    return a


def _fmt(values) -> str:
    return ", ".join(f"{v:.3g}" for v in values)


def run_coupled(steps: int, dt: float, iterate: Callable[[TimeWindow, int, np.ndarray], np.ndarray], x0,
                accelerator: Accelerator | None = None, tolerance: float = 1e-6, max_iterations: int = 50,
                checkpoint: Checkpoint | None = None,
                on_converged: Callable[[TimeWindow, np.ndarray, "StepRecord"], None] | None = None,
                progress=None, *, weights=None, abs_tolerance: float = 0.0, allow_unconverged: bool = False,
                coupling: str = "implicit", t0: float = 0.0, extrapolation: int = 0,
                divergence_factor: float | None = 1e8,
                unmet: Callable[[], str | None] | None = None, comm=None) -> CouplingResult:
    """Run `steps` time windows of length `dt`, each to convergence of the interface fixed point.

    Parameters
    ----------
    steps, dt, t0:
        number of windows, their length, the start time; window ``n`` is
        ``[t0 + n dt, t0 + (n + 1) dt]``.
    iterate:
        ``iterate(window, iteration, x) -> H(x)``: one coupling iteration (Steps
        1-4 and 6) on the interface vector ``x`` (flat float array of fixed size).
    x0:
        the interface value before the first window (the first prediction).
    accelerator:
        an :class:`~coupler.acceleration.Accelerator`; ``None`` is the plain
        iteration (``ConstantRelaxation(1.0)``).
    tolerance, abs_tolerance:
        converged when ``||H(x) - x||_M <= tolerance ||H(x)||_M`` or
        ``||H(x) - x||_M <= abs_tolerance``.
    max_iterations:
        evaluations of ``H`` per window at most.
    checkpoint:
        ``save(window)`` before the first iteration of a window,
        ``restore(window)`` before every further one; ``None`` when ``iterate``
        has no state of its own.
    on_converged:
        ``on_converged(window, x, step)`` with the accepted interface value ``H(x)``
        of the last iteration and the window's :class:`StepRecord` (already in the
        result), once per window.
    progress:
        an object with ``update(n, status)`` and ``close()`` told of every window, and
        optionally ``iteration(window, iteration, residual)`` of every coupling iteration
        (e.g. :class:`coupler.output.progress.ProgressBar`), or ``None``.
    weights:
        the lumped mass per dof of ``x`` (M-norm of the residual); also given to
        the accelerator when it has no weights of its own.
    allow_unconverged:
        accept the last iterate of a window that reached `max_iterations` (with
        a warning) instead of raising :class:`CouplingDiverged`.
    coupling:
        ``"implicit"`` (fixed point per window) or ``"explicit"`` (one call of
        ``iterate`` per window, its output accepted; no checkpoints, no
        accelerator).
    extrapolation:
        prediction of a window's first iterate from the converged values: 0
        (the last one) or 1 (linear, ``2 x_n - x_{n-1}``).
    unmet:
        a further condition of convergence (e.g. a target the interface vector carries an
        unknown for): called once the residual is below tolerance, ``None`` when it holds, else
        why not (one line, named when the window reaches `max_iterations`); the window goes on.
    divergence_factor:
        raise :class:`CouplingDiverged` at once when ``||H(x) - x||_M`` grows
        beyond this factor times its value in the first iteration of the window
        (also with `allow_unconverged`); ``None`` disables it.
    comm:
        an mpi4py communicator when `x0`, `weights` and what `iterate` returns are this
        rank's rows of the interface vector (any number, none too); the accelerator is
        given it when it has none (it must not have another). All ranks call
        ``run_coupled`` together; ``None``: serial.

    Returns
    -------
    CouplingResult
        also attached as ``.result`` to any :class:`CouplingError` raised, and as
        ``.coupling_result`` to any other exception passing through (a failed
        participant, ``KeyboardInterrupt``), holding the windows completed.

    Raises
    ------
    CouplingDiverged
        a window did not converge in `max_iterations` (unless `allow_unconverged`)
        or its residual blew up; the message names the step, the iterations and
        the last residuals.
    NonFiniteInterface
        ``H(x)`` contained NaN/inf (names the step, iteration and first bad dof).
    """
    if coupling not in COUPLINGS:
        raise ValueError(f"run_coupled: coupling must be one of {', '.join(COUPLINGS)}, not {coupling!r}")
    if int(steps) != steps or steps < 0:
        raise ValueError(f"run_coupled: steps must be a non-negative integer, not {steps}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"run_coupled: dt must be positive, not {dt}")
    if int(max_iterations) != max_iterations or max_iterations < 1:
        raise ValueError(f"run_coupled: max_iterations must be a positive integer, not {max_iterations}")
    if extrapolation not in (0, 1):
        raise ValueError(f"run_coupled: extrapolation must be 0 or 1, not {extrapolation}")
    steps, max_iterations = int(steps), int(max_iterations)
    x = np.asarray(x0, dtype=float).ravel().copy()
    size = x.size
    first = TimeWindow(0, float(t0), float(t0) + dt)
    rows = RowSums(comm)
    _check_finite(x, first, 0, "the initial interface value x0", rows)
    w = as_weights(weights, size, comm)
    implicit = coupling == "implicit"
    if implicit:
        if accelerator is None:
            accelerator = ConstantRelaxation(1.0)
        if accelerator.comm is None:
            accelerator.comm = comm
        elif RowSums(accelerator.comm).comm is not rows.comm:
            raise ValueError("run_coupled: the accelerator's comm is not the loop's")
        if w is not None and accelerator.weights is None:
            accelerator.set_weights(w)
    monitor = ConvergenceMonitor(tolerance, abs_tolerance, w, comm)
    result = CouplingResult(coupling=coupling, tolerance=float(tolerance), norm=monitor.summary()["norm"],
                            accelerator=accelerator.info() if implicit else {"name": "none (explicit)"})
    bar = progress
    x_prev_converged: np.ndarray | None = None
    start_run = time.perf_counter()
    try:
        for n in range(steps):
            window = TimeWindow(n, float(t0) + n * dt, float(t0) + (n + 1) * dt)
            history = monitor.start_window(n, window.t_start)
            start = time.perf_counter()
            t_iterate = t_accel = t_checkpoint = 0.0
            converged = False
            if not implicit:
                tic = time.perf_counter()
                Hx = _as_interface(iterate(window, 0, x.copy()), size, window, 0)
                t_iterate += time.perf_counter() - tic
                _check_finite(Hx, window, 0, "H(x)", rows)
                monitor.measure(x, Hx)
                converged = True
            else:
                if checkpoint is not None:
                    tic = time.perf_counter()
                    checkpoint.save(window)
                    t_checkpoint += time.perf_counter() - tic
                accelerator.start_window()
                first_abs = None
                for k in range(max_iterations):
                    if k > 0 and checkpoint is not None:
                        tic = time.perf_counter()
                        checkpoint.restore(window)
                        t_checkpoint += time.perf_counter() - tic
                    tic = time.perf_counter()
                    Hx = _as_interface(iterate(window, k, x.copy()), size, window, k)
                    t_iterate += time.perf_counter() - tic
                    _check_finite(Hx, window, k, "H(x)", rows)
                    res = monitor.measure(x, Hx)
                    if hasattr(bar, "iteration"):
                        bar.iteration(n, k, res.relative)
                    pending = None
                    if monitor.is_converged(res):
                        pending = unmet() if unmet is not None else None
                        if pending is None:
                            converged = True
                            break
                    if first_abs is None:
                        first_abs = res.absolute
                    elif divergence_factor is not None and res.absolute > divergence_factor * first_abs:
                        raise CouplingDiverged(
                            f"coupling diverges in {window}: after {k + 1} iterations the interface residual "
                            f"||H(x)-x||_M = {res.absolute:.3g} has grown by more than {divergence_factor:g} times "
                            f"its first value {first_abs:.3g} (relative residuals: {_fmt(history.relative[-5:])}); "
                            f"{accelerator.name} {_describe(accelerator)}: {accelerator.advice()}", step=n, time=window.t_start, iterations=k + 1, residual=res.relative,
                            residuals=list(history.relative), reason="divergence")
                    if k == max_iterations - 1:
                        break
                    tic = time.perf_counter()
                    x_next = accelerator.update(x, Hx)
                    t_accel += time.perf_counter() - tic
                    _check_finite(x_next, window, k, f"the {accelerator.name} update", rows)
                    x = x_next
                if not converged:
                    last = history.relative[-1]
                    reason = (f"the residual is below tolerance but {pending}" if pending else
                              f"last relative residual {last:.3g} > tolerance {tolerance:g}")
                    message = (f"coupling did not converge in {window}: {history.iterations} iterations "
                               f"(max_iterations), {reason} "
                               f"({result.norm} norm); residuals of the last iterations: "
                               f"{_fmt(history.relative[-5:])}; acceleration {accelerator.name} "
                               f"{_describe(accelerator)}")
                    if not allow_unconverged:
                        raise CouplingDiverged(f"{message}: raise [coupling] max_iterations, or "
                                               f"{accelerator.advice()}", step=n, time=window.t_start,
                                               iterations=history.iterations, residual=last,
                                               residuals=list(history.relative))
                    warnings.warn(message + "; accepted (allow_unconverged)", RuntimeWarning, stacklevel=2)
                tic = time.perf_counter()
                accelerator.end_window(x, Hx)
                t_accel += time.perf_counter() - tic
            monitor.end_window(converged)
            accepted = Hx.copy()
            step = StepRecord(n, window.t_start, window.t_end, history.iterations, list(history.relative),
                              list(history.absolute), converged, time.perf_counter() - start, t_iterate, t_accel,
                              t_checkpoint)
            result.steps.append(step)
            result.x = accepted
            if on_converged is not None:
                on_converged(window, accepted.copy(), step)
            if extrapolation == 1 and x_prev_converged is not None:
                x = 2.0 * accepted - x_prev_converged
            else:
                x = accepted.copy()
            x_prev_converged = accepted
            if bar is not None:
                bar.update(1, status=f"it={history.iterations} res={history.relative[-1]:.2e}"
                           + ("" if converged else " (unconverged)"))
        result.completed = True
    except CouplingError as exc:
        exc.result = result
        raise
    except BaseException as exc:  # a participant failed, Ctrl-C: the windows done so far stay available
        try:
            exc.coupling_result = result
        except AttributeError:
            pass
        raise
    finally:
        result.seconds = time.perf_counter() - start_run
        if implicit:
            result.accelerator = accelerator.info()
        if bar is not None:
            bar.close()
    return result


def _describe(accelerator: Accelerator) -> str:
    info = {k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in accelerator.info().items() if k != "name"}
    return "(" + ", ".join(f"{k}={v}" for k, v in info.items()) + ")" if info else ""
