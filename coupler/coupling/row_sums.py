"""Inner products of interface vectors split by rows over MPI ranks (docs/scaling.md, step 4).

The interface vector ``x`` of the coupling iteration (paper, section 2.3), its image
``H(x)``, the lumped mass ``m`` of the M-inner product ``(u, v)_M = sum_i m_i u_i v_i`` and
IQN-ILS's secant columns may be split by rows over the ranks of an MPI communicator: each
rank holds its own rows, any number of them, none too. An inner product is then a local sum
plus an allreduce, and a block of them (``k`` columns against one vector) travels in one
allreduce of ``k`` numbers. :class:`RowSums` holds the communicator and does those sums, so the
accelerators and the convergence test are written once: with ``comm=None`` (or a single
rank) every method is the serial expression, no MPI is involved and results are unchanged
bit for bit.

Every reduced value is the same on every rank (Open MPI combines the partial sums in one
order on all ranks), so decisions taken from it (a column filtered out, convergence) agree.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["RowSums", "inner", "norm"]


def inner(u: np.ndarray, v: np.ndarray, weights: np.ndarray | None = None) -> float:
    """The inner product ``(u, v)_M = sum_i m_i u_i v_i`` (Euclidean when `weights` is None)."""
    if weights is None:
        return float(np.dot(u, v))
    return float(np.dot(weights * u, v))


def norm(v: np.ndarray, weights: np.ndarray | None = None) -> float:
    """The norm ``||v||_M = sqrt((v, v)_M)``."""
    if weights is None:
        return float(np.linalg.norm(v))
    return float(np.sqrt(np.dot(weights * v, v)))


class RowSums:
    """Sums over the rows that the ranks of `comm` hold (``None``: one process holds them all).

    The methods are collective: every rank calls them in the same order, with its own rows.
    """

    def __init__(self, comm=None):
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None

    @property
    def distributed(self) -> bool:
        return self.comm is not None

    def sum(self, local):
        """The sum over the ranks of a number or an array of numbers (one allreduce)."""
        if self.comm is None:
            return local
        from mpi4py import MPI

        send = np.ascontiguousarray(local, dtype=float)
        total = np.empty_like(send)
        self.comm.Allreduce(send, total, op=MPI.SUM)
        return float(total) if np.ndim(local) == 0 else total

    def extremum(self, local, op: str):
        """``max`` or ``min`` over the ranks of a number or an array of numbers."""
        if self.comm is None:
            return local
        from mpi4py import MPI

        send = np.ascontiguousarray(local, dtype=float)
        total = np.empty_like(send)
        self.comm.Allreduce(send, total, op={"max": MPI.MAX, "min": MPI.MIN}[op])
        return float(total) if np.ndim(local) == 0 else total

    def norms(self, vectors, weights=None) -> np.ndarray:
        """``||v||_M`` of each vector of `vectors` (one allreduce for all)."""
        return np.sqrt(self.sum(np.array([inner(v, v, weights) for v in vectors])))

    def norm(self, v, weights=None) -> float:
        """``||v||_M`` over all rows (the serial value of :func:`norm` bit for bit)."""
        if self.comm is None:
            return norm(v, weights)
        return math.sqrt(self.sum(inner(v, v, weights)))

    def column_dots(self, A: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``A^T v`` over all rows: k numbers for k columns, one allreduce."""
        return self.sum(A.T @ v)

    def column_norms(self, A: np.ndarray) -> np.ndarray:
        """The Euclidean norm of every column of `A` over all rows (``np.linalg.norm(A,
        axis=0)`` serially)."""
        if self.comm is None:
            return np.linalg.norm(A, axis=0)
        return np.sqrt(self.sum(np.add.reduce(A * A, axis=0)))

    def size(self, local: int) -> int:
        """The number of rows of all ranks."""
        return int(round(self.sum(float(local))))

    def offset(self, local: int) -> int:
        """The global index of this rank's first row (the rows of the lower ranks come first)."""
        if self.comm is None:
            return 0
        return int(self.comm.exscan(int(local)) or 0)

    def any(self, flag: bool) -> bool:
        """True on every rank when `flag` is true on some rank."""
        return bool(self.extremum(float(bool(flag)), "max")) if self.comm is not None else bool(flag)
