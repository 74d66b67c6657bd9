"""Acceleration of the coupling iteration: constant relaxation, Aitken, IQN-ILS.

Within one time window the partitioned scheme of the paper (section 2.3, Steps
1-6) is a fixed-point iteration on the interface quantity ``x`` (a flat float
vector, e.g. the solid velocity on the fluid grid, or traction and displacement
concatenated)::

    x~_k = H(x_k)                     Steps 1-4 and 6: both solvers and the transfers
    r_k  = H(x_k) - x_k               Step 5: interface residual, convergence check
    x_{k+1} = update(x_k, x~_k)       Step 5: acceleration (this module)

Plain iteration ``x_{k+1} = x~_k`` diverges for strong added-mass effects or
converges slowly; the accelerators below post-process it. They all share one
interface (:class:`Accelerator`)::

    acc.start_window()                         # a new time window begins
    x_next = acc.update(x, Hx)                 # one non-converged iteration
    acc.end_window(x, Hx)                      # the window converged on (x, Hx)

and an optional diagonal weight vector ``m`` (the lumped mass per dof, repeated
per component for vector fields, see :func:`coupler.convergence.dof_weights`):
inner products and norms are then the discrete L2 ones, ``(u, v)_M = sum m_i u_i
v_i``, so that the result does not depend on how unevenly the interface is
meshed.

Every accelerator takes an optional ``comm`` (an mpi4py communicator): x, H(x), the
weights and IQN-ILS's secant columns then hold this rank's rows only (any number, none
too), every inner product is a local sum and one allreduce (:mod:`coupler.coupling.row_sums`),
and the factors derived from them (Aitken's omega, the QR's triangle, the least-squares
coefficients, the columns filtered out) are the same on every rank. ``comm=None`` is the
serial computation, unchanged.

References
----------
- B. M. Irons, R. C. Tuck, "A version of the Aitken accelerator for computer
  iteration", Int. J. Numer. Meth. Eng. 1 (1969) 275-277.
- U. Küttler, W. A. Wall, "Fixed-point fluid-structure interaction solvers with
  dynamic relaxation", Comput. Mech. 43 (2008) 61-72.
- J. Degroote, K.-J. Bathe, J. Vierendeels, "Performance of a new partitioned
  procedure versus a monolithic procedure in fluid-structure interaction",
  Comput. Struct. 87 (2009) 793-801 (IQN-ILS).
- R. Haelterman, A. Bogaers, K. Scheufele, B. Uekermann, M. Mehl, "Improving the
  performance of the partitioned QN-ILS procedure for fluid-structure interaction
  problems: Filtering", Comput. Struct. 171 (2016) 9-17 (QR1, QR2 filters).
- B. Uekermann, "Partitioned fluid-structure interaction on massively parallel
  systems", PhD thesis, TU Munich (2016): the preCICE implementation followed
  here (column order, reuse of past time windows, filters).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular

from coupler.coupling.convergence import as_weights, inner
from coupler.coupling.row_sums import RowSums

__all__ = ["Accelerator", "ConstantRelaxation", "Aitken", "IQNILS", "FilteredQR",
           "filtered_qr", "make_accelerator", "ACCELERATIONS"]


def _vector(a) -> np.ndarray:
    return np.asarray(a, dtype=float).ravel()


class Accelerator:
    """Post-processing of a fixed-point iteration ``x_{k+1} = H(x_k)`` (common interface).

    Parameters
    ----------
    weights:
        the diagonal of the (lumped) mass matrix ``M``, one non-negative value per
        dof of ``x``; ``None`` uses the Euclidean inner product.
    comm:
        an mpi4py communicator when x, H(x) and the weights hold this rank's rows only;
        ``None``: serial. Every method is then collective.
    """

    name = "accelerator"

    def __init__(self, weights=None, comm=None):
        self.comm = comm
        self.weights = as_weights(weights, comm=comm)
        self.iteration = 0  # iterations of the current window seen by update()
        self.windows = 0  # windows completed (end_window calls)

    def set_weights(self, weights) -> None:
        """Set the diagonal mass of the inner product (before the first window)."""
        self.weights = as_weights(weights, comm=self.comm)

    @property
    def rows(self) -> RowSums:
        """The sums over the ranks' rows (serial when `comm` is None)."""
        return RowSums(self.comm)

    def _check(self, x, Hx) -> tuple[np.ndarray, np.ndarray]:
        x = _vector(x)
        Hx = _vector(Hx)
        if x.shape != Hx.shape:
            raise ValueError(f"{self.name}: x has {x.size} values but H(x) has {Hx.size}")
        if self.weights is not None and self.weights.size != x.size:
            raise ValueError(f"{self.name}: {self.weights.size} weights for an interface vector of {x.size} dofs")
        return x, Hx

    def start_window(self) -> None:
        """A new time window begins: forget the previous iterate of the old window."""
        self.iteration = 0

    def update(self, x, Hx) -> np.ndarray:
        """Given the iterate ``x`` and its image ``Hx = H(x)`` (not converged), return the next iterate."""
        raise NotImplementedError

    def end_window(self, x=None, Hx=None) -> None:
        """The window converged; ``(x, Hx)`` of the last (converged) iteration, if given, is kept as information."""
        self.iteration = 0
        self.windows += 1

    def info(self) -> dict:
        """JSON-ready parameters and statistics (for summary.json)."""
        return {"name": self.name}

    def advice(self) -> str:
        """What to try in a scene's ``[coupling]`` table when this accelerator's iteration
        diverges or stalls (a message must not advise what the scene already does)."""
        return "use [coupling] acceleration = 'iqn-ils'"


