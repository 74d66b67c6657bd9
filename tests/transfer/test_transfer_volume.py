"""Volume transfer: exactness (paper eq. 1-3) between non-matching meshes and grids.

An L2 projection onto a space that contains the linear functions reproduces a
linear field exactly; so does the pseudo-L2 projection (the dual basis of eq. 4
reproduces what the target space contains). Both for l2 and pseudo_l2.
"""

import numpy as np
import pytest

from transfer import FunctionSpace, StructuredGrid, Transfer
from transfer.generate import box_tetrahedra

from vc_helpers import Linear, rel_err

EXACT = 1e-12


def reproduce(source, target, method, field, **kwargs):
    T = Transfer.assemble(source, target, method, **kwargs)
    assert T.covered_fraction == 1.0
    return rel_err(T(source.interpolate(field)), target.interpolate(field))


# -- P1 <-> P1 ---------------------------------------------------------------
@pytest.mark.parametrize("quadrature_degree", [None, 2])
def test_p1_p1_linear_scalar(spaces, method, quadrature_degree):
    src, dst = spaces
    for seed in range(3):
        assert reproduce(src, dst, method, Linear(seed), quadrature_degree=quadrature_degree) < EXACT
    assert reproduce(dst, src, method, Linear(7), quadrature_degree=quadrature_degree) < EXACT


@pytest.mark.parametrize("quadrature_degree", [None, 2])
def test_p1_p1_linear_vector(spaces, method, quadrature_degree):
    src, dst = spaces
    u = Linear(3, k=3)
    T = Transfer.assemble(src, dst, method, quadrature_degree=quadrature_degree)
    v = T(src.interpolate(u))
    assert v.shape == (dst.num_dofs, 3)
    assert rel_err(v, dst.interpolate(u)) < EXACT
    # component-wise application agrees with the vector application
    v0 = T(src.interpolate(u)[:, 0])
    np.testing.assert_allclose(v[:, 0], v0, rtol=0, atol=1e-13 * np.abs(v0).max())


def test_quadrature_path_equals_moments(spaces, method):
    """B and D integrated from moments and by a degree-2 rule agree (both are exact)."""
    src, dst = spaces
    a = Transfer.assemble(src, dst, method)
    b = Transfer.assemble(src, dst, method, quadrature_degree=2)
    assert a.stats["quadrature_degree"] == "exact" and b.stats["quadrature_degree"] == 2
    assert abs(a.B - b.B).max() <= 1e-13 * abs(a.B).max()
    assert abs(a.D - b.D).max() <= 1e-13 * abs(a.D).max()


def test_l2_projection_is_identity_on_the_target_space(method):
    """A field of the target space, given on a finer source that contains it (nested
    Kuhn meshes: each 2h-simplex is a union of h-simplices), comes back exactly,
    whatever the field (here: random nodal values, not a polynomial)."""
    coarse = FunctionSpace(box_tetrahedra((2, 2, 2), name="coarse"), "P1")
    fine = FunctionSpace(box_tetrahedra((4, 4, 4), name="fine"), "P1")
    w = np.random.default_rng(5).normal(size=coarse.num_dofs)
    # interpolate the coarse P1 field on the fine vertices (fine = coarse + midpoints)
    to_fine = Transfer.assemble(coarse, fine, "l2")
    w_fine = to_fine(w)
    back = Transfer.assemble(fine, coarse, method)(w_fine)
    assert rel_err(back, w) < EXACT
    # and the coarse field is itself reproduced on the fine mesh (it is in that space)
    assert rel_err(Transfer.assemble(coarse, fine, method)(w), w_fine) < EXACT
    on_coarse_vertices = np.flatnonzero(np.isin(
        np.round(fine.mesh.points * 4).astype(int) % 2, [0]).all(axis=1))
    assert len(on_coarse_vertices) == coarse.num_dofs
    np.testing.assert_allclose(np.sort(w_fine[on_coarse_vertices]), np.sort(w), rtol=0, atol=1e-12)


def test_coupling_matrix_is_symmetric_in_the_meshes(spaces):
    """B from a to b is the transpose of B from b to a: int lambda_j^a lambda_k^b."""
    a, b = spaces
    Bab = Transfer.assemble(a, b, "l2").B
    Bba = Transfer.assemble(b, a, "l2").B
    assert Bab.shape == (b.num_dofs, a.num_dofs)
    assert abs(Bab - Bba.T).max() <= 1e-14 * abs(Bab).max()


def test_l2_mass_matrix_is_the_target_mass_matrix(spaces, method):
    """When the source covers the target, D (l2) is the target's own mass matrix and
    B's entries sum to the volume of the domain."""
    src, dst = spaces
    T = Transfer.assemble(src, dst, method)
    np.testing.assert_allclose(T.B.sum(), 1.0, rtol=1e-13)
    if method == "l2":
        M = dst.mass_matrix()
        assert abs(T.D - M).max() <= 1e-13 * abs(M).max()


# -- structured grids and hexahedra -------------------------------------------
def test_grid_q1_to_p1(grid, dst_tets, method):
    Q, P = FunctionSpace(grid, "Q1"), FunctionSpace(dst_tets, "P1")
    assert reproduce(Q, P, method, Linear(11)) < EXACT
    assert reproduce(Q, P, method, Linear(12, k=3)) < EXACT


