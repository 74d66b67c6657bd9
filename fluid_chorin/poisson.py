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
dissection ordering; one cell pinned when singular; on several MPI ranks MUMPS's), cheaper per
solve on small grids, where multigrid's fixed cost per cycle dominates; ``"auto"`` takes the
direct one up to :data:`DIRECT_CELLS` cells, and up to :data:`DIRECT_CELLS_ANISOTROPIC` on
anisotropic cells (a fracture's grid, much finer across the aperture than along it), where
multigrid needs its threshold for weak couplings (:data:`GAMG_THRESHOLD`) to converge at all and
is still far slower than a factorization (bench/poisson.py). Either is set up once per matrix
(a new ``dt`` or solid) and reused for every solve with it. On several ranks (:mod:`fluid_chorin.slabs`) the
matrix and vectors are distributed by slabs, each rank holding the rows of its cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .slabs import Slabs
from .staggered import AXIS, Staggered, along

#: ``"auto"`` factorizes up to this many cells and uses multigrid beyond
DIRECT_CELLS = 30000
#: cells whose longest side is at least this many times their shortest are anisotropic
ANISOTROPIC = 10.0
#: ``"auto"`` on anisotropic cells: the factorization up to this many cells (its memory grows as
#: cells^(4/3), about 0.8 GB at 170,000 cells)
DIRECT_CELLS_ANISOTROPIC = 300000
#: GAMG drops couplings weaker than this in its coarsening on anisotropic cells (PETSc's
#: ``-pc_gamg_threshold``; without it CG stalls there)
GAMG_THRESHOLD = 0.02


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
    """The pressure equation on the cells of ``slabs`` (:class:`fluid_chorin.slabs.Slabs`): each
    rank assembles the rows of its own cells from its local ``grid`` and ``beta`` (ghosts
    included) into one PETSc matrix over the ranks' communicator."""

    def __init__(self, grid: Staggered, beta: list[np.ndarray], slabs: Slabs, method: str = "auto",
                 rtol: float = 1e-10, max_iterations: int = 500):
        from petsc4py import PETSc

        self.slabs = slabs
        comm = PETSc.COMM_SELF if slabs.comm is None else PETSc.Comm(slabs.comm)
        n, N = slabs.count, int(np.prod(slabs.shape))
        self.size = N
        local = assemble(grid, beta)
        rows = np.arange(local.shape[0]).reshape(grid.cells)[slabs.owned()].ravel()
        local = local[rows]
        matrix = sp.csr_matrix((local.data, slabs.numbering.ravel()[local.indices], local.indptr), shape=(n, N))
        self.singular = not any(f["kind"] == "pressure" for f in slabs.grid_faces.values())
        h = grid.h[np.asarray(grid.active)]
        anisotropic = len(h) > 1 and h.max() >= ANISOTROPIC * h.min()
        limit = DIRECT_CELLS_ANISOTROPIC if anisotropic else DIRECT_CELLS
        self.method = ("direct" if N <= limit else "gamg") if method == "auto" else method
        self.pinned = self.method == "direct" and self.singular and slabs.offset == 0
        if self.method == "direct" and self.singular:  # pin cell 0 (the solution is shifted to zero mean)
            first = np.ones(n)
            first[0] = 1.0 - self.pinned
            keep = np.ones(N)
            keep[0] = 0.0
            pin = sp.csr_matrix(([1.0] * self.pinned, ([0] * self.pinned, [0] * self.pinned)), shape=(n, N))
            matrix = (sp.diags(first) @ matrix @ sp.diags(keep) + pin).tocsr()
        if self.method == "direct" and slabs.size > 1 and not PETSc.Sys.hasExternalPackage("mumps"):
            raise ValueError(f"poisson = 'direct' on {slabs.size} ranks needs PETSc with MUMPS, which this PETSc "
                             f"lacks: use poisson = 'gamg'")
        matrix.sort_indices()
        A = PETSc.Mat().createAIJ(size=((n, N), (n, N)), csr=(matrix.indptr.astype(PETSc.IntType),
                                                              matrix.indices.astype(PETSc.IntType), matrix.data),
                                  comm=comm)
        A.assemble()
        ksp = PETSc.KSP().create(comm=comm)
        ksp.setOperators(A)
        if self.method == "direct":
            ksp.setType("preonly")
            pc = ksp.getPC()
            pc.setType("cholesky")
            if slabs.size > 1:
                pc.setFactorSolverType("mumps")
            else:
                pc.setFactorOrdering("nd")
        else:
            if self.singular:
                A.setNullSpace(PETSc.NullSpace().create(constant=True, comm=comm))
            ksp.setType("cg")
            ksp.getPC().setType("gamg")
            if anisotropic:
                ksp.setOptionsPrefix("varcouple_poisson_")
                PETSc.Options("varcouple_poisson_")["pc_gamg_threshold"] = GAMG_THRESHOLD
                ksp.getPC().setFromOptions()
            ksp.setTolerances(rtol=rtol, atol=1e-300, max_it=max_iterations)
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setUp()
        self.A, self.ksp = A, ksp
        self.criterion = ((DIRECT_TOLERANCE, "Cholesky" + " (MUMPS)" * (slabs.size > 1)) if self.method == "direct"
                          else (rtol, "CG + GAMG"))
        self.x, self.b = A.createVecs()
        self.r = self.b.duplicate()

    def mean(self, values: np.ndarray) -> float:
        return self.slabs.sum(float(values.sum())) / self.size

    def solve(self, rhs: np.ndarray) -> tuple[np.ndarray, PoissonReport]:
        """phi on the owned cells for the right-hand side ``rhs`` on them."""
        b = np.asarray(rhs, dtype=float).ravel()
        if self.singular:
            b = b - self.mean(b)
            if self.pinned:
                b[0] = 0.0
        norm = math.sqrt(self.slabs.sum(float(np.dot(b, b))))
        shape = rhs.shape
        if norm == 0.0:
            return np.zeros(shape), PoissonReport(0, 0.0, True, *self.criterion)
        self.b.array[:] = b
        self.x.set(0.0)
        self.ksp.solve(self.b, self.x)
        phi = self.x.array.copy()
        if self.singular:
            phi -= self.mean(phi)
        if self.method == "direct":
            self.A.mult(self.x, self.r)
            self.r.axpy(-1.0, self.b)
            residual = self.r.norm() / norm
            report = PoissonReport(1, residual, residual < DIRECT_TOLERANCE, *self.criterion)
        else:
            report = PoissonReport(self.ksp.getIterationNumber(), self.ksp.getResidualNorm() / norm,
                                   self.ksp.getConvergedReason() > 0, *self.criterion)
        return phi.reshape(shape), report

    def destroy(self) -> None:
        for obj in (self.ksp, self.A, self.x, self.b, self.r):
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
