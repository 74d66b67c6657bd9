"""Primal-dual active set method (Hintermueller, Ito and Kunisch 2002) for a
:class:`BoundConstrainedQP`: the semismooth Newton method on the KKT system of
paper eq. 10-11 written as ``x = P(x + c lam)``, ``lam = b - A x``.

Each iteration predicts the active sets from ``y = x + lam / diag(A)``::

    U = {y > upper},   L = {y < lower},   I = the rest

and solves the equality-constrained problem ``x_U = upper_U``, ``x_L = lower_L``,
``(A x)_I = b_I`` with CG + GAMG (the active rows and columns replaced by their
diagonal, which keeps the block structure and the near-nullspace usable for
AMG; the AMG is set up once, on the first iteration's system, and preconditions the
later ones, whose operators differ from it only in the rows and columns whose set
changed). It stops when the sets repeat (the exact PDAS criterion: the last solve
then satisfies all KKT conditions up to the Krylov tolerance) or when the
scaled natural residual ``max |x - P(x + lam / diag(A))|``, relative to
``max(|x|, |finite bounds|)``, falls below ``tol``: that relative residual is the
criterion :class:`Solution` reports.

Anti-chattering: when a set seen earlier returns (a cycle), the method
switches to a monotone mode in which a constraint leaves the active set only
when no inactive component violates its bound, and then only the half with
the most negative multiplier. If that also fails within ``max_iter``, or an
inner CG reaches its iteration limit, the last iterate is returned unconverged
(``reason`` with the set changes of the last iterations); it raises
:class:`NonsmoothSolveError` only for a matrix that is not SPD, NaN, or a Krylov
breakdown.

The same iteration runs on a :class:`~nonsmooth.distributed.DistributedQP` (MPI AIJ
matrices): the sets and iterates are then local parts, every decision (residual, set
changes, cycles, the monotone mode's worst half) is taken on values reduced over the
communicator, so all ranks stop together, and the inner CG + GAMG is distributed.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from .distributed import DistributedQP
from .petsc import configure_cg_amg, converged_reason, near_nullspace, petsc_matrix, petsc_vector
from .problem import BoundConstrainedQP, Control, NonsmoothSolveError, Solution

log = logging.getLogger("varcouple.nonsmooth")

#: a long solve logs its progress when this many seconds have passed since its last line, checked
#: after each iteration (so a line comes at least every 10 s while iterations take under 5 s): the
#: line is also the participant's progress, which keeps the coupler's [messaging] timeout from
#: cutting it off (docs/protocol.md)
PROGRESS_SECONDS = 5.0


def _fixed_system(A: sp.csr_matrix, b: np.ndarray, diag: np.ndarray, active: np.ndarray, value: np.ndarray):
    """The system with x[active] = value[active]: active rows and columns
    replaced by their diagonal, the known values moved to the right side."""
    keep = (~active).astype(float)
    K = sp.diags(keep) @ A @ sp.diags(keep) + sp.diags(np.where(active, diag, 0.0))
    xa = np.where(active, value, 0.0)
    rhs = np.where(active, diag * xa, b - A @ xa)
    return sp.csr_matrix(K), rhs


class _Serial:
    """The serial QP's algebra for the solver: scipy products, sequential PETSc inner
    systems (a :class:`~nonsmooth.distributed.DistributedQP` provides the same methods)."""

    comm = MPI.COMM_SELF

    def __init__(self, qp: BoundConstrainedQP):
        self.qp = qp

    def diagonal(self) -> np.ndarray:
        return self.qp.A.diagonal()

    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.qp.b)) and np.all(np.isfinite(self.qp.A.data)))

    def fixed_system(self, active, value, diag) -> tuple[PETSc.Mat, PETSc.Vec]:
        K, rhs = _fixed_system(self.qp.A, self.qp.b, diag, active, value)
        return petsc_matrix(K, self.qp.block_size), petsc_vector(rhs)

    def product(self, x: np.ndarray) -> np.ndarray:
        return self.qp.A @ x

    def shift(self, rhs: np.ndarray) -> None:
        """b += rhs."""
        self.qp.b += rhs

    @staticmethod
    def vector(values) -> PETSc.Vec:
        return petsc_vector(values)


class _Sets:
    """The active sets as one int8 array: -1 at lower, +1 at upper, 0 inactive (the local
    part on several ranks; the worst half of :meth:`monotone` is chosen over all ranks)."""

    @staticmethod
    def predict(qp, x, lam, dinv, tol):
        y = x + lam * dinv
        s = np.zeros(len(x), np.int8)
        s[y > qp.upper + tol] = 1
        s[y < qp.lower - tol] = -1
        s[qp.lower == qp.upper] = 1  # fixed components are always at their bound
        return s

    @staticmethod
    def monotone(qp, s, x, lam, dinv, tol, comm):
        """Add every violated bound; drop wrong-sign multipliers only when
        nothing is violated, the worst half of them."""
        new = s.copy()
        free = s == 0
        new[free & (x > qp.upper + tol)] = 1
        new[free & (x < qp.lower - tol)] = -1
        if comm.allreduce(bool(np.any(new != s)), op=MPI.LOR):
            return new
        wrong = np.flatnonzero(((s == 1) & (lam * dinv < -tol)) | ((s == -1) & (lam * dinv > tol)))
        wrong = wrong[qp.lower[wrong] != qp.upper[wrong]]
        size = np.abs(lam[wrong] * dinv[wrong])
        sizes = comm.allgather(size) if comm.size > 1 else [size]
        everywhere = np.concatenate(sizes)
        if everywhere.size:
            chosen = np.argsort(-everywhere)[: max(1, everywhere.size // 2)] - sum(len(v) for v in sizes[:comm.rank])
            new[wrong[chosen[(chosen >= 0) & (chosen < len(wrong))]]] = 0
        return new


class _SetHistory:
    """The active sets of every iteration: a set seen before (a cycle) is one that every
    rank's local part has seen at the same iteration."""

    def __init__(self, comm):
        self.comm, self.keys = comm, []

    def add(self, sets: np.ndarray) -> None:
        self.keys.append(sets.tobytes())

    def __contains__(self, sets: np.ndarray) -> bool:
        key = sets.tobytes()
        same = np.array([k == key for k in self.keys], np.int8)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, same, op=MPI.MIN)
        return bool(same.any())