class ConstantRelaxation(Accelerator):
    """Constant under-relaxation ``x_{k+1} = x_k + omega (H(x_k) - x_k)``.

    ``omega = 1`` is the plain (Gauss-Seidel) iteration of Steps 1-6. For a
    linearised ``H`` with iteration matrix ``A`` the relaxed iteration matrix is
    ``(1 - omega) I + omega A``; it converges only if all eigenvalues ``lambda``
    of ``A`` satisfy ``|1 - omega (1 - lambda)| < 1``, which for strong
    added-mass effects requires a small ``omega`` and many iterations.
    """

    name = "constant"

    def __init__(self, omega: float = 0.5, weights=None, comm=None):
        super().__init__(weights, comm)
        if not (math.isfinite(omega) and omega > 0):
            raise ValueError(f"constant relaxation: omega must be positive, not {omega}")
        self.omega = float(omega)

    def update(self, x, Hx) -> np.ndarray:
        x, Hx = self._check(x, Hx)
        self.iteration += 1
        return x + self.omega * (Hx - x)

    def info(self) -> dict:
        return {"name": self.name, "omega": self.omega}

    def advice(self) -> str:
        return (f"use [coupling] acceleration = 'iqn-ils' (or 'aitken'), or a relaxation below "
                f"the present {self.omega:g}")


