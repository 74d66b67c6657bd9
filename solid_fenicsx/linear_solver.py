"""PETSc linear solvers for the elasticity systems: CG + GAMG with rigid body
modes as near-nullspace (the default), or a direct LU factorisation (MUMPS).

:func:`solve` tells how a solve ended (:class:`LinearSolve`) instead of raising when
the Krylov method stops short: the caller reports it (the coupler decides what the run
may claim); it raises only when the solution is unusable (NaN, a breakdown)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc

import dolfinx
import dolfinx.la
from nonsmooth.petsc import converged_reason

from .settings import LINEAR_SOLVERS


@dataclass
class SolverOptions:
    """Linear solver settings.

    kind : ``"cg"`` (CG preconditioned by smoothed-aggregation GAMG with the
        rigid body modes as near-nullspace) or ``"lu"`` (direct, MUMPS)
    rtol, atol, max_it : Krylov stopping criteria (unpreconditioned residual is not
        used: PETSc's default preconditioned norm for CG)
    petsc_options : extra PETSc options (without prefix) applied last
    """

    kind: str = "cg"
    rtol: float = 1e-10
    atol: float = 1e-50
    max_it: int = 1000
    petsc_options: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.kind not in LINEAR_SOLVERS:
            raise ValueError(f"linear solver must be one of {', '.join(map(repr, LINEAR_SOLVERS))}, "
                             f"got {self.kind!r}")


class LinearSolveError(RuntimeError):
    """A linear solve without a usable solution (NaN or inf, a Krylov breakdown)."""


@dataclass
class LinearSolve:
    """How one linear solve ended.

    solver : ``"CG+GAMG"``, ``"LU"``, ... (KSP and PC types)
    what : the system (``"static"``, ``"time step"``, ``"initial acceleration"``)
    residual : the final residual relative to the norm PETSc's stopping test divides by (the
        initial residual, or with a nonzero initial guess the right side), in the test's norm
        (CG: the preconditioned norm); direct solves: ``||A x - b|| / ||b||``
    tolerance : the relative residual the Krylov method had to reach (``max(rtol, atol / r0)``;
        direct solves: ``rtol`` of the options)
    reason : PETSc's converged reason (``"CONVERGED_RTOL"``, ``"DIVERGED_MAX_IT"``)
    """

    solver: str
    what: str
    converged: bool
    iterations: int
    residual: float
    tolerance: float
    reason: str


def rigid_body_modes(V) -> PETSc.NullSpace:
    """The six rigid body modes (3 translations, 3 rotations) of a vector
    Lagrange space, orthonormalised: the near-nullspace GAMG needs for elasticity."""
    index_map = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    n_local = index_map.size_local
    x = V.tabulate_dof_coordinates()[:n_local]
    vecs = [dolfinx.la.create_petsc_vector(index_map, bs) for _ in range(6)]
    arrays = [v.getArray() for v in vecs]  # views of the owned part
    for d in range(3):
        arrays[d][d::3] = 1.0
    arrays[3][0::3], arrays[3][1::3] = -x[:, 1], x[:, 0]
    arrays[4][0::3], arrays[4][2::3] = x[:, 2], -x[:, 0]
    arrays[5][1::3], arrays[5][2::3] = -x[:, 2], x[:, 1]
    for v in vecs:
        v.assemble()
    dolfinx.la.orthonormalize(vecs)
    return PETSc.NullSpace().create(vectors=vecs, comm=V.mesh.comm)


_counter = iter(range(1 << 30))


def make_ksp(A: PETSc.Mat, options: SolverOptions, V=None, symmetric: bool = True) -> PETSc.KSP:
    """A KSP for the operator ``A`` (its preconditioner is built once, at the
    first solve, and reused while ``A`` does not change)."""
    comm = A.getComm()
    ksp = PETSc.KSP().create(comm)
    prefix = f"solid_{next(_counter)}_"
    ksp.setOptionsPrefix(prefix)
    opts = PETSc.Options()
    if options.kind == "lu":
        opts[prefix + "ksp_type"] = "preonly"
        opts[prefix + "pc_type"] = "lu"
        if PETSc.Sys.hasExternalPackage("mumps"):
            opts[prefix + "pc_factor_mat_solver_type"] = "mumps"
    else:
        if V is not None:
            A.setNearNullSpace(rigid_body_modes(V))
        opts[prefix + "ksp_type"] = "cg" if symmetric else "gmres"
        opts[prefix + "pc_type"] = "gamg"
        opts[prefix + "pc_gamg_type"] = "agg"
        opts[prefix + "pc_gamg_agg_nsmooths"] = 1
        opts[prefix + "pc_gamg_threshold"] = 0.0  # measured: fastest set-up + solve on graded crack meshes
        opts[prefix + "mg_levels_ksp_type"] = "chebyshev"
        opts[prefix + "mg_levels_pc_type"] = "jacobi"
        opts[prefix + "ksp_rtol"] = options.rtol
        opts[prefix + "ksp_atol"] = options.atol
        opts[prefix + "ksp_max_it"] = options.max_it
    for key, value in options.petsc_options.items():
        opts[prefix + key] = value
    ksp.setOperators(A)
    ksp.setFromOptions()
    if options.kind == "lu":  # preonly reads no tolerance options; its residual is reported against rtol
        ksp.setTolerances(rtol=options.rtol)
    # the options belong to this KSP only: drop them from the global database
    for key in list(opts.getAll()):
        if key.startswith(prefix):
            opts.delValue(key)
    return ksp


def _method(ksp: PETSc.KSP) -> str:
    """``"CG+GAMG"``, ``"CG+JACOBI"``, ``"LU"``: the KSP and PC types (a direct solve by its PC alone)."""
    pc = ksp.getPC().getType().upper()
    return pc if ksp.getType() == "preonly" else f"{ksp.getType().upper()}+{pc}"


#: negative PETSc reasons that leave a finite iterate (reported unconverged); the others raise
_REPORTED = (PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT, PETSc.KSP.ConvergedReason.DIVERGED_DTOL)


def _reference_norm(ksp: PETSc.KSP, b: PETSc.Vec) -> float:
    """The norm PETSc's default test divides by: the initial residual's for a zero initial
    guess, else the right side's (``||B b||`` in the preconditioned norm), as KSPConvergedDefault."""
    if not ksp.getInitialGuessNonzero():
        norms = ksp.getConvergenceHistory()
        return float(norms[0]) if len(norms) else 0.0
    if ksp.getNormType() != PETSc.KSP.NormType.PRECONDITIONED:
        return b.norm()
    z = b.duplicate()
    ksp.getPC().apply(b, z)
    norm = z.norm()
    z.destroy()
    return norm