def _controlled(algebra, qp, control: Control, ksp, sets, diag, bound, x):
    """The Newton step of a :class:`Control` on the system of the current `sets`: its response
    to a unit of c solved with the same operator and preconditioner, c moved so that the
    response reaches the target (exact for these sets: the system is linear in c); `qp` and
    the fixed values `bound` moved with it. Returns x, the change of c and the Krylov iterations."""
    comm = algebra.comm
    unit = np.where(sets != 0, control.bounds, 0.0)
    rhs = algebra.vector(np.where(sets != 0, diag * unit, control.rhs - algebra.product(unit)))
    xv = algebra.vector(unit)
    ksp.solve(rhs, xv)
    dx = xv.getArray().copy()
    dx[sets != 0] = unit[sets != 0]
    its = ksp.getIterationNumber()
    for v in (rhs, xv):
        v.destroy()
    value, slope = comm.allreduce(np.array([np.dot(control.response, x), np.dot(control.response, dx)]), op=MPI.SUM)
    if not abs(slope) > 1e-6 * abs(control.slope):  # no stiffness against c in these sets (the faces apart)
        slope = control.slope
    step = (control.target - value) / slope
    algebra.shift(step * control.rhs)
    qp.lower += step * control.bounds
    qp.upper += step * control.bounds
    bound += step * control.bounds
    return x + step * dx, step, its