class Aitken(Accelerator):
    """Aitken dynamic relaxation (Irons & Tuck 1969; Küttler & Wall 2008, eq. 44).

    ``x_{k+1} = x_k + omega_k r_k`` with ``r_k = H(x_k) - x_k`` and

        omega_k = -omega_{k-1} (r_{k-1}, r_k - r_{k-1})_M / ||r_k - r_{k-1}||_M^2,

    the secant estimate of the optimal relaxation along the last direction (one
    column of IQN-ILS). The first iteration of a window uses
    ``sign(omega_prev) * min(omega0, |omega_prev|)`` with ``omega_prev`` the last
    factor of the previous window (``omega0`` in the first window), as preCICE
    does; ``|omega_k|`` is capped at `omega_max` when given.
    """

    name = "aitken"

    def __init__(self, omega0: float = 0.5, omega_max: float | None = None, weights=None, comm=None):
        super().__init__(weights, comm)
        if not (math.isfinite(omega0) and omega0 > 0):
            raise ValueError(f"Aitken: omega0 must be positive, not {omega0}")
        if omega_max is not None and not omega_max > 0:
            raise ValueError(f"Aitken: omega_max must be positive, not {omega_max}")
        self.omega0 = float(omega0)
        self.omega_max = None if omega_max is None else float(omega_max)
        self.omega = self.omega0  # the current factor omega_k
        self._r_prev: np.ndarray | None = None
        self.history: list[float] = []  # factors of the current window

    def start_window(self) -> None:
        super().start_window()
        self._r_prev = None
        self.history = []
        self.omega = math.copysign(min(self.omega0, abs(self.omega)), self.omega)

    def _cap(self, omega: float) -> float:
        if self.omega_max is not None and abs(omega) > self.omega_max:
            return math.copysign(self.omega_max, omega)
        return omega

    def update(self, x, Hx) -> np.ndarray:
        x, Hx = self._check(x, Hx)
        r = Hx - x
        if self._r_prev is not None:
            dr = r - self._r_prev
            local = np.array([inner(dr, dr, self.weights), inner(self._r_prev, dr, self.weights)])
            denom, numerator = map(float, self.rows.sum(local))  # one allreduce of 2 numbers
            if denom > 0 and math.isfinite(denom):
                self.omega = self._cap(-self.omega * numerator / denom)
            # dr = 0: the residual did not change, keep the factor
        else:
            self.omega = self._cap(self.omega)
        self._r_prev = r
        self.history.append(self.omega)
        self.iteration += 1
        return x + self.omega * r

    def end_window(self, x=None, Hx=None) -> None:
        super().end_window(x, Hx)
        self._r_prev = None

    def info(self) -> dict:
        return {"name": self.name, "omega0": self.omega0, "omega_max": self.omega_max, "omega": self.omega}

    def advice(self) -> str:
        return (f"use [coupling] acceleration = 'iqn-ils', or an initial relaxation below the present "
                f"{self.omega0:g}")


@dataclass
class FilteredQR:
    """A thin QR decomposition ``S V[:, kept] = Q R`` of the weighted columns kept by a filter.

    ``S = diag(sqrt(m))`` turns the M-inner product into the Euclidean one.
    """

    Q: np.ndarray  # (n, p), orthonormal columns
    R: np.ndarray  # (p, p), upper triangular
    kept: list[int]  # indices of the columns of V kept, in order
    removed: list[int]  # indices of the columns of V filtered out