def solve(ksp: PETSc.KSP, b: PETSc.Vec, x: PETSc.Vec, what: str) -> LinearSolve:
    """Solve ``A x = b`` and tell how it ended (an iteration limit or a divergence is
    reported, not raised); :class:`LinearSolveError` naming `what` only when ``x`` is
    unusable (NaN or inf, a breakdown, an indefinite matrix, a failed preconditioner)."""
    ksp.setConvergenceHistory(reset=True)
    ksp.solve(b, x)
    reason, name = ksp.getConvergedReason(), converged_reason(ksp)
    iterations = ksp.getIterationNumber()
    if not np.isfinite(x.norm()) or (reason < 0 and reason not in _REPORTED):
        raise LinearSolveError(f"{what}: {_method(ksp)} failed ({name}) after {iterations} iterations, "
                               f"the solution is not usable")
    x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    rtol, atol, _, _ = ksp.getTolerances()
    if ksp.getType() == "preonly":  # direct: the true relative residual
        r = b.duplicate()
        ksp.getOperators()[0].mult(x, r)
        r.axpy(-1.0, b)
        b_norm, residual = b.norm(), r.norm()
        r.destroy()
        return LinearSolve(_method(ksp), what, True, 1, residual / b_norm if b_norm > 0 else 0.0, rtol, name)
    r0 = _reference_norm(ksp, b)
    return LinearSolve(_method(ksp), what, reason > 0, iterations,
                       ksp.getResidualNorm() / r0 if r0 > 0 else 0.0, max(rtol, atol / r0) if r0 > 0 else rtol, name)


def mass_ksp(M: PETSc.Mat, options: SolverOptions) -> PETSc.KSP:
    """A solver for a mass matrix: CG + Jacobi (well conditioned), or LU."""
    if options.kind == "lu":
        return make_ksp(M, options)
    ksp = PETSc.KSP().create(M.getComm())
    ksp.setType("cg")
    ksp.getPC().setType("jacobi")
    ksp.setTolerances(rtol=min(options.rtol, 1e-12), atol=options.atol, max_it=max(options.max_it, 2000))
    ksp.setOperators(M)
    return ksp

