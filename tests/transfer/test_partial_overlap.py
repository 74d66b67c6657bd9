"""Partial and empty overlap: the covered mask, NaN for uncovered dofs, NoOverlapError."""

import numpy as np
import pytest

from transfer import FunctionSpace, Mesh, NoOverlapError, StructuredGrid, Transfer, TransferError
from transfer.generate import box_hexahedra, box_tetrahedra

from vc_helpers import Linear, rel_err, tet_box_overlap

EXACT = 1e-12


@pytest.fixture(scope="module")
def independent_geometry(shifted_tets):
    """Volume and centroid of every shifted target cell inside the unit cube,
    computed in the test."""
    out = [tet_box_overlap(p, np.zeros(3), np.ones(3), with_centroid=True) for p in shifted_tets.cell_vertices()]
    return np.array([v for v, _ in out]), np.array([c for _, c in out])


@pytest.fixture(scope="module")
def independent_overlap(independent_geometry):
    return independent_geometry[0]


@pytest.fixture(scope="module")
def src_p1(src_tets):
    return FunctionSpace(src_tets, "P1")


@pytest.fixture(scope="module")
def dst_p1(shifted_tets):
    return FunctionSpace(shifted_tets, "P1")


def test_cell_overlaps_match_independent_geometry(src_p1, dst_p1, shifted_tets, independent_overlap, method):
    T = Transfer.assemble(src_p1, dst_p1, method)
    np.testing.assert_allclose(T.coupling.overlap, independent_overlap, rtol=0, atol=1e-13)
    np.testing.assert_allclose(T.coupling.measure, shifted_tets.cell_measures(), rtol=1e-13)
    # the configuration is a real partial overlap: full, cut and empty cells
    full = np.isclose(independent_overlap, shifted_tets.cell_measures(), rtol=1e-12)
    empty = independent_overlap == 0
    assert full.any() and empty.any() and (~full & ~empty).any()


def dof_sums(cells, per_cell_per_vertex, n):
    out = np.zeros(n)
    np.add.at(out, cells.ravel(), np.asarray(per_cell_per_vertex).ravel())
    return out


def test_covered_mask_is_geometric(src_p1, dst_p1, shifted_tets, independent_geometry, method):
    """A target dof is covered iff its support (the cells around it) overlaps the source;
    `coverage` is the fraction of its support's volume inside the source."""
    T = Transfer.assemble(src_p1, dst_p1, method)
    volume, _ = independent_geometry
    cells, n = shifted_tets.cells, dst_p1.num_dofs
    support_overlap = dof_sums(cells, np.repeat(volume, 4), n)
    support = dof_sums(cells, np.repeat(shifted_tets.cell_measures(), 4), n)
    # no dof is a borderline case for the geometric criterion
    assert not np.any((support_overlap > 0) & (support_overlap < 1e-6))
    np.testing.assert_array_equal(T.covered, support_overlap > 0)
    np.testing.assert_allclose(T.coverage, support_overlap / support, rtol=0, atol=1e-12)
    assert 0 < T.covered_fraction < 1
    np.testing.assert_allclose(T.covered_fraction, np.mean(support_overlap > 0))
    np.testing.assert_array_equal(T.uncovered, np.flatnonzero(support_overlap == 0))


def test_overlap_mass_of_each_dof(src_p1, dst_p1, shifted_tets, independent_geometry, method):
    """The row sums of D are int_overlap phi_j (both methods): phi_j is linear on each
    cell piece, so its integral is the piece volume times its value at the piece centroid."""
    T = Transfer.assemble(src_p1, dst_p1, method)
    volume, centroid = independent_geometry
    p = shifted_tets.cell_vertices()
    lam = np.linalg.solve(np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1)), (centroid - p[:, 0])[..., None])[..., 0]
    bary = np.column_stack([1 - lam.sum(axis=1), lam])
    expected = dof_sums(shifted_tets.cells, volume[:, None] * bary, dst_p1.num_dofs)
    rows = np.asarray(T.D.sum(axis=1)).ravel()
    np.testing.assert_allclose(rows, expected, rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.asarray(T.B.sum(axis=1)).ravel(), expected, rtol=0, atol=1e-13)


def test_uncovered_dofs_are_nan_and_fill_works(src_p1, dst_p1, method):
    T = Transfer.assemble(src_p1, dst_p1, method)
    u = src_p1.interpolate(Linear(41))
    v = T(u)
    assert np.all(np.isnan(v[T.uncovered]))
    assert np.all(np.isfinite(v[T.covered]))
    w = T.apply(u, fill=0.0)
    assert np.all(w[T.uncovered] == 0.0)
    np.testing.assert_array_equal(w[T.covered], v[T.covered])
    vec = T(np.column_stack([u, 2 * u]), fill=-7.0)
    assert np.all(vec[T.uncovered] == -7.0)
    np.testing.assert_allclose(vec[T.covered, 1], 2 * v[T.covered], rtol=0, atol=1e-12 * np.abs(v[T.covered]).max())