def filtered_qr(V: np.ndarray, filter: str = "QR2", eps: float = 1e-8, weights=None, comm=None) -> FilteredQR:
    """QR decomposition of the columns of `V` with filtering of (nearly) linearly dependent ones.

    Columns are taken in order (for IQN-ILS the newest first, so that old
    information is dropped before new). Filters (Haelterman et al. 2016):

    - ``"QR1"``: after a QR decomposition, remove every column ``i`` with
      ``|R_ii| < eps * ||R||_F``, and repeat until none is removed.
    - ``"QR1-absolute"``: the same with ``|R_ii| < eps``.
    - ``"QR2"``: Gram-Schmidt, column by column (classical, with one
      re-orthogonalisation); a column is dropped when the part of it orthogonal
      to the columns kept so far is small relative to the column itself,
      ``||v_orth|| < eps * ||v||``.
    - ``"none"``: only exactly zero columns are removed.

    Zero columns are always removed. With `comm`, `V` and `weights` are this rank's rows:
    ``Q`` has them too, ``R`` is the same on every rank, and QR1's decomposition is the
    Gram-Schmidt one of QR2 without its filter (Householder's needs the whole columns).
    """
    V = np.asarray(V, dtype=float)
    if V.ndim != 2:
        raise ValueError("filtered_qr: V must be a 2-D array of columns")
    rows = RowSums(comm)
    n_local, m = V.shape
    w = as_weights(weights, n_local, comm)
    S = V if w is None else np.sqrt(w)[:, None] * V
    norms = rows.column_norms(S)
    n = rows.size(n_local)
    kept = [j for j in range(m) if norms[j] > 0 and math.isfinite(norms[j])]
    kind = filter.upper() if isinstance(filter, str) else filter
    if kind in ("QR1", "QR1-ABSOLUTE", "NONE", None):
        kept = kept[:n]  # more columns than dofs: the oldest are dependent
        while kept:
            if rows.distributed:
                Q, R, kept = _gram_schmidt(S, kept, norms, 0.0, len(kept), rows)
            else:
                Q, R = np.linalg.qr(S[:, kept], mode="reduced")
            if kind in ("NONE", None):
                break
            limit = eps if kind == "QR1-ABSOLUTE" else eps * np.linalg.norm(R)
            bad = np.abs(np.diag(R)) < limit
            if not np.any(bad):
                break
            kept = [j for j, b in zip(kept, bad) if not b]
        if not kept:
            Q, R = np.zeros((n_local, 0)), np.zeros((0, 0))
    elif kind == "QR2":
        Q, R, kept = _gram_schmidt(S, kept, norms, eps, min(len(kept), n), rows)
    else:
        raise ValueError(f"filtered_qr: filter must be 'QR1', 'QR1-absolute', 'QR2' or 'none', not {filter!r}")
    removed = sorted(set(range(m)) - set(kept))
    return FilteredQR(Q, R, list(kept), removed)


