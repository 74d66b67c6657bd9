"""Fields given to a transfer: validation (FieldError) and the operator interface."""

import numpy as np
import pytest

from transfer import FieldError, FunctionSpace, Transfer, TransferError

from vc_helpers import Linear


@pytest.fixture(scope="module")
def transfers(src_tets, dst_tets):
    S, D = FunctionSpace(src_tets, "P1"), FunctionSpace(dst_tets, "P1")
    return {m: Transfer.assemble(S, D, m) for m in ("l2", "pseudo_l2")}


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_values_raise(transfers, method, bad):
    T = transfers[method]
    u = np.ones(T.source.num_dofs)
    u[17] = bad
    with pytest.raises(FieldError, match=r"NaN/inf.*dof 17"):
        T.apply(u)
    v = np.ones((T.source.num_dofs, 3))
    v[5, 2] = bad
    with pytest.raises(FieldError, match=r"dof 5"):
        T(v)


def test_wrong_shapes_raise(transfers, method):
    T = transfers[method]
    n = T.source.num_dofs
    for bad in (np.ones(n + 1), np.ones(n - 1), np.ones((n, 2, 2)), np.ones(T.target.num_dofs)):
        with pytest.raises(FieldError, match="expected"):
            T(bad)
    assert issubclass(FieldError, TransferError) and issubclass(FieldError, ValueError)


def test_input_is_not_modified_and_lists_work(transfers, method):
    T = transfers[method]
    u = T.source.interpolate(Linear(61))
    keep = u.copy()
    v = T(u)
    np.testing.assert_array_equal(u, keep)
    np.testing.assert_allclose(T(list(u)), v, rtol=0, atol=0)
    np.testing.assert_allclose(T(u.astype(np.float32)), T(u.astype(np.float32).astype(float)))


def test_linearity(transfers, method):
    T = transfers[method]
    rng = np.random.default_rng(62)
    a, b = rng.normal(size=(2, T.source.num_dofs))
    scale = np.abs(T(a)).max() + np.abs(T(b)).max()
    np.testing.assert_allclose(T(2 * a - 3 * b), 2 * T(a) - 3 * T(b), rtol=0, atol=1e-12 * 5 * scale)


def test_pseudo_l2_matrix_equals_apply(transfers):
    T = transfers["pseudo_l2"]
    u = np.random.default_rng(63).normal(size=T.source.num_dofs)
    M = T.matrix()
    assert M.shape == (T.target.num_dofs, T.source.num_dofs)
    np.testing.assert_allclose(M @ u, T(u), rtol=1e-14, atol=1e-14)
    # pseudo-L2 rows are convex-like combinations reproducing constants: row sums are one
    np.testing.assert_allclose(np.asarray(M.sum(axis=1)).ravel(), 1.0, rtol=1e-13)
    with pytest.raises(TransferError, match="dense"):
        transfers["l2"].matrix()


def test_pseudo_l2_matrix_rows_of_uncovered_dofs_are_empty(src_tets, shifted_tets):
    T = Transfer.assemble(FunctionSpace(src_tets, "P1"), FunctionSpace(shifted_tets, "P1"), "pseudo_l2")
    M = T.matrix()
    nnz_per_row = np.diff(M.indptr)
    assert np.all(nnz_per_row[T.uncovered] == 0)
    assert np.all(nnz_per_row[T.covered] > 0)