def test_l2_reproduces_linears_on_covered_dofs(src_p1, dst_p1, shifted_tets, independent_overlap):
    """l2 with the overlap mass matrix: T u = u on covered dofs, cut supports included.

    Excluded: dofs touching a cell with less than 1% of it covered, whose overlap mass the
    kernels lump by design (common.hpp kConsistentCut: the consistent mass of a small
    piece is nearly singular) - there l2 is only conservative, not exact."""
    T = Transfer.assemble(src_p1, dst_p1, "l2")
    fraction = independent_overlap / shifted_tets.cell_measures()
    lumped = (fraction > 0) & (fraction < 1e-2)
    exact = T.covered.copy()
    exact[shifted_tets.cells[lumped].ravel()] = False
    cut = (fraction > 0) & (fraction < 1 - 1e-12)
    on_cut = np.zeros(dst_p1.num_dofs, bool)
    on_cut[shifted_tets.cells[cut].ravel()] = True
    assert np.count_nonzero(exact & on_cut) > 10  # the test does reach cut supports
    for u in (Linear(42), Linear(43, k=2)):
        v = T(src_p1.interpolate(u))
        assert rel_err(v[exact], dst_p1.interpolate(u)[exact]) < EXACT


def test_pseudo_l2_reproduces_linears_where_fully_covered(src_p1, dst_p1, shifted_tets, independent_overlap):
    """pseudo_l2 falls back to lumped standard rows on cut cells, so it is exact on the
    dofs whose whole support lies in the overlap (and only conservative elsewhere)."""
    T = Transfer.assemble(src_p1, dst_p1, "pseudo_l2")
    cut = ~np.isclose(independent_overlap, shifted_tets.cell_measures(), rtol=1e-12)
    inner = np.ones(dst_p1.num_dofs, bool)
    inner[shifted_tets.cells[cut].ravel()] = False
    assert inner.sum() >= 5
    u = Linear(44)
    v = T(src_p1.interpolate(u))
    assert rel_err(v[inner], dst_p1.interpolate(u)[inner]) < EXACT


def test_grid_target_partially_covered(src_tets, method):
    """A grid sticking out of the source on one side: exactly its first layers are covered."""
    g = StructuredGrid.from_bounds((0.5, 0, 0), (1.5, 1, 1), (4, 2, 2))  # spacing 0.25 in x
    T = Transfer.assemble(FunctionSpace(src_tets, "P1"), FunctionSpace(g, "Q1"), method)
    x = g.points[:, 0]
    # dofs at x <= 1.0 have a support that overlaps [0, 1]^3 with positive volume
    np.testing.assert_array_equal(T.covered, x < 1.0 + 1e-9)
    u = Linear(45)
    v = T(FunctionSpace(src_tets, "P1").interpolate(u))
    if method == "l2":
        assert rel_err(v[T.covered], u(g.points[T.covered])) < EXACT


# -- no overlap --------------------------------------------------------------
def test_disjoint_boxes_raise(src_tets, method):
    far = box_tetrahedra((2, 2, 2), lower=(2, 0, 0), upper=(3, 1, 1), name="far")
    with pytest.raises(NoOverlapError, match="do not overlap"):
        Transfer.assemble(FunctionSpace(src_tets, "P1"), FunctionSpace(far, "P1"), method)
    assert issubclass(NoOverlapError, TransferError)


def test_touching_meshes_raise(src_tets, method):
    """Sharing a face only: zero-volume overlap (bounding boxes do touch)."""
    touching = box_tetrahedra((2, 2, 2), lower=(1, 0, 0), upper=(2, 1, 1), jitter=0.1, name="touching")
    with pytest.raises(NoOverlapError, match="do not overlap"):
        Transfer.assemble(FunctionSpace(src_tets, "P1"), FunctionSpace(touching, "P1"), method)
    hexes = box_hexahedra((2, 2, 2), lower=(0, 0, 1), upper=(1, 1, 2), name="on-top")
    with pytest.raises(NoOverlapError, match="do not overlap"):
        Transfer.assemble(FunctionSpace(src_tets, "P0"), FunctionSpace(hexes, "Q0"), method)


def test_overlapping_bounding_boxes_but_disjoint_cells_raise(method):
    """Bounding boxes overlap, the cells do not: the kernel finds no intersection."""
    corner = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], "tetra", name="corner")
    box = box_tetrahedra((1, 1, 1), lower=(0.7, 0.7, 0.7), upper=(0.95, 0.95, 0.95), name="box")
    with pytest.raises(NoOverlapError, match="corner and box do not overlap"):
        Transfer.assemble(FunctionSpace(corner, "P1"), FunctionSpace(box, "P1"), method)


def test_grid_source_disjoint_raises(grid, method):
    far = box_tetrahedra((1, 1, 1), lower=(-3, -3, -3), upper=(-2, -2, -2))
    with pytest.raises(NoOverlapError, match="do not overlap"):
        Transfer.assemble(FunctionSpace(grid, "Q1"), FunctionSpace(far, "P1"), method)