def _gram_schmidt(S: np.ndarray, columns: list[int], norms: np.ndarray, eps: float, most: int,
                  rows: RowSums) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Thin QR of ``S[:, columns]`` by classical Gram-Schmidt with one re-orthogonalisation
    (CGS2: twice is enough, Giraud et al. 2005), at most `most` columns; a column whose part
    orthogonal to the columns accepted so far is zero or below ``eps`` times its norm is
    skipped (QR2's filter). Each projection is one reduction of p numbers over `rows`."""
    Q = np.zeros((S.shape[0], most))
    R = np.zeros((most, most))
    accepted = []
    for j in columns:
        p = len(accepted)
        if p == most:
            break  # V already spans the whole space: the rest is dependent
        v = S[:, j].copy()
        h = np.zeros(p)
        for _ in range(2):
            if p:
                c = rows.column_dots(Q[:, :p], v)
                v -= Q[:, :p] @ c
                h += c
        rho = rows.norm(v)
        if rho < eps * norms[j] or rho == 0.0:
            continue
        Q[:, p] = v / rho
        R[:p, p] = h
        R[p, p] = rho
        accepted.append(j)
    p = len(accepted)
    return Q[:, :p], R[:p, :p], accepted


class IQNILS(Accelerator):
    """Interface quasi-Newton with an inverse Jacobian from least squares (IQN-ILS).

    Degroote, Bathe & Vierendeels 2009; the preCICE variant (Uekermann 2016) with
    QR filtering (Haelterman et al. 2016) and reuse of past time windows.

    Each iteration ``k`` of a window adds the differences to the previous iteration

        V = [dr_k, dr_{k-1}, ...],   dr_i = r_i - r_{i-1},   r_i = H(x_i) - x_i
        W = [dx~_k, dx~_{k-1}, ...], dx~_i = H(x_i) - H(x_{i-1})

    (newest first) to the columns kept from the last `reuse` windows. The inverse
    Jacobian of the residual is approximated from these secants: the
    combination of the columns that best cancels the current residual,

        alpha = argmin_a || V a + r_k ||_M,    (thin QR: R alpha = -Q^T S r_k)

    gives the update ``x_{k+1} = H(x_k) + W alpha``. Nearly dependent columns of
    ``V`` are filtered out of the least-squares problem (and dropped from ``V``
    and ``W``), see :func:`filtered_qr`. The first iteration of a window uses
    constant relaxation ``x_1 = x_0 + omega0 r_0`` unless columns from past
    windows are available. For a linear ``H`` on ``R^n`` (and no filtering of
    independent columns) the iterate after ``n + 1`` evaluations of ``H`` is the
    fixed point: IQN-ILS is then equivalent to GMRES on ``r(x) = 0`` (Haelterman
    et al., "Equivalence of QN-LS and GMRES ...", 2010).

    Parameters
    ----------
    omega0:
        relaxation factor of the first iteration of a window without past columns.
    reuse:
        number of past time windows whose columns are reused (0: start afresh
        each window).
    filter, filter_eps:
        the QR filter (``"QR1"``, ``"QR1-absolute"``, ``"QR2"``, ``"none"``) and its
        threshold. The default, QR2 with 1e-2, is the value of the preCICE
        tutorials: robust when ``H`` carries solver noise (inexact inner solves);
        a tighter threshold (1e-8 and below) keeps more columns and suits an
        ``H`` computed to rounding.
    max_columns:
        at most this many columns (the oldest are dropped; ``None``: no limit
        beyond the interface size). Memory: ``2 * max_columns`` interface
        vectors.
    weights:
        lumped mass per dof for the M-weighted least-squares problem.
    comm:
        with this rank's rows of x, H(x), the weights and the columns (see :class:`Accelerator`).
    """

    name = "iqn-ils"

    def __init__(self, omega0: float = 0.5, reuse: int = 0, filter: str = "QR2", filter_eps: float = 1e-2,
                 max_columns: int | None = 100, weights=None, comm=None):
        super().__init__(weights, comm)
        if not (math.isfinite(omega0) and omega0 > 0):
            raise ValueError(f"IQN-ILS: omega0 must be positive, not {omega0}")
        if int(reuse) != reuse or reuse < 0:
            raise ValueError(f"IQN-ILS: reuse must be a non-negative integer, not {reuse}")
        if not filter_eps >= 0:
            raise ValueError(f"IQN-ILS: filter_eps must be non-negative, not {filter_eps}")
        if max_columns is not None and max_columns < 1:
            raise ValueError(f"IQN-ILS: max_columns must be at least 1, not {max_columns}")
        filtered_qr(np.zeros((1, 0)), filter, filter_eps)  # validates the filter name
        self.omega0 = float(omega0)
        self.reuse = int(reuse)
        self.filter = filter
        self.filter_eps = float(filter_eps)
        self.max_columns = max_columns
        # columns, newest first: V (residual differences), W (output differences) and the window they came from
        self._V: list[np.ndarray] = []
        self._W: list[np.ndarray] = []
        self._origin: list[int] = []
        self._r_prev: np.ndarray | None = None
        self._Hx_prev: np.ndarray | None = None
        self.filtered_columns = 0  # columns removed by the filter, all windows
        self.used_columns = 0  # columns in the last least-squares problem
        self.last_alpha: np.ndarray | None = None

    @property
    def columns(self) -> int:
        """Number of stored secant columns."""
        return len(self._V)

    @property
    def V(self) -> np.ndarray:
        return np.column_stack(self._V) if self._V else np.zeros((0, 0))

    @property
    def W(self) -> np.ndarray:
        return np.column_stack(self._W) if self._W else np.zeros((0, 0))

    def start_window(self) -> None:
        super().start_window()
        self._r_prev = None
        self._Hx_prev = None

    def _add_secant(self, r: np.ndarray, Hx: np.ndarray) -> None:
        """Append the differences to the previous iteration of this window (newest first)."""
        reference = self._r_prev if self._r_prev is not None else (self._V[0] if self._V else None)
        if reference is not None and reference.size != r.size:
            raise ValueError(f"IQN-ILS: interface size changed from {reference.size} to {r.size}")
        if self._r_prev is not None:
            self._V.insert(0, r - self._r_prev)
            self._W.insert(0, Hx - self._Hx_prev)
            self._origin.insert(0, self.windows)
            limit = self.max_columns
            if limit is not None and len(self._V) > limit:
                del self._V[limit:], self._W[limit:], self._origin[limit:]
        self._r_prev = r
        self._Hx_prev = Hx.copy()

    def _drop(self, indices) -> None:
        for i in sorted(indices, reverse=True):
            del self._V[i], self._W[i], self._origin[i]

    def update(self, x, Hx) -> np.ndarray:
        x, Hx = self._check(x, Hx)
        r = Hx - x
        self._add_secant(r, Hx)
        self.iteration += 1
        if self._V:
            qr = filtered_qr(self.V, self.filter, self.filter_eps, self.weights, self.comm)
            if qr.removed:
                self.filtered_columns += len(qr.removed)
                self._drop(qr.removed)
            self.used_columns = len(qr.kept)
            if qr.kept:
                s = r if self.weights is None else np.sqrt(self.weights) * r
                alpha = solve_triangular(qr.R, -self.rows.column_dots(qr.Q, s), lower=False)
                self.last_alpha = alpha
                return Hx + self.W @ alpha
        self.used_columns = 0
        return x + self.omega0 * r

    def end_window(self, x=None, Hx=None) -> None:
        """Keep the secant of the converged iteration, then the columns of the last `reuse` windows only."""
        if x is not None and Hx is not None:
            x, Hx = self._check(x, Hx)
            self._add_secant(Hx - x, Hx)
        super().end_window(x, Hx)
        oldest = self.windows - self.reuse  # keep columns made in windows >= oldest
        keep = [i for i, o in enumerate(self._origin) if o >= oldest]
        self._V = [self._V[i] for i in keep]
        self._W = [self._W[i] for i in keep]
        self._origin = [self._origin[i] for i in keep]
        self._r_prev = None
        self._Hx_prev = None

    def advice(self) -> str:
        return (f"IQN-ILS is in use already: try a first relaxation below the present {self.omega0:g}, fewer "
                f"[coupling] columns (newest secants only; now {self.max_columns}), a shorter [time] dt (a better "
                f"first guess), or more [coupling] max_iterations; a residual that grows instead of stalling "
                f"points at the physics (a load the solid cannot carry, a fluid grid too coarse for the gap)")

    def info(self) -> dict:
        return {"name": self.name, "omega0": self.omega0, "reuse": self.reuse, "filter": self.filter,
                "filter_eps": self.filter_eps, "max_columns": self.max_columns, "columns": self.columns,
                "filtered_columns": self.filtered_columns}


#: Names accepted by :func:`make_accelerator` (the ``[coupling] acceleration`` key of a scene).
ACCELERATIONS = ("constant", "aitken", "iqn-ils")


def make_accelerator(name: str, relaxation: float = 0.5, reuse: int = 0, filter: str = "QR2",
                     filter_eps: float = 1e-2, omega_max: float | None = None,
                     max_columns: int | None = 100, weights=None, comm=None) -> Accelerator:
    """The accelerator a scene's ``[coupling]`` table asks for.

    `relaxation` is the constant factor (``constant``) or the initial one
    (``aitken``, ``iqn-ils``); `reuse`, `filter`, `filter_eps` and `max_columns`
    apply to IQN-ILS, `omega_max` to Aitken; `comm`: x holds this rank's rows (see
    :class:`Accelerator`).
    """
    key = name.lower().replace("_", "-")
    if key in ("constant", "relaxation", "constant-relaxation"):
        return ConstantRelaxation(relaxation, weights=weights, comm=comm)
    if key == "aitken":
        return Aitken(relaxation, omega_max, weights=weights, comm=comm)
    if key in ("iqn-ils", "iqnils", "iqn"):
        return IQNILS(relaxation, reuse, filter, filter_eps, max_columns, weights=weights, comm=comm)
    raise ValueError(f"unknown acceleration {name!r}: one of {', '.join(ACCELERATIONS)}")
