"""The pressure Poisson equation of the projection, ``-div(beta grad phi) = s - div u*``, on the
cells of the staggered grid, solved by PETSc's conjugate gradients preconditioned with
algebraic multigrid (GAMG).

``beta`` lives on the faces: ``1 / (1/dt + D)`` with the penalization drag ``D`` of the face,
the same factor that multiplies the pressure gradient in the predictor, so the corrected
velocity ``u* - beta grad phi`` is discretely divergence free (up to the source ``s``) also
where the solid is penalized. The matrix is the 7-point stencil ``beta_f / h^2`` per interior
face and ``2 beta_f / h^2`` on the diagonal behind a fixed-pressure face (``phi = 0`` half a
cell out); without such a face it is singular (constants), and the solve is in the space
of zero-mean fields.

Methods: ``"gamg"``, conjugate gradients preconditioned by PETSc's algebraic multigrid to a
relative residual ``rtol``; ``"direct"``, PETSc's sparse Cholesky factorization (nested
dissection ordering; one cell pinned when singular), cheaper per solve on small grids, where
multigrid's fixed cost per cycle dominates; ``"auto"`` takes the direct one up to
:data:`DIRECT_CELLS` cells. Either is set up once per matrix (a new ``dt`` or solid) and
reused for every solve with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .staggered import AXIS, Staggered, along

#: ``"auto"`` factorizes up to this many cells and uses multigrid beyond
DIRECT_CELLS = 30000


#: the relative residual a factorization's solve must reach (it is rounding error, else a bad matrix)
DIRECT_TOLERANCE = 1e-8


@dataclass
class PoissonReport:
    iterations: int
    residual: float  # final residual norm relative to the right-hand side's
    converged: bool
    tolerance: float
    method: str  # "CG + GAMG" or "Cholesky"


class PressurePoisson:
    def __init__(self, grid: Staggered, beta: list[np.ndarray], method: str = "auto", rtol: float = 1e-10,
                 max_iterations: int = 500):
        from petsc4py import PETSc

        self.grid, self.rtol = grid, rtol
        matrix = assemble(grid, beta)
        n = matrix.shape[0]
        self.singular = not grid.pressure_faces
        self.method = ("direct" if n <= DIRECT_CELLS else "gamg") if method == "auto" else method
        if self.method == "direct" and self.singular:  # pin cell 0 (the solution is shifted to zero mean)
            keep = sp.diags(np.r_[0.0, np.ones(n - 1)])
            matrix = (keep @ matrix @ keep + sp.diags(np.r_[1.0, np.zeros(n - 1)])).tocsr()
        matrix.sort_indices()
        A = PETSc.Mat().createAIJ(size=(n, n), csr=(matrix.indptr.astype(PETSc.IntType),
                                                    matrix.indices.astype(PETSc.IntType), matrix.data),
                                  comm=PETSc.COMM_SELF)
        A.assemble()
        ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
        ksp.setOperators(A)
        if self.method == "direct":
            ksp.setType("preonly")
            pc = ksp.getPC()
            pc.setType("cholesky")
            pc.setFactorOrdering("nd")
        else:
            if self.singular:
                A.setNullSpace(PETSc.NullSpace().create(constant=True, comm=PETSc.COMM_SELF))
            ksp.setType("cg")
            ksp.getPC().setType("gamg")
            ksp.setTolerances(rtol=rtol, atol=1e-300, max_it=max_iterations)
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setUp()
        self.matrix, self.A, self.ksp = matrix, A, ksp
        self.criterion = (DIRECT_TOLERANCE, "Cholesky") if self.method == "direct" else (rtol, "CG + GAMG")
        self.x, self.b = A.createVecs()

    def solve(self, rhs: np.ndarray) -> tuple[np.ndarray, PoissonReport]:
        b = np.asarray(rhs, dtype=float).ravel()
        if self.singular:
            b = b - b.mean()
            if self.method == "direct":
                b[0] = 0.0
        norm = float(np.linalg.norm(b))
        if norm == 0.0:
            return np.zeros(self.grid.cells), PoissonReport(0, 0.0, True, *self.criterion)
        self.b.array[:] = b
        self.x.set(0.0)
        self.ksp.solve(self.b, self.x)
        phi = self.x.array.copy()
        if self.singular:
            phi -= phi.mean()
        if self.method == "direct":
            residual = float(np.linalg.norm(self.matrix @ self.x.array - b)) / norm
            report = PoissonReport(1, residual, residual < DIRECT_TOLERANCE, *self.criterion)
        else:
            report = PoissonReport(self.ksp.getIterationNumber(), self.ksp.getResidualNorm() / norm,
                                   self.ksp.getConvergedReason() > 0, *self.criterion)
        return phi.reshape(self.grid.cells), report

    def destroy(self) -> None:
        for obj in (self.ksp, self.A, self.x, self.b):
            obj.destroy()


def assemble(grid: Staggered, beta: list[np.ndarray]) -> sp.csr_matrix:
    """``-div(beta grad .)`` on the cells (see the module doc)."""
    index = np.arange(int(np.prod(grid.cells))).reshape(grid.cells)
    rows, cols, vals = [], [], []
    diagonal = np.zeros(grid.cells)
    for c in range(3):
        A = AXIS[c]
        w = beta[c][grid.interior(c)] / grid.h[c] ** 2
        left, right = index[along(A, slice(None, -1))].ravel(), index[along(A, slice(1, None))].ravel()
        w = w.ravel()
        rows += [left, right]
        cols += [right, left]
        vals += [-w, -w]
        diagonal[along(A, slice(None, -1))] += w.reshape(diagonal[along(A, slice(None, -1))].shape)
        diagonal[along(A, slice(1, None))] += w.reshape(diagonal[along(A, slice(1, None))].shape)
    for d, side in grid.pressure_faces:
        A = AXIS[d]
        plane = along(A, slice(-1, None) if side else slice(0, 1))
        diagonal[plane] += 2.0 * beta[d][plane] / grid.h[d] ** 2
    rows.append(index.ravel())
    cols.append(index.ravel())
    vals.append(diagonal.ravel())
    n = index.size
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
