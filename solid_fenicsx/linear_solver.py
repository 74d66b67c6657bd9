"""PETSc linear solvers for the elasticity systems: CG + GAMG with rigid body
modes as near-nullspace (the default), or a direct LU factorisation (MUMPS)."""

from __future__ import annotations

from dataclasses import dataclass, field

from petsc4py import PETSc

import dolfinx
import dolfinx.la


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
        if self.kind not in ("cg", "lu"):
            raise ValueError(f"linear solver must be 'cg' or 'lu', got {self.kind!r}")


class LinearSolveError(RuntimeError):
    """The Krylov solver did not converge."""


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
    # the options belong to this KSP only: drop them from the global database
    for key in list(opts.getAll()):
        if key.startswith(prefix):
            opts.delValue(key)
    return ksp


def solve(ksp: PETSc.KSP, b: PETSc.Vec, x: PETSc.Vec, what: str = "solve") -> int:
    """Solve, raising :class:`LinearSolveError` with PETSc's reason on divergence;
    returns the number of iterations."""
    ksp.solve(b, x)
    reason = ksp.getConvergedReason()
    if reason < 0:
        raise LinearSolveError(f"{what}: linear solver diverged (PETSc reason {reason}) after "
                               f"{ksp.getIterationNumber()} iterations, residual {ksp.getResidualNorm():.3e}")
    x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    return ksp.getIterationNumber()


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

