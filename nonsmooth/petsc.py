"""PETSc for the nonsmooth solvers: scipy -> PETSc conversion, CG + GAMG, and
the baseline solver, PETSc's SNES VI (reduced-space active set Newton,
``vinewtonrsls``) on a :class:`BoundConstrainedQP`.

SNES VI solves F(x) = A x - b = 0 subject to lower <= x <= upper, i.e. the
KKT system of the QP; each Newton step solves the system restricted to the
inactive set with CG + algebraic multigrid (BoomerAMG by default: GAMG fails
inside vinewtonrsls in PETSc 3.18, see :func:`solve_snes_vi`).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from .problem import BoundConstrainedQP, NonsmoothSolveError, Solution


def petsc_matrix(A: sp.csr_matrix, block_size: int = 1) -> PETSc.Mat:
    """A sequential AIJ matrix with the entries of a scipy CSR matrix."""
    A = sp.csr_matrix(A)
    A.sort_indices()
    M = PETSc.Mat().create(PETSc.COMM_SELF)
    M.setSizes(A.shape)
    M.setType("aij")
    if block_size > 1:
        M.setBlockSize(block_size)
    M.setPreallocationCSR((A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType)))
    M.setValuesCSR(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data)
    M.assemble()
    return M


def petsc_vector(values: np.ndarray) -> PETSc.Vec:
    """A sequential vector holding a copy of `values`."""
    return PETSc.Vec().createWithArray(np.array(values, dtype=PETSc.ScalarType), comm=PETSc.COMM_SELF)


def near_nullspace(Z: np.ndarray | None) -> PETSc.NullSpace | None:
    """An orthonormal PETSc near-nullspace from the columns of Z (e.g. rigid body modes)."""
    if Z is None:
        return None
    Q, R = np.linalg.qr(np.asarray(Z, float))
    d = np.abs(np.diag(R))
    Q = Q[:, d > 1e-12 * np.max(d, initial=0.0)]
    return PETSc.NullSpace().create(vectors=[petsc_vector(q) for q in Q.T], comm=PETSc.COMM_SELF)


def converged_reason(solver: PETSc.KSP | PETSc.SNES) -> str:
    """The name of a KSP's or SNES's converged reason (``"CONVERGED_RTOL"``, ``"DIVERGED_MAX_IT"``)."""
    reason = solver.getConvergedReason()
    names = {v: k for k, v in vars(type(solver).ConvergedReason).items() if not k.startswith("_")}
    return names.get(reason, str(reason))


#: algebraic multigrid preconditioners for :func:`configure_cg_amg`
AMG = ("gamg", "hypre")


def configure_cg_amg(ksp: PETSc.KSP, rtol: float, atol: float = 1e-50, max_it: int = 2000, amg: str = "gamg") -> None:
    """CG preconditioned by algebraic multigrid: ``"gamg"`` (smoothed aggregation,
    PETSc's defaults: Chebyshev/Jacobi smoothers; uses the near-nullspace) or
    ``"hypre"`` (BoomerAMG, classical AMG; ignores the near-nullspace)."""
    if amg not in AMG:
        raise ValueError(f"amg must be one of {AMG}, got {amg!r}")
    ksp.setType("cg")
    ksp.setTolerances(rtol=rtol, atol=atol, max_it=max_it)
    pc = ksp.getPC()
    if amg == "gamg":
        pc.setType("gamg")
        pc.setGAMGType("agg")
    else:
        pc.setType("hypre")
        pc.setHYPREType("boomeramg")


def petsc_bounds(qp: BoundConstrainedQP) -> tuple[PETSc.Vec, PETSc.Vec]:
    """The bounds with infinite entries replaced by -+PETSC_INFINITY (free for SNES VI)."""
    lower = np.where(np.isfinite(qp.lower), qp.lower, PETSc.NINFINITY)
    upper = np.where(np.isfinite(qp.upper), qp.upper, PETSc.INFINITY)
    return petsc_vector(lower), petsc_vector(upper)


def solve_snes_vi(qp: BoundConstrainedQP, x0: np.ndarray | None = None, *, rtol: float = 1e-12,
                  atol: float = 0.0, max_iter: int = 200, ksp_rtol: float = 1e-12,
                  amg: str = "hypre", monitor=None) -> Solution:
    """Solve the QP with SNES ``vinewtonrsls`` and CG + AMG on the inactive set.

    ``amg="hypre"`` (BoomerAMG) by default: GAMG inside vinewtonrsls fails in
    PETSc 3.18 at the second Newton step ("Cannot change local size of Amat
    after use", the inactive set changed size; KSPReset does not help).

    Converged when the residual norm on the inactive set falls below
    ``max(rtol * |F(x0)|, atol)`` (PETSc's test), or the step is below 1e-14
    relative. ``iterations`` are Newton steps, ``krylov_iterations`` their CG iterations;
    the criterion reported is that norm relative to ``|F(x0)|`` against
    ``max(rtol, atol / |F(x0)|)``. Any PETSc divergence (iteration limit, line search)
    returns the last iterate unconverged with PETSc's reason; only NaN raises.
    """
    start = time.perf_counter()
    n = qp.size
    A = petsc_matrix(qp.A, qp.block_size)
    nns = near_nullspace(qp.near_nullspace)
    if nns is not None:
        A.setNearNullSpace(nns)
    b = petsc_vector(qp.b)
    x = petsc_vector(qp.project(np.zeros(n) if x0 is None else np.asarray(x0, float)))
    f = x.duplicate()

    def residual(snes, xv, fv):
        A.mult(xv, fv)
        fv.axpy(-1.0, b)

    norms: list[float] = []
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    snes.setType("vinewtonrsls")
    snes.setFunction(residual, f)
    snes.setJacobian(lambda snes, xv, J, P: None, A, A)
    snes.setVariableBounds(*petsc_bounds(qp))
    snes.setTolerances(rtol=rtol, atol=atol, stol=1e-14, max_it=max_iter)
    # PETSc's default backtracking line search: with full steps ("basic") vinewtonrsls cycles on
    # SPD problems that are not M-matrices (tests/test_nonsmooth_active_set.py, CYCLING_A)
    def heard(snes, it, norm):
        norms.append(float(norm))
        if monitor is not None:  # a caller's progress lines (nonsmooth.solvers.solve)
            monitor(newton_iteration=it, residual=float(norm))

    snes.setMonitor(heard)
    configure_cg_amg(snes.getKSP(), ksp_rtol, amg=amg)
    snes.solve(None, x)
    reason = snes.getConvergedReason()
    name = converged_reason(snes)
    xs = x.getArray().copy()
    iterations, krylov = snes.getIterationNumber(), snes.getLinearSolveIterations()
    for obj in (snes, A, b, x, f):
        obj.destroy()
    if reason == PETSc.SNES.ConvergedReason.DIVERGED_FNORM_NAN or not np.all(np.isfinite(xs)):
        raise NonsmoothSolveError(f"SNES VI (vinewtonrsls): NaN after {iterations} Newton steps ({name})")
    initial = norms[0] if norms else 0.0
    return Solution(x=xs, iterations=iterations, converged=reason > 0, solver="snes_vi",
                    seconds=time.perf_counter() - start, krylov_iterations=krylov,
                    history=norms[1:] if len(norms) > 1 else norms,
                    active=(xs <= qp.lower) | (xs >= qp.upper),
                    info={"petsc_reason": int(reason), "kkt_residual": qp.kkt_residual(xs)},
                    residual=norms[-1] / initial if initial > 0 else 0.0,
                    tolerance=max(rtol, atol / initial) if initial > 0 else rtol,
                    reason="iteration limit" if reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT else name)
