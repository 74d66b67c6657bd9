"""Truncated nonsmooth multigrid on a semi-geometric hierarchy (paper section 2.4).

One iteration (Graeser and Kornhuber's truncated nonsmooth Newton multigrid,
TNNMG, with the monotone multigrid's fine-level smoother of Kornhuber and
Krause) for ``min J(x) = 1/2 x^T A x - b^T x`` on ``lower <= x <= upper``:

1. nonlinear pre-smoothing: projected Gauss-Seidel on the fine level;
2. truncation: the components at a bound (the active set, which includes
   fixed components ``lower == upper``) are removed from the fine basis, and
   the coarse operators are the Galerkin products of the truncated fine matrix
   through the projections of eq. 17 (updated from the untruncated product, only
   when the active set changes);
3. coarse correction: one linear V-cycle on the truncated problem (Gauss-Seidel
   on the coarse levels, a direct solve on the coarsest);
4. the correction is projected onto the feasible set and scaled by an exact line
   search within it, so the coarse levels can never violate a fine constraint;
5. nonlinear post-smoothing (backward sweeps).

Every step lowers J or leaves it unchanged and every iterate is feasible; no
penalty, no augmented Lagrangian. The criterion is the paper's step length
``||x_{k+1} - x_k||_2 < tol`` (section 4.3).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .hierarchy import Hierarchy
from .problem import BoundConstrainedQP, NonsmoothSolveError, Solution
from .smoothers import csr_int32, projected_gauss_seidel
from .solvers import register

#: coarsest problems up to this size are solved densely (eigen-decomposition,
#: robust to the near-dependent coarse functions truncation can leave)
DENSE_COARSE = 3000


class _CoarseSolve:
    """The coarsest truncated problem, solved directly on its positive-diagonal rows."""

    def __init__(self, A: sp.csr_matrix):
        self.rows = np.flatnonzero(A.diagonal() > 0)
        Ar = A[self.rows][:, self.rows]
        self.n = A.shape[0]
        if len(self.rows) <= DENSE_COARSE:
            w, V = la.eigh(Ar.toarray())
            keep = w > 1e-12 * max(w.max(initial=0.0), np.finfo(float).tiny)
            self._dense = V[:, keep] / w[keep]
            self._V = V[:, keep]
            self._lu = None
        else:
            self._lu = spla.splu(Ar.tocsc())

    def __call__(self, r: np.ndarray) -> np.ndarray:
        v = np.zeros(self.n)
        rr = r[self.rows]
        v[self.rows] = self._dense @ (self._V.T @ rr) if self._lu is None else self._lu.solve(rr)
        return v


class _TruncatedGalerkin:
    """``(D P)^T A (D P)`` for the truncation ``D = diag(free)`` of the finest prolongation P.

    ``P^T A P`` and ``A P`` are formed once; with ``S`` the rows of P at the truncated
    components, ``(P - S)^T A (P - S) = P^T A P - S^T A P - (S^T A P)^T + S^T A S`` costs
    only as much as the truncated rows. Coarse functions left without support
    (diagonal below :data:`SUPPORT_RTOL` of the untruncated one) are removed outright."""

    def __init__(self, A: sp.csr_matrix, P: sp.csr_matrix):
        self.A, self.P = A, P
        self.AP = (A @ P).tocsr()
        self.G = (P.T.tocsr() @ self.AP).tocsr()
        self.diagonal = self.G.diagonal()

    def __call__(self, free: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """(truncated prolongation D P, its Galerkin operator)."""
        cut = np.flatnonzero(~free)
        S = self.P[cut]
        M = (S.T.tocsr() @ self.AP[cut]).tocsr()
        Ac = self.G - M - M.T + S.T.tocsr() @ (self.A[cut][:, cut] @ S)
        supported = (Ac.diagonal() > SUPPORT_RTOL * self.diagonal).astype(float)
        Z = sp.diags(supported)
        Ac = (Z @ Ac @ Z).tocsr()
        Ac.eliminate_zeros()
        return (sp.diags(free.astype(float)) @ self.P @ Z).tocsr(), Ac


#: a coarse basis function whose truncated energy is below this fraction of its
#: untruncated energy has lost its support on the free components
SUPPORT_RTOL = 1e-10


class _TruncatedCycle:
    """The linear V-cycle on the coarse levels of the truncated problem."""

    def __init__(self, galerkin: _TruncatedGalerkin, hierarchy: Hierarchy, free: np.ndarray, smoothing: int):
        P_fine, A_coarse = galerkin(free)
        self.prolongations = hierarchy.prolongations[:-1] + [P_fine]
        ops = [A_coarse]
        for P in reversed(hierarchy.prolongations[:-1]):
            ops.append((P.T.tocsr() @ ops[-1] @ P).tocsr())
        self.ops = [csr_int32(op) for op in ops[::-1]]  # coarsest first
        self.coarse = _CoarseSolve(self.ops[0])
        self.inf = [np.full(op.shape[0], np.inf) for op in self.ops]
        self.smoothing = smoothing

    def correction(self, residual: np.ndarray) -> np.ndarray:
        """Fine-level correction P_L V(P_L^T r) (zero on the truncated components)."""
        P = self.prolongations[-1]
        return P @ self._cycle(len(self.ops) - 1, P.T @ residual)

    def _cycle(self, level: int, r: np.ndarray) -> np.ndarray:
        if level == 0:
            return self.coarse(r)
        A, inf, nu = self.ops[level], self.inf[level], self.smoothing
        v = np.zeros(A.shape[0])
        projected_gauss_seidel(A, r, -inf, inf, v, nu, "forward")
        P = self.prolongations[level - 1]
        v += P @ self._cycle(level - 1, P.T @ (r - A @ v))
        projected_gauss_seidel(A, r, -inf, inf, v, nu, "backward")
        return v


def _line_search(qp: BoundConstrainedQP, x: np.ndarray, r: np.ndarray, v: np.ndarray) -> float:
    """argmin of J(x + a v) over the a >= 0 keeping x + a v feasible (J is quadratic in a)."""
    curvature = float(v @ (qp.A @ v))
    if curvature <= 0:
        return 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(v > 0, (qp.upper - x) / v, np.inf)
        down = np.where(v < 0, (qp.lower - x) / v, np.inf)
    longest = float(min(up.min(initial=np.inf), down.min(initial=np.inf)))
    return float(np.clip((r @ v) / curvature, 0.0, longest))


def asymptotic_rate(steps, last: int = 5) -> float:
    """Geometric mean of the step-length ratios over the `last` iterations before
    the final one (whose step is at round-off level); NaN with too few steps."""
    s = np.asarray(steps, dtype=float)[:-1]
    s = s[-(last + 1):]
    if len(s) < 2 or np.any(s <= 0):
        return float("nan")
    return float((s[-1] / s[0]) ** (1.0 / (len(s) - 1)))


def solve_multilevel(qp: BoundConstrainedQP, x0: np.ndarray | None = None, *, hierarchy: Hierarchy | None = None,
                     tol: float = 1e-12, maxiter: int = 200, presmooth: int = 3, postsmooth: int = 3,
                     coarse_smooth: int = 3, callback=None, monitor=None) -> Solution:
    """Truncated nonsmooth multigrid (module docstring) on `hierarchy`, whose
    finest level must be the unknowns of `qp`. Stops when the step length
    ``||x_{k+1} - x_k||_2`` (the criterion reported) falls below `tol`, or after
    `maxiter` iterations (returned unconverged); ``callback(k, x)`` sees every iterate.

    ``Solution.history`` holds the step lengths; ``info`` the energies, the
    largest bound violation over all iterates, the asymptotic rate and the level sizes.
    """
    if hierarchy is None:
        raise ValueError("the multilevel solver needs hierarchy= (nonsmooth.hierarchy.semi_geometric_hierarchy)")
    if hierarchy.sizes[-1] != qp.size:
        raise ValueError(f"the hierarchy's fine level has {hierarchy.sizes[-1]} unknowns, the problem {qp.size}")
    start = time.perf_counter()
    A = csr_int32(qp.A)
    x = qp.project(np.zeros(qp.size) if x0 is None else np.asarray(x0, dtype=float))
    steps, energies, violation = [], [qp.energy(x)], 0.0
    galerkin = _TruncatedGalerkin(A, hierarchy.prolongations[-1])
    cycle, free_prev, rebuilds = None, None, 0
    converged = False
    for k in range(1, maxiter + 1):
        x_prev = x.copy()
        projected_gauss_seidel(A, qp.b, qp.lower, qp.upper, x, presmooth, "forward")
        free = (x > qp.lower) & (x < qp.upper)
        if cycle is None or not np.array_equal(free, free_prev):
            cycle, free_prev = _TruncatedCycle(galerkin, hierarchy, free, coarse_smooth), free
            rebuilds += 1
        r = qp.b - A @ x
        v = cycle.correction(np.where(free, r, 0.0))
        v = qp.project(x + v) - x
        x = qp.project(x + _line_search(qp, x, r, v) * v)  # the clip only removes round-off
        projected_gauss_seidel(A, qp.b, qp.lower, qp.upper, x, postsmooth, "backward")
        if not np.all(np.isfinite(x)):
            raise NonsmoothSolveError(f"multilevel: non-finite iterate at iteration {k}")
        steps.append(float(np.linalg.norm(x - x_prev)))
        energies.append(qp.energy(x))
        violation = max(violation, qp.infeasibility(x))
        if callback is not None:
            callback(k, x)
        if monitor is not None:  # a caller's progress lines (nonsmooth.solvers.solve)
            monitor(multigrid_iteration=k, step_length=steps[-1])
        if steps[-1] < tol:
            converged = True
            break
    active = ~((x > qp.lower) & (x < qp.upper))
    info = {"energies": energies, "max_infeasibility": violation, "asymptotic_rate": asymptotic_rate(steps),
            "level_sizes": hierarchy.sizes, "levels": hierarchy.levels, "coarse_rebuilds": rebuilds,
            "kkt_residual": qp.kkt_residual(x)}
    return Solution(x, len(steps), converged, "multilevel", time.perf_counter() - start, 0, steps, active, info,
                    residual=steps[-1] if steps else float("nan"), tolerance=tol,
                    reason="step length below the tolerance" if converged else "iteration limit")


register("multilevel", solve_multilevel)