def test_p1_to_grid_q1(grid, src_tets, method):
    P, Q = FunctionSpace(src_tets, "P1"), FunctionSpace(grid, "Q1")
    assert reproduce(P, Q, method, Linear(13)) < EXACT
    assert reproduce(P, Q, method, Linear(14, k=3)) < EXACT


def test_grid_reproduces_multilinear_fields(method):
    """Q1 grid -> finer Q1 grid (nested): a trilinear field is in both spaces."""
    coarse = StructuredGrid.from_bounds((0, 0, 0), (1, 2, 1), (2, 3, 2))
    fine = StructuredGrid.from_bounds((0, 0, 0), (1, 2, 1), (4, 6, 4))
    f = lambda x: 1 + x[:, 0] * x[:, 1] * x[:, 2] - 2 * x[:, 0] * x[:, 2] + x[:, 1]
    assert reproduce(FunctionSpace(coarse, "Q1"), FunctionSpace(fine, "Q1"), method, f) < EXACT
    assert reproduce(FunctionSpace(fine, "Q1"), FunctionSpace(coarse, "Q1"), method, f) < EXACT


def test_hex_q1_to_p1(src_hexes, dst_tets, method):
    H, P = FunctionSpace(src_hexes, "Q1"), FunctionSpace(dst_tets, "P1")
    assert reproduce(H, P, method, Linear(15)) < EXACT
    assert reproduce(H, P, method, Linear(16, k=3)) < EXACT


def test_p1_to_hex_q1(src_tets, src_hexes, method):
    P, H = FunctionSpace(src_tets, "P1"), FunctionSpace(src_hexes, "Q1")
    assert reproduce(P, H, method, Linear(17)) < EXACT


def test_grid_to_hexes(grid, src_hexes, method):
    assert reproduce(FunctionSpace(grid, "Q1"), FunctionSpace(src_hexes, "Q1"), method, Linear(18)) < EXACT


# -- degree 0 ----------------------------------------------------------------
def test_p0_p0_constants(src_tets, dst_tets, method):
    S, D = FunctionSpace(src_tets, "P0"), FunctionSpace(dst_tets, "P0")
    T = Transfer.assemble(S, D, method)
    v = T(np.full(S.num_dofs, -2.5))
    np.testing.assert_allclose(v, -2.5, rtol=1e-13)
    # B[k, j] = |K_k ∩ K_j|: rows sum to the target cell volumes, columns to the source ones
    np.testing.assert_allclose(np.asarray(T.B.sum(axis=1)).ravel(), dst_tets.cell_measures(), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(T.B.sum(axis=0)).ravel(), src_tets.cell_measures(), rtol=1e-12)
    np.testing.assert_allclose(T.D.diagonal(), dst_tets.cell_measures(), rtol=1e-12)


def test_p1_to_p0_gives_cell_means(src_tets, dst_tets, method):
    """The L2 projection on P0 is the cell mean; of a linear field, its centroid value."""
    P, Z = FunctionSpace(src_tets, "P1"), FunctionSpace(dst_tets, "P0")
    u = Linear(19)
    v = Transfer.assemble(P, Z, method)(P.interpolate(u))
    assert rel_err(v, u(dst_tets.cell_vertices().mean(axis=1))) < EXACT


def test_p0_to_p1_constants(src_tets, dst_tets, method):
    Z, P = FunctionSpace(src_tets, "P0"), FunctionSpace(dst_tets, "P1")
    v = Transfer.assemble(Z, P, method)(np.full(Z.num_dofs, 4.0))
    np.testing.assert_allclose(v, 4.0, rtol=1e-13)


def test_q0_grid_to_p0(grid, dst_tets, method):
    Z, P = FunctionSpace(grid, "Q0"), FunctionSpace(dst_tets, "P0")
    v = Transfer.assemble(Z, P, method)(np.full(Z.num_dofs, 3.0))
    np.testing.assert_allclose(v, 3.0, rtol=1e-13)


# -- options and statistics --------------------------------------------------
def test_threads_give_the_same_operator(spaces, method):
    src, dst = spaces
    a = Transfer.assemble(src, dst, method, nthreads=1)
    b = Transfer.assemble(src, dst, method, nthreads=2)
    assert abs(a.B - b.B).max() <= 1e-15 * abs(a.B).max()
    assert b.stats["nthreads"] == 2
    assert a.stats["pairs_intersected"] == b.stats["pairs_intersected"] > 0


def test_unknown_method_is_rejected(spaces):
    from transfer import TransferError

    with pytest.raises(TransferError, match="unknown method"):
        Transfer.assemble(*spaces, "nearest")


def test_mixed_dimensions_are_rejected(src_tets):
    from transfer import TransferError
    from transfer.generate import rectangle

    surf = FunctionSpace(rectangle((2, 2)), "P1")
    with pytest.raises(TransferError, match="surface field cannot be projected onto a volume"):
        Transfer.assemble(surf, FunctionSpace(src_tets, "P1"))
