"""The bound-constrained quadratic program shared by every nonsmooth solver.

For contact, ``x`` are the displacements in the transformed basis of paper
eq. 10 (slave nodes rotated to normal/tangential coordinates), so that
non-penetration (eq. 11) is ``x_normal <= gap`` at each slave node. For the
obstacle problem ``x`` are nodal displacements and the bounds the obstacle.
The KKT conditions, with multiplier ``lam = b - A x``::

    lower <= x <= upper,   lam <= 0 where x = lower,   lam >= 0 where x = upper,
    lam = 0 where lower < x < upper.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


class NonsmoothSolveError(RuntimeError):
    """A nonsmooth solve without a usable result (a singular system, NaN), or one a caller
    refuses unconverged (:meth:`Solution.raise_if_unconverged`)."""


@dataclass
class BoundConstrainedQP:
    """min 1/2 x^T A x - b^T x  subject to  lower <= x <= upper.

    A : (n, n) sparse, symmetric positive definite (CSR)
    b : (n,) right-hand side
    lower, upper : (n,) bounds, ``-inf`` / ``+inf`` where free
    block_size : unknowns per node (3 for displacements), for AMG and smoothers
    near_nullspace : (n, k) optional, e.g. rigid body modes, for AMG
    """

    A: sp.csr_matrix
    b: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    block_size: int = 1
    near_nullspace: np.ndarray | None = None

    def __post_init__(self):
        self.A = sp.csr_matrix(self.A)
        n = self.A.shape[0]
        if self.A.shape != (n, n):
            raise ValueError(f"A must be square, got shape {self.A.shape}")
        self.b = np.asarray(self.b, dtype=float)
        self.lower = np.broadcast_to(np.asarray(self.lower, dtype=float), (n,)).copy()
        self.upper = np.broadcast_to(np.asarray(self.upper, dtype=float), (n,)).copy()
        if self.b.shape != (n,):
            raise ValueError(f"b has shape {self.b.shape}, expected ({n},)")
        for name, v in (("A", self.A.data), ("b", self.b)):
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} contains NaN or inf")
        if np.any(np.isnan(self.lower)) or np.any(np.isnan(self.upper)):
            raise ValueError("bounds contain NaN")
        bad = np.flatnonzero(self.lower > self.upper)
        if bad.size:
            raise ValueError(f"empty feasible set: lower > upper at {bad.size} components (first {bad[0]})")
        if n % self.block_size:
            raise ValueError(f"n = {n} is not a multiple of block_size = {self.block_size}")

    @property
    def size(self) -> int:
        return self.A.shape[0]

    @property
    def constrained(self) -> np.ndarray:
        """Indices of components with at least one finite bound."""
        return np.flatnonzero(np.isfinite(self.lower) | np.isfinite(self.upper))

    def energy(self, x: np.ndarray) -> float:
        """J(x) = 1/2 x^T A x - b^T x."""
        return float(0.5 * x @ (self.A @ x) - self.b @ x)

    def project(self, x: np.ndarray) -> np.ndarray:
        """The closest feasible point (componentwise clip)."""
        return np.clip(x, self.lower, self.upper)

    def multiplier(self, x: np.ndarray) -> np.ndarray:
        """lam = b - A x (the constraint force; zero where x is strictly inside the bounds)."""
        return self.b - self.A @ x

    def kkt_residual(self, x: np.ndarray) -> float:
        """max |x - P(x - (A x - b))|: zero exactly at the solution (natural residual)."""
        return float(np.max(np.abs(x - self.project(x + self.multiplier(x))), initial=0.0))

    def infeasibility(self, x: np.ndarray) -> float:
        """Largest bound violation of x."""
        return float(max(np.max(x - self.upper, initial=0.0), np.max(self.lower - x, initial=0.0)))


@dataclass
class Control:
    """One more unknown of a QP: a scalar c the problem depends on affinely (``b + c rhs``, the
    fixed components' bounds ``+ c bounds``) set so that the affine response ``sum(response * x)``
    reaches ``target`` (e.g. a rigid platen's displacement under a prescribed mean stress, paper
    4.1: the mean force as a constraint). Arrays are the local parts on several ranks.

    rhs : d b / d c; bounds : d(lower = upper) / d c on the fixed components (0 elsewhere)
    response : the gradient g of the controlled quantity g . x
    target : the value g . x must reach
    slope : d(g . x) / d c assumed while the active sets carry none (a body held only by c)
    """

    rhs: np.ndarray
    bounds: np.ndarray
    response: np.ndarray
    target: float
    slope: float


@dataclass
class Solution:
    """What every nonsmooth solver returns, converged or not: a solver raises
    :class:`NonsmoothSolveError` only when it has no usable iterate (NaN, a matrix that is
    not SPD, a breakdown); hitting its iteration limit is told by ``converged`` False.

    ``residual`` is the final value of the solver's own stopping criterion and
    ``tolerance`` the value it had to reach (both in the solver's scaling, see each
    solver); ``reason`` says why it stopped.
    """

    x: np.ndarray
    iterations: int  # outer iterations (active-set, Newton, multigrid cycles)
    converged: bool
    solver: str
    seconds: float = 0.0
    krylov_iterations: int = 0  # total inner linear iterations, where there are any
    history: list[float] = field(default_factory=list)  # per outer iteration: the solver's own criterion
    active: np.ndarray | None = None  # boolean mask of components at a bound, at the end
    info: dict = field(default_factory=dict)
    residual: float = float("nan")
    tolerance: float = float("nan")
    reason: str = ""

    def as_dict(self) -> dict:
        """Figures for summary.json and benchmark JSON (no arrays)."""
        return {"solver": self.solver, "iterations": self.iterations, "converged": self.converged,
                "residual": self.residual, "tolerance": self.tolerance, "reason": self.reason,
                "seconds": self.seconds, "krylov_iterations": self.krylov_iterations,
                "history": [float(h) for h in self.history],
                "active": None if self.active is None else int(np.count_nonzero(self.active)), **self.info}

    def describe(self) -> str:
        """One line: ``active_set did not converge: criterion 3.2e-03 > 1e-10 after 1 iteration (iteration limit)``."""
        state, relation = ("converged", "<=") if self.converged else ("did not converge", ">")
        return (f"{self.solver} {state}: criterion {self.residual:.3g} {relation} {self.tolerance:g} after "
                f"{self.iterations} iteration{'s' * (self.iterations != 1)} ({self.reason})")

    def raise_if_unconverged(self, what: str) -> "Solution":
        """``self`` if converged, else :class:`NonsmoothSolveError` naming `what` (for
        callers that cannot report an unconverged solve, e.g. a study's bracketing)."""
        if not self.converged:
            raise NonsmoothSolveError(f"{what}: {self.describe()}")
        return self
