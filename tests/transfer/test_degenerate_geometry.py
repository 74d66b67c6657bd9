"""Degenerate and badly scaled geometry: identical meshes (every face coplanar with
another), tiny offsets, very flat cells, other units, meshes far from the origin."""

import numpy as np
import pytest

from transfer import FunctionSpace, Mesh, StructuredGrid, Transfer
from transfer.generate import box_hexahedra, box_tetrahedra

from vc_helpers import Linear, rel_err, signed_volumes, split_tet

EXACT = 1e-12


def dense_T(T):
    """T = D^{-1} B as a dense array, by applying it to the identity."""
    return T(np.eye(T.source.num_dofs))


# -- identical meshes ---------------------------------------------------------
def test_identical_meshes_l2_b_equals_d(src_tets):
    V = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(V, V, "l2")
    assert abs(T.B - T.D).max() <= 1e-13 * abs(T.D).max()
    M = V.mass_matrix()
    assert abs(T.D - M).max() <= 1e-13 * abs(M).max()
    np.testing.assert_allclose(T.coupling.overlap, src_tets.cell_measures(), rtol=1e-13)


def test_identical_meshes_t_is_identity(src_tets, method):
    V = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(V, V, method)
    assert T.covered_fraction == 1.0
    np.testing.assert_allclose(dense_T(T), np.eye(V.num_dofs), rtol=0, atol=1e-12)
    if method == "pseudo_l2":
        np.testing.assert_allclose(T.matrix().toarray(), np.eye(V.num_dofs), rtol=0, atol=1e-12)


def test_copied_mesh_gives_the_same_operator(src_tets, method):
    """Same geometry in a separate Mesh object (shared faces, not shared memory)."""
    copy = Mesh(src_tets.points.copy(), src_tets.cells.copy(), "tetra", name="copy")
    T = Transfer.assemble(FunctionSpace(src_tets, "P1"), FunctionSpace(copy, "P1"), method)
    np.testing.assert_allclose(dense_T(T), np.eye(copy.num_points), rtol=0, atol=1e-12)


@pytest.mark.parametrize("family", ["P0"])
def test_identical_meshes_p0_is_identity(src_tets, method, family):
    V = FunctionSpace(src_tets, family)
    T = Transfer.assemble(V, V, method)
    np.testing.assert_allclose(T.B.toarray(), np.diag(src_tets.cell_measures()), rtol=0, atol=1e-15)


def test_identical_grids_and_hexes_t_is_identity(grid, src_hexes, method):
    for mesh in (grid, src_hexes):
        V = FunctionSpace(mesh, "Q1")
        T = Transfer.assemble(V, V, method)
        assert T.covered_fraction == 1.0
        np.testing.assert_allclose(dense_T(T), np.eye(V.num_dofs), rtol=0, atol=1e-11)


def test_coplanar_boundaries_cover_exactly(spaces, grid, src_hexes, method):
    """Non-matching meshes of the same cube share their boundary planes: every target
    cell is fully covered, no sliver of it is lost or counted twice."""
    src, dst = spaces
    for source in (src, FunctionSpace(grid, "Q1"), FunctionSpace(src_hexes, "Q1")):
        T = Transfer.assemble(source, dst, method)
        np.testing.assert_allclose(T.coupling.overlap, T.coupling.measure, rtol=1e-12)
        np.testing.assert_allclose(T.coverage, 1.0, rtol=1e-12)
        np.testing.assert_allclose(T.B.sum(), 1.0, rtol=1e-12)


def test_tiny_offset(src_tets, dst_tets, method):
    """Target moved by 1e-12: still fully covered, still exact for linears."""
    for direction in ([1.0, 1.0, 1.0], [-1.0, 0.5, 0.0]):
        moved = Mesh(dst_tets.points + 1e-12 * np.asarray(direction), dst_tets.cells, "tetra", name="moved")
        S, D = FunctionSpace(src_tets, "P1"), FunctionSpace(moved, "P1")
        T = Transfer.assemble(S, D, method)
        assert T.covered_fraction == 1.0
        u = Linear(51)
        assert rel_err(T(S.interpolate(u)), D.interpolate(u)) < 1e-9


def test_tiny_offset_identical_mesh(src_tets, method):
    """The worst case of coplanarity: every face of the source nearly on one of the target."""
    moved = Mesh(src_tets.points + [1e-12, -1e-12, 1e-12], src_tets.cells, "tetra")
    S, D = FunctionSpace(src_tets, "P1"), FunctionSpace(moved, "P1")
    T = Transfer.assemble(S, D, method)
    assert T.covered_fraction == 1.0
    np.testing.assert_allclose(dense_T(T), np.eye(S.num_dofs), rtol=0, atol=1e-9)