def solve_active_set(qp: BoundConstrainedQP | DistributedQP, x0: np.ndarray | None = None, *, tol: float = 1e-10,
                     max_iter: int = 100, ksp_rtol: float = 1e-12, ksp_max_it: int = 2000,
                     amg: str = "gamg", amg_reuse: bool = True, monitor=None,
                     control: Control | None = None) -> Solution:
    """Solve the QP by the primal-dual active set method with CG + GAMG inner solves.

    qp : serial (scipy) or distributed (:class:`~nonsmooth.distributed.DistributedQP`: ``x0``
        and the returned ``x`` and ``active`` are then the local parts)
    amg : ``"gamg"`` (with the near-nullspace) or ``"hypre"``, see :func:`nonsmooth.petsc.configure_cg_amg`
    tol : on the natural residual scaled by diag(A), relative to max(|x|, |finite bounds|)
    x0 : start (e.g. the previous load step); projected onto the bounds. The first active
        sets are predicted from it (``x0 + lam / diag(A)`` against the bounds): at the
        previous solution with the previous loads they are its active sets, with changed
        loads those sets moved by the change of the multiplier (a warm start of both).
    amg_reuse : set the AMG up once, on the first iteration's system, and precondition the
        later ones with it (their operators differ only in the rows and columns of the
        components whose set changed; the near null space is the same), each CG still to
        ``ksp_rtol``; False sets it up anew at every iteration
    monitor : called as ``monitor(**values)`` after every active-set iteration
        (``active_set_iteration``, ``residual``, ``cg_iterations`` so far) and every CG iteration
        (``cg_iteration``, ``cg_residual``): a caller's progress lines; without one, a log line
        every ``PROGRESS_SECONDS`` on rank 0
    control : one more unknown (:class:`~nonsmooth.problem.Control`): after each iteration's
        solve, a second with the same operator gives the response to it, and a Newton step
        sets it so that the response reaches its target for those sets (exactly, when the sets
        repeat); ``qp`` keeps its last value, ``info["control"]`` the change over the solve
    ``iterations`` counts active-set iterations (one linear solve each, two with a control),
    ``history`` the relative scaled natural residual after each, ``info["changes"]``
    the number of components whose set changed before each solve, ``info["amg_setups"]``
    and ``info["amg_setup_seconds"]`` the AMG set-ups and their time.
    """
    start = time.perf_counter()
    algebra = qp if isinstance(qp, DistributedQP) else _Serial(qp)
    comm = algebra.comm
    diag = algebra.diagonal()
    nonpositive = comm.allreduce(int(np.sum(diag <= 0)))
    if nonpositive:
        raise NonsmoothSolveError(f"A has {nonpositive} non-positive diagonal entries: not SPD")
    dinv = 1.0 / diag
    if not algebra.finite():
        raise NonsmoothSolveError("the problem contains NaN or inf")
    finite = np.concatenate([qp.lower[np.isfinite(qp.lower)], qp.upper[np.isfinite(qp.upper)]])
    bound_scale = comm.allreduce(float(np.max(np.abs(finite), initial=0.0)), op=MPI.MAX)
    x = qp.project(np.zeros(len(qp.lower)) if x0 is None else np.asarray(x0, float).copy())
    bound = np.where(qp.lower == qp.upper, qp.lower, 0.0)

    def scale(x):
        return max(comm.allreduce(float(np.max(np.abs(x), initial=0.0)), op=MPI.MAX), bound_scale,
                   np.finfo(float).tiny)

    nns = near_nullspace(qp.near_nullspace)
    ksp = PETSc.KSP().create(comm)
    configure_cg_amg(ksp, ksp_rtol, max_it=ksp_max_it, amg=amg)
    ksp.setInitialGuessNonzero(True)
    if monitor is not None:
        ksp.setMonitor(lambda _, k, rnorm: monitor(cg_iteration=k, cg_residual=float(rnorm)))
    preconditioner, setups, setup_seconds, moved = None, 0, 0.0, 0.0

    lam = qp.multiplier(x)
    sets = _Sets.predict(qp, x, lam, dinv, tol * scale(x))
    seen = _SetHistory(comm)
    seen.add(sets)
    history, changes, krylov = [], [], 0
    monotone_from, converged, reason = None, False, ""
    shown = time.monotonic()
    try:
        for it in range(1, max_iter + 1):
            value = np.where(sets == 1, qp.upper, np.where(sets == -1, qp.lower, bound))
            M, bv = algebra.fixed_system(sets != 0, value, diag)
            if nns is not None:
                M.setNearNullSpace(nns)
            if preconditioner is None or not amg_reuse:  # a new AMG on this system
                ksp.setOperators(M)
                t_setup = time.perf_counter()
                ksp.setUp()
                setup_seconds += time.perf_counter() - t_setup
                setups += 1
                if amg_reuse:
                    preconditioner = M
            else:  # this system preconditioned by the first one's AMG, set up once
                ksp.setOperators(M, preconditioner)
            xv = algebra.vector(np.where(sets != 0, value, x))
            ksp.solve(bv, xv)
            inner = ksp.getConvergedReason()
            krylov += ksp.getIterationNumber()
            if inner < 0 and inner != PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT:
                raise NonsmoothSolveError(f"active set iteration {it}: CG + {amg.upper()} failed "
                                          f"({converged_reason(ksp)}) after {ksp.getIterationNumber()} iterations")
            x = xv.getArray().copy()
            x[sets != 0] = value[sets != 0]  # exact (a reused AMG couples the active rows to CG's tolerance)
            if control is not None and inner >= 0:
                x, step, its = _controlled(algebra, qp, control, ksp, sets, diag, bound, x)
                moved += step
                krylov += its
            for obj in (xv, bv) if M is preconditioner else (M, xv, bv):
                obj.destroy()
            if not comm.allreduce(bool(np.all(np.isfinite(x))), op=MPI.LAND):
                raise NonsmoothSolveError(f"active set iteration {it}: the linear solve returned NaN/inf")
            lam = qp.multiplier(x)
            lam[sets == 0] = 0.0  # zero up to the Krylov tolerance
            residual = comm.allreduce(float(np.max(np.abs(x - qp.project(x + lam * dinv)), initial=0.0)), op=MPI.MAX)
            history.append(residual / scale(x))
            tol_abs = tol * scale(x)
            if monitor is not None:  # the caller shows the progress (the solid: platen trial, iterations)
                monitor(active_set_iteration=it, residual=history[-1], cg_iterations=krylov)
            elif comm.rank == 0 and time.monotonic() - shown >= PROGRESS_SECONDS:  # a long solve shows it moves
                shown = time.monotonic()
                log.info("active set iteration %d: residual %.3g (tolerance %g), %d Krylov iterations so far", it,
                         history[-1], tol, krylov)
            if inner < 0:
                reason = (f"the inner CG + {amg.upper()} reached its {ksp_max_it} iterations at active set "
                          f"iteration {it}")
                break
            if monotone_from is None:
                new = _Sets.predict(qp, x, lam, dinv, tol_abs)
            else:
                new = _Sets.monotone(qp, sets, x, lam, dinv, tol_abs, comm)
            changes.append(comm.allreduce(int(np.count_nonzero(new != sets))))
            if changes[-1] == 0 or history[-1] <= tol:
                converged, reason = True, "active sets repeat" if changes[-1] == 0 else "criterion below the tolerance"
                break
            if new in seen and monotone_from is None:
                monotone_from = it  # a cycle: the sets of an earlier iteration came back
                new = _Sets.monotone(qp, sets, x, lam, dinv, tol_abs, comm)
            seen.add(new)
            sets = new
        else:
            reason = (f"iteration limit; set changes in the last iterations {changes[-5:]}"
                      f"{'' if monotone_from is None else f'; cycling detected at iteration {monotone_from}'}")
    finally:
        ksp.destroy()
        if preconditioner is not None:
            preconditioner.destroy()
    return Solution(x=x, iterations=len(history), converged=converged, solver="active_set",
                    seconds=time.perf_counter() - start, krylov_iterations=krylov, history=history,
                    active=sets != 0,
                    info={"changes": changes, "monotone_from": monotone_from, "kkt_residual": qp.kkt_residual(x),
                          "amg_setups": setups, "amg_setup_seconds": setup_seconds,
                          **({"control": moved} if control is not None else {})},
                    residual=history[-1] if history else float("nan"), tolerance=tol, reason=reason)
