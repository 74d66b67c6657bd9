"""Convergence of the coupling iteration: the interface residual in the mass-weighted L2 norm.

Step 5 of the coupling scheme (paper, section 2.3) checks whether the fixed-point
iteration ``x_{k+1} = H(x_k)`` of one time window has converged. ``x`` is the
interface quantity (a flat vector of dof values, e.g. the solid velocity on the
fluid grid, or traction and displacement concatenated) and ``H`` one pass of
Steps 1-4 and 6. The residual is measured in the discrete L2 norm of the
interface field,

    ||v||_M^2 = sum_i m_i v_i^2,

with ``M = diag(m)`` the lumped (row-sum) mass matrix of the space the field lives
in, repeated per component for vector fields. Unlike the Euclidean norm of the dof
vector, this norm does not depend on how finely or how unevenly the interface is
meshed: a vertex of a tiny element weighs little, a vertex of a large one much.

The convergence test is relative (Uekermann, "Partitioned fluid-structure
interaction on massively parallel systems", PhD thesis, TU Munich 2016, sec. 2.3)::

    ||H(x) - x||_M <= tol * ||H(x)||_M          (relative)
    ||H(x) - x||_M <= abs_tol                   (absolute floor, optional)

and the reference norm in the denominator of the reported relative residual is
floored so that an interface field that vanishes (no load in a window) gives a
finite number instead of 0/0.

With ``comm`` (an mpi4py communicator) the vectors and weights hold this rank's rows only
(:mod:`coupler.coupling.row_sums`): the norms are local sums and one allreduce, the same on
every rank; ``comm=None`` is the serial computation, unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from coupler.coupling.row_sums import RowSums, inner, norm  # noqa: F401  (inner, norm: the M-inner product's API)

#: Denominator floor of the relative residual: below this the reference norm counts as zero.
REFERENCE_FLOOR = 1e-300


def as_weights(weights, size: int | None = None, comm=None) -> np.ndarray | None:
    """Check a diagonal mass (one non-negative weight per dof); ``None`` means the Euclidean norm.

    With `comm` the weights are this rank's rows and the checks are collective: every rank
    raises when one rank's weights are wrong, or when all ranks' weights are zero."""
    if weights is None:
        return None
    rows = RowSums(comm)
    w = np.asarray(weights, dtype=float).ravel()
    local = [size is not None and w.size != size, not np.all(np.isfinite(w)) or np.any(w < 0), w.size > 0,
             np.any(w > 0)]
    wrong_size, invalid, some_rows, positive = map(bool, rows.extremum(np.array(local, dtype=float), "max"))
    where = " (on some rank)" if rows.distributed else ""
    if wrong_size:
        raise ValueError(f"interface weights: {w.size} values for an interface vector of {size} dofs{where}")
    if invalid:
        raise ValueError(f"interface weights: a lumped mass must be finite and non-negative{where}")
    if some_rows and not positive:
        raise ValueError("interface weights: all weights are zero")
    return w


def dof_weights(mass, components: int = 1, layout: str = "interleaved") -> np.ndarray:
    """Per-dof weights of a field from the lumped mass per node.

    A vector field with ``components`` values per node has the node's mass on
    each component. ``layout="interleaved"`` is the C-order flattening of an
    array of shape (nodes, components) (x0, y0, z0, x1, ...); ``"blocked"`` is
    (x0, x1, ..., y0, y1, ...).
    """
    m = np.asarray(mass, dtype=float).ravel()
    if components == 1:
        return m.copy()
    if layout == "interleaved":
        return np.repeat(m, components)
    if layout == "blocked":
        return np.tile(m, components)
    raise ValueError(f"dof_weights: layout must be 'interleaved' or 'blocked', not {layout!r}")


def concatenate_weights(*weights) -> np.ndarray:
    """Weights of an interface vector made of several fields concatenated (same order as the fields)."""
    return np.concatenate([np.asarray(w, dtype=float).ravel() for w in weights])


@dataclass(frozen=True)
class Residual:
    """The interface residual of one iteration: ``||H(x) - x||_M`` and its reference ``||H(x)||_M``."""

    absolute: float
    reference: float

    @property
    def relative(self) -> float:
        if self.absolute == 0.0:
            return 0.0
        return self.absolute / max(self.reference, REFERENCE_FLOOR)


def interface_residual(x, Hx, weights=None, comm=None) -> Residual:
    """The residual ``H(x) - x`` of the fixed-point iteration measured in the M-norm (with
    `comm`: this rank's rows of x, H(x) and the weights; both norms in one allreduce)."""
    x = np.asarray(x, dtype=float).ravel()
    Hx = np.asarray(Hx, dtype=float).ravel()
    if x.shape != Hx.shape:
        raise ValueError(f"interface residual: x has {x.size} values, H(x) has {Hx.size}")
    w = as_weights(weights, x.size, comm)
    rows = RowSums(comm)
    if not rows.distributed:
        return Residual(norm(Hx - x, w), norm(Hx, w))
    absolute, reference = rows.norms([Hx - x, Hx], w)
    return Residual(float(absolute), float(reference))


def relative_residual(x, Hx, weights=None, comm=None) -> float:
    """``||H(x) - x||_M / ||H(x)||_M`` with the denominator floored at :data:`REFERENCE_FLOOR`."""
    return interface_residual(x, Hx, weights, comm).relative


@dataclass
class WindowHistory:
    """The residuals of the iterations of one time window."""

    window: int
    time: float
    relative: list[float] = field(default_factory=list)
    absolute: list[float] = field(default_factory=list)
    converged: bool = False

    @property
    def iterations(self) -> int:
        return len(self.relative)

    def to_dict(self) -> dict:
        return {"window": self.window, "time": self.time, "iterations": self.iterations,
                "converged": self.converged, "residuals": list(self.relative),
                "absolute_residuals": list(self.absolute)}


class ConvergenceMonitor:
    """Measures the interface residual of every iteration, decides convergence, keeps the history.

    Parameters
    ----------
    tolerance:
        relative tolerance: converged when ``||H(x) - x||_M <= tolerance * ||H(x)||_M``.
    abs_tolerance:
        absolute floor: also converged when ``||H(x) - x||_M <= abs_tolerance``
        (in the units of the interface field; 0 disables it).
    weights:
        the lumped mass per dof (``M = diag(weights)``); ``None`` is the Euclidean
        norm of the dof vector.
    comm:
        an mpi4py communicator when x, H(x) and the weights hold this rank's rows only
        (the residuals are then the same on every rank); ``None``: serial.
    """

    def __init__(self, tolerance: float, abs_tolerance: float = 0.0, weights=None, comm=None):
        if not tolerance >= 0 or not abs_tolerance >= 0:
            raise ValueError("convergence: tolerances must be non-negative")
        self.tolerance = float(tolerance)
        self.abs_tolerance = float(abs_tolerance)
        self.comm = comm
        self.weights = as_weights(weights, comm=comm)
        self.windows: list[WindowHistory] = []

    def start_window(self, window: int, time: float = 0.0) -> WindowHistory:
        self.windows.append(WindowHistory(int(window), float(time)))
        return self.windows[-1]

    @property
    def current(self) -> WindowHistory:
        if not self.windows:
            raise RuntimeError("ConvergenceMonitor: no window started")
        return self.windows[-1]

    def measure(self, x, Hx) -> Residual:
        """Measure and record the residual of one iteration."""
        res = interface_residual(x, Hx, self.weights, self.comm)
        self.current.relative.append(res.relative)
        self.current.absolute.append(res.absolute)
        return res

    def is_converged(self, res: Residual) -> bool:
        return res.absolute <= self.tolerance * res.reference or res.absolute <= self.abs_tolerance

    def end_window(self, converged: bool) -> None:
        self.current.converged = bool(converged)

    def summary(self) -> dict:
        """A JSON-ready summary: per window the iterations, residual history and converged flag."""
        its = [w.iterations for w in self.windows]
        return {"tolerance": self.tolerance, "abs_tolerance": self.abs_tolerance,
                "norm": "euclidean" if self.weights is None else "mass-weighted L2 (lumped mass)",
                "windows": [w.to_dict() for w in self.windows],
                "total_iterations": int(sum(its)),
                "mean_iterations": float(np.mean(its)) if its else 0.0,
                "max_iterations": int(max(its)) if its else 0,
                "all_converged": all(w.converged for w in self.windows)}