# -- very flat cells ------------------------------------------------------------
def flat_cell_mesh(delta=1e-6):
    """A jittered cube mesh where a few interior tets are split around a point very
    close to one of their faces (flat caps, relative volume delta) or to one of their
    edges (flat wedges, two cells of relative volume delta)."""
    base = box_tetrahedra((3, 3, 3), jitter=0.15, seed=6)
    points, cells = list(base.points), [list(c) for c in base.cells]
    centroids = base.cell_vertices().mean(axis=1)
    interior = np.flatnonzero(np.all((centroids > 0.34) & (centroids < 0.66), axis=1))
    flat = []
    for n, c in enumerate(interior[:4]):
        ref = base.cell_measures()[c]
        if n % 2 == 0:
            new = split_tet(cells, c, points, [delta, (1 - delta) / 3, (1 - delta) / 3, (1 - delta) / 3])
        else:
            new = split_tet(cells, c, points, [delta, 0.5 - delta, 0.5 - delta, delta])
        flat += [(k, ref) for k in new]
    mesh = Mesh(np.array(points), np.array(cells), "tetra", name="flat")
    vol = signed_volumes(mesh)
    ratios = np.array([vol[k] / ref for k, ref in flat])
    return mesh, ratios


def sliver_bipyramid(delta=1e-6):
    """Three tets around the axis a-e of a bipyramid, the axis passing at relative
    distance ~delta from the edge b-c: the tet (a, e, b, c) is a true sliver, its four
    vertices nearly coplanar with no short edge. The two-tet split of the same bipyramid
    is the non-matching partner."""
    b, c, d = np.array([-1.0, -1.0, 0]), np.array([1.0, -1.0, 0]), np.array([0.0, 1.5, 0])
    q = np.array([0.0, -1.0 + 2.5 * delta, 0])  # on the face b-c-d, near the edge b-c
    a, e = q + [0.2, 0.3, 1.0], q - [0.2, 0.3, 1.0]
    points = np.array([a, b, c, d, e])

    def oriented(cells):
        cells = np.array(cells)
        p = points[cells]
        vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
        cells[vol < 0] = cells[vol < 0][:, [1, 0, 2, 3]]
        return cells

    three = Mesh(points, oriented([[0, 4, 1, 2], [0, 4, 2, 3], [0, 4, 3, 1]]), "tetra", name="three")
    two = Mesh(points, oriented([[0, 1, 2, 3], [4, 1, 2, 3]]), "tetra", name="two")
    return three, two


def refine(mesh, times=2):
    """Split every tet at its centroid, `times` times (a non-matching, finer mesh)."""
    points, cells = list(mesh.points), [list(c) for c in mesh.cells]
    for _ in range(times):
        for k in range(len(cells)):
            split_tet(cells, k, points, [0.25, 0.25, 0.25, 0.25])
    return Mesh(np.array(points), np.array(cells), "tetra", name=mesh.name + "-refined")


def test_flat_cell_mesh_is_what_it_claims():
    mesh, ratios = flat_cell_mesh()
    assert np.all(ratios > 0)
    assert np.sum(ratios < 1e-5) >= 4  # several cells with relative volume ~1e-6
    np.testing.assert_allclose(mesh.cell_measures().sum(), 1.0, rtol=1e-13)
    three, _ = sliver_bipyramid()
    v = three.cell_measures()
    assert v.min() / v.max() < 1e-5
    s = three.cell_vertices()[np.argmin(v)]
    edges = np.linalg.norm(s[:, None] - s[None], axis=-1)
    assert edges[edges > 0].min() > 0.5  # a sliver, not a needle or a cap


@pytest.mark.parametrize("quadrature_degree", [None, 2])
def test_flat_cells_as_source(dst_tets, method, quadrature_degree):
    mesh, _ = flat_cell_mesh()
    F, D = FunctionSpace(mesh, "P1"), FunctionSpace(dst_tets, "P1")
    u = Linear(52)
    T = Transfer.assemble(F, D, method, quadrature_degree=quadrature_degree)
    assert T.covered_fraction == 1.0
    assert rel_err(T(F.interpolate(u)), D.interpolate(u)) < EXACT


@pytest.mark.parametrize("quadrature_degree", [None, 2])
def test_flat_cells_as_target(dst_tets, method, quadrature_degree):
    """Flat target cells: the default (moment) integration switches to quadrature
    for badly shaped cells, and full coverage is judged in coordinates relative
    to each target cell."""
    mesh, _ = flat_cell_mesh()
    F, D = FunctionSpace(mesh, "P1"), FunctionSpace(dst_tets, "P1")
    u = Linear(52)
    T = Transfer.assemble(D, F, method, quadrature_degree=quadrature_degree)
    assert T.covered_fraction == 1.0
    assert rel_err(T(D.interpolate(u)), F.interpolate(u)) < EXACT


