"""PETSc for the steady Newton solve (:mod:`fluid_chorin.steady`) on one process, for the blocks
of its preconditioner (:class:`fluid_chorin.steady.Block`): the sparse LU factorization of a
scipy matrix (nested-dissection ordering, no pivoting: the blocks are diagonally dominant or
Laplacian-like) or one V-cycle of hypre's BoomerAMG; and GMRES preconditioned by a Python
function."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def has_multigrid() -> bool:
    """Whether this PETSc has hypre (BoomerAMG)."""
    from petsc4py import PETSc

    return bool(PETSc.Sys.hasExternalPackage("hypre"))


def _matrix(M: sp.spmatrix):
    from petsc4py import PETSc

    M = sp.csr_matrix(M)
    M.sort_indices()
    out = PETSc.Mat().createAIJ(size=M.shape, csr=(M.indptr.astype(PETSc.IntType), M.indices.astype(PETSc.IntType),
                                                   M.data), comm=PETSc.COMM_SELF)
    out.assemble()
    return out


class Factor:
    """An inverse of the square matrix ``M``: its LU factors, or (``multigrid``) one V-cycle of
    BoomerAMG; :meth:`solve` applies it."""

    def __init__(self, M: sp.spmatrix, multigrid: bool = False):
        from petsc4py import PETSc

        self.M = _matrix(M)
        self.ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
        self.ksp.setOperators(self.M)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        if multigrid:
            pc.setType("hypre")
            pc.setHYPREType("boomeramg")
        else:
            pc.setType("lu")
            pc.setFactorOrdering("nd")
        self.ksp.setUp()
        self.x, self.b = self.M.createVecs()

    def solve(self, r: np.ndarray) -> np.ndarray:
        self.b.array[:] = r
        self.ksp.solve(self.b, self.x)
        return self.x.array.copy()

    def destroy(self) -> None:
        for obj in (self.ksp, self.M, self.x, self.b):
            obj.destroy()


class _Shell:
    """A PETSc Python preconditioner applying ``apply`` (ndarray to ndarray)."""

    def __init__(self, apply):
        self.apply_ = apply

    def apply(self, pc, x, y) -> None:
        y.array[:] = self.apply_(x.array_r)


def gmres(J: sp.spmatrix, b: np.ndarray, apply, rtol: float, atol: float, iterations: int) -> tuple[np.ndarray, int]:
    """``J x = b`` by GMRES from zero, right-preconditioned by ``apply`` (so its residual is the
    true one), to ``|r| <= max(rtol |b|, atol)`` in at most ``iterations`` (no restart):
    the solution and the iterations made."""
    from petsc4py import PETSc

    M = _matrix(J)
    ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
    ksp.setOperators(M)
    ksp.setType("gmres")
    ksp.setGMRESRestart(iterations)
    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonContext(_Shell(apply))
    ksp.setPCSide(PETSc.PC.Side.RIGHT)
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=rtol, atol=atol, max_it=iterations)
    x, rhs = M.createVecs()
    rhs.array[:] = b
    x.set(0.0)
    ksp.solve(rhs, x)
    out, count = x.array.copy(), ksp.getIterationNumber()
    for obj in (ksp, M, x, rhs):
        obj.destroy()
    return out, count
