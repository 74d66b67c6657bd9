"""Projected Gauss-Seidel (the nonlinear smoother of paper section 2.4), compiled.

A sweep minimises ``J(x) = 1/2 x^T A x - b^T x`` along each coordinate in turn
within ``lower <= x <= upper``, so it never increases J and every iterate is
feasible. With ``lower = upper = 0`` on truncated components and infinite
bounds elsewhere it is the linear Gauss-Seidel sweep of the truncated matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _smoothers

#: sweep orders of :func:`projected_gauss_seidel`
ORDERS = {"forward": 0, "backward": 1, "symmetric": 2}


def csr_int32(A: sp.spmatrix) -> sp.csr_matrix:
    """A as CSR with int32 indices, the layout the compiled sweeps read."""
    A = sp.csr_matrix(A)
    if A.indptr.dtype != np.int32 or A.indices.dtype != np.int32:
        if A.nnz > np.iinfo(np.int32).max:
            raise ValueError(f"{A.nnz} nonzeros do not fit int32 indices")
        A = sp.csr_matrix((A.data, A.indices.astype(np.int32), A.indptr.astype(np.int32)), shape=A.shape)
    return A


def projected_gauss_seidel(A: sp.csr_matrix, b: np.ndarray, lower: np.ndarray, upper: np.ndarray, x: np.ndarray,
                           sweeps: int = 1, order: str = "forward") -> np.ndarray:
    """`sweeps` projected Gauss-Seidel sweeps on x in place, in `order`
    (:data:`ORDERS`); A must come from :func:`csr_int32`."""
    if order not in ORDERS:
        raise ValueError(f"unknown sweep order {order!r}; use one of {list(ORDERS)}")
    _smoothers.projected_gauss_seidel(A.indptr, A.indices, np.ascontiguousarray(A.data, dtype=float),
                                      np.ascontiguousarray(b, dtype=float), lower, upper, x, sweeps, ORDERS[order])
    return x