def test_flat_cells_identity(method):
    mesh, _ = flat_cell_mesh()
    F = FunctionSpace(mesh, "P1")
    T = Transfer.assemble(F, F, method)
    np.testing.assert_allclose(dense_T(T), np.eye(F.num_dofs), rtol=0, atol=1e-10)


SLIVER_PAIRS = ["three->two", "two->three", "three->fine", "fine->three"]


@pytest.mark.parametrize("quadrature_degree", [None, 2])
def test_slivers_transfer_linears_exactly(method, quadrature_degree):
    three, two = sliver_bipyramid()
    meshes = {"three": three, "two": two, "fine": refine(two)}
    u = Linear(53)
    errors = {}
    for pair in SLIVER_PAIRS:
        a, b = (meshes[k] for k in pair.split("->"))
        A, B = FunctionSpace(a, "P1"), FunctionSpace(b, "P1")
        T = Transfer.assemble(A, B, method, quadrature_degree=quadrature_degree)
        assert T.covered_fraction == 1.0
        np.testing.assert_allclose(T.B.sum(), b.cell_measures().sum(), rtol=1e-12)
        errors[pair] = rel_err(T(A.interpolate(u)), B.interpolate(u))
    assert max(errors.values()) < EXACT, errors


def test_sliver_mass_matrix_is_symmetric_with_quadrature():
    three, _ = sliver_bipyramid()
    V = FunctionSpace(three, "P1")
    D = Transfer.assemble(V, V, "l2", quadrature_degree=2).D
    assert abs(D - D.T).max() <= 1e-15 * abs(D).max()
    M = V.mass_matrix()
    assert abs(D - M).max() <= 1e-14 * abs(M).max()


# -- units and position -------------------------------------------------------
@pytest.mark.parametrize("scale", [1e3, 1e-3])
def test_unit_scale_invariance(src_tets, dst_tets, method, scale):
    def scaled(m):
        return Mesh(m.points * scale, m.cells, "tetra", name=m.name)

    S, D = FunctionSpace(src_tets, "P1"), FunctionSpace(dst_tets, "P1")
    Ss, Ds = FunctionSpace(scaled(src_tets), "P1"), FunctionSpace(scaled(dst_tets), "P1")
    T, Ts = Transfer.assemble(S, D, method), Transfer.assemble(Ss, Ds, method)
    assert abs(Ts.B - scale**3 * T.B).max() <= 1e-12 * scale**3 * abs(T.B).max()
    assert abs(Ts.D - scale**3 * T.D).max() <= 1e-12 * scale**3 * abs(T.D).max()
    Td, Tsd = dense_T(T), dense_T(Ts)
    assert np.max(np.abs(Tsd - Td)) <= 1e-12 * np.max(np.abs(Td))
    assert Ts.covered_fraction == T.covered_fraction == 1.0


FAR = [1e3, -3e4, 1e5]


def far_case(pair, offset, src_tets, dst_tets, grid):
    shift = np.array([offset, 0.5 * offset, -offset])
    spaces = {
        "tet": FunctionSpace(Mesh(src_tets.points + shift, src_tets.cells, "tetra", name="src"), "P1"),
        "tet2": FunctionSpace(Mesh(dst_tets.points + shift, dst_tets.cells, "tetra", name="dst"), "P1"),
        "grid": FunctionSpace(StructuredGrid(grid.origin + shift, grid.spacing, grid.shape), "Q1"),
        "hex": FunctionSpace(box_hexahedra((2, 3, 2), lower=shift, upper=shift + 1, jitter=0.2, seed=2), "Q1"),
    }
    a, b = (spaces[k] for k in pair.split("->"))
    return a, b, Linear(54, x0=shift)  # O(1) values and variation on the moved meshes


@pytest.mark.parametrize("offset", FAR)
@pytest.mark.parametrize("pair", ["tet->tet2", "tet2->tet", "grid->tet2", "tet2->grid", "hex->tet2", "tet2->hex"])
def test_far_from_origin_l2(src_tets, dst_tets, grid, pair, offset):
    a, b, u = far_case(pair, offset, src_tets, dst_tets, grid)
    T = Transfer.assemble(a, b, "l2")
    assert T.covered_fraction == 1.0
    assert rel_err(T(a.interpolate(u)), b.interpolate(u)) < 1e-9


@pytest.mark.parametrize("offset", [*FAR, 1e6])
@pytest.mark.parametrize("pair", ["tet->tet2", "hex->tet2", "grid->tet2", "tet2->grid", "tet2->hex"])
def test_far_from_origin_pseudo_l2(src_tets, dst_tets, grid, pair, offset):
    a, b, u = far_case(pair, offset, src_tets, dst_tets, grid)
    T = Transfer.assemble(a, b, "pseudo_l2")
    assert T.covered_fraction == 1.0
    assert rel_err(T(a.interpolate(u)), b.interpolate(u)) < 1e-9
