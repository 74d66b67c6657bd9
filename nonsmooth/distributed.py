"""The bound-constrained QP of :mod:`nonsmooth.problem` on distributed PETSc matrices: ``A``
an MPI AIJ matrix, ``b`` an MPI vector, the bounds and every iterate the local (owned)
part of a vector laid out like ``A``'s rows. The active set solver
(:func:`nonsmooth.active_set.solve_active_set`) takes it as it takes the serial
:class:`~nonsmooth.problem.BoundConstrainedQP`: its componentwise steps act on the local
parts, its maxima and counts are reduced over the communicator, and the inner systems
stay distributed (CG + GAMG on the communicator)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


@dataclass
class DistributedQP:
    """min 1/2 x^T A x - b^T x subject to lower <= x <= upper, distributed.

    A : (n, n) MPI AIJ, symmetric positive definite
    b : its right-hand side, a vector laid out like A's rows
    lower, upper : the local (owned) parts of the bounds, ``-inf`` / ``+inf`` where free
    block_size : unknowns per node (for GAMG)
    """

    A: PETSc.Mat
    b: PETSc.Vec
    lower: np.ndarray
    upper: np.ndarray
    block_size: int = 1
    near_nullspace: None = None  # not supported on distributed matrices

    def __post_init__(self):
        self.comm: MPI.Comm = self.A.getComm().tompi4py()
        self.start, self.stop = self.A.getOwnershipRange()
        local = self.stop - self.start
        self.lower = np.broadcast_to(np.asarray(self.lower, float), (local,)).copy()
        self.upper = np.broadcast_to(np.asarray(self.upper, float), (local,)).copy()
        bad = self.comm.allreduce(int(np.count_nonzero(self.lower > self.upper)))
        if bad:
            raise ValueError(f"empty feasible set: lower > upper at {bad} components")

    @classmethod
    def from_serial(cls, qp, comm: MPI.Comm) -> "DistributedQP":
        """The serial :class:`~nonsmooth.problem.BoundConstrainedQP` `qp` (the same on every
        rank) with its rows split over `comm` in PETSc's default layout (whole blocks)."""
        n, bs = qp.size, qp.block_size
        blocks = PETSc.Vec().createMPI((PETSc.DECIDE, n // bs), comm=comm).getOwnershipRange()
        start, stop = bs * blocks[0], bs * blocks[1]
        rows = qp.A[start:stop]
        rows.sort_indices()
        A = PETSc.Mat().createAIJ(((stop - start, n), (stop - start, n)), bsize=bs, comm=comm,
                                  csr=(rows.indptr.astype(PETSc.IntType), rows.indices.astype(PETSc.IntType),
                                       rows.data))
        A.assemble()
        b = A.createVecLeft()
        b.getArray()[:] = qp.b[start:stop]
        return cls(A, b, qp.lower[start:stop], qp.upper[start:stop], block_size=bs)

    @property
    def size(self) -> int:
        return self.A.getSize()[0]

    def vector(self, values: np.ndarray) -> PETSc.Vec:
        """A new vector laid out like A's rows holding the local `values`."""
        v = self.A.createVecRight()
        v.getArray()[:] = values
        return v

    def product(self, x: np.ndarray) -> np.ndarray:
        """The local part of A x."""
        xv, y = self.vector(x), self.A.createVecLeft()
        self.A.mult(xv, y)
        out = y.getArray().copy()
        xv.destroy()
        y.destroy()
        return out

    def shift(self, rhs: np.ndarray) -> None:
        """b += rhs (local parts)."""
        self.b.setArray(self.b.getArray() + rhs)

    def diagonal(self) -> np.ndarray:
        d = self.A.getDiagonal()
        out = d.getArray().copy()
        d.destroy()
        return out

    def finite(self) -> bool:
        """A and b hold no NaN or inf (on every rank)."""
        ok = bool(np.all(np.isfinite(self.b.getArray())) and np.isfinite(self.A.norm(PETSc.NormType.FROBENIUS)))
        return self.comm.allreduce(ok, op=MPI.LAND)

    def project(self, x: np.ndarray) -> np.ndarray:
        return np.clip(x, self.lower, self.upper)

    def multiplier(self, x: np.ndarray) -> np.ndarray:
        """The local part of lam = b - A x."""
        return self.b.getArray() - self.product(x)

    def kkt_residual(self, x: np.ndarray) -> float:
        """max |x - P(x - (A x - b))| over all ranks."""
        local = np.max(np.abs(x - self.project(x + self.multiplier(x))), initial=0.0)
        return float(self.comm.allreduce(local, op=MPI.MAX))

    def fixed_system(self, active: np.ndarray, value: np.ndarray, diag: np.ndarray) -> tuple[PETSc.Mat, PETSc.Vec]:
        """The system with x[active] = value[active] (the serial ``_fixed_system`` of
        :mod:`nonsmooth.active_set`): active rows and columns replaced by their diagonal,
        the known values moved to the right side; new objects (destroy them)."""
        K = self.A.duplicate(copy=True)
        rows = (self.start + np.flatnonzero(active)).astype(PETSc.IntType)
        K.zeroRowsColumns(rows, diag=1.0)
        d = self.vector(diag)
        K.setDiagonal(d)  # A's diagonal on every row: unchanged where inactive
        xa = np.where(active, value, 0.0)
        rhs = self.vector(np.where(active, diag * xa, self.b.getArray() - self.product(xa)))
        d.destroy()
        return K, rhs
