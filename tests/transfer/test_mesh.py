"""Mesh validation, meshio conversion, function spaces on meshes."""

import re

import meshio
import numpy as np
import pytest

import transfer
from transfer import FunctionSpace, Mesh, MeshError, SpaceError, StructuredGrid
from transfer.generate import box_hexahedra, box_tetrahedra

from vc_helpers import signed_volumes

UNIT_TET = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])


def two_tets():
    """Two positively oriented tets sharing the face (1, 2, 3)."""
    points = np.vstack([UNIT_TET, [[1.0, 1.0, 1.0]]])
    cells = np.array([[0, 1, 2, 3], [4, 3, 2, 1]])
    assert np.all(signed_volumes(Mesh(points, cells, "tetra")) > 0)
    return points, cells


def test_valid_meshes_are_accepted():
    points, cells = two_tets()
    m = Mesh(points, cells, "tetra")
    assert m.num_cells == 2 and m.num_points == 5 and m.tdim == 3
    np.testing.assert_allclose(m.cell_measures(), [1 / 6, 1 / 3], rtol=1e-15)


def test_inverted_tet_is_rejected():
    points, cells = two_tets()
    cells = cells.copy()
    cells[1, [0, 1]] = cells[1, [1, 0]]  # swap two vertices
    with pytest.raises(MeshError, match=r"cell 1 is inverted"):
        Mesh(points, cells, "tetra")


def test_inverted_hex_is_rejected():
    m = box_hexahedra((2, 1, 1))
    cells = m.cells.copy()
    cells[1] = cells[1][[4, 5, 6, 7, 0, 1, 2, 3]]  # mirrored: top and bottom swapped
    with pytest.raises(MeshError, match=r"cell 1 is inverted"):
        Mesh(m.points, cells, "hexahedron")


def test_flat_tet_is_rejected():
    points, cells = two_tets()
    points = points.copy()
    points[4] = [0.3, 0.3, 0.4]  # on the plane x + y + z = 1 of the shared face: zero volume
    with pytest.raises(MeshError, match=r"cell 1 is degenerate"):
        Mesh(points, cells, "tetra")


def test_repeated_vertex_is_rejected():
    points, cells = two_tets()
    cells = cells.copy()
    cells[0, 3] = cells[0, 1]
    with pytest.raises(MeshError, match=r"cell 0 repeats a vertex"):
        Mesh(points, cells, "tetra")


@pytest.mark.parametrize("bad_index", [5, -1])
def test_index_out_of_range_is_rejected(bad_index):
    points, cells = two_tets()
    cells = cells.copy()
    cells[1, 0] = bad_index
    with pytest.raises(MeshError, match=r"out of range"):
        Mesh(points, cells, "tetra")


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_coordinates_are_rejected(value):
    points, cells = two_tets()
    points = points.copy()
    points[3, 1] = value
    with pytest.raises(MeshError, match=r"point 3 has a non-finite coordinate"):
        Mesh(points, cells, "tetra")


def test_coordinates_that_overflow_the_transfers_are_rejected_as_such():
    """A mesh at 1e300 was reported as 'do not overlap' its partner, one at 1e60-1e100 transferred a
    linear field with errors of order one and no word; within the limit the transfer stays exact."""
    src, dst = box_tetrahedra((3, 3, 3), jitter=0.2, seed=4), box_hexahedra((4, 4, 4))
    for scale in (1e60, 1e300):
        with pytest.raises(MeshError, match=re.escape(f"big: coordinates up to {scale:.3g} in magnitude overflow "
                                                      f"double precision") + r".* \(at most 1e\+50\); give the "
                                                                              r"geometry in other units"):
            Mesh(src.points * scale, src.cells, "tetra", name="big")
        with pytest.raises(MeshError, match="grid: coordinates up to .* overflow double precision"):
            StructuredGrid([0, 0, 0], [scale, scale, scale], [2, 2, 2])
    scale = transfer.mesh.COORDINATE_LIMIT / 2
    a = Mesh(src.points * scale, src.cells, "tetra")
    b = Mesh(dst.points * scale, dst.cells, "hexahedron")
    u = 1 + src.points @ [1.0, -2.0, 3.0]
    v = transfer.Transfer.assemble(FunctionSpace(a, "P1"), FunctionSpace(b, "Q1"), "l2")(u)
    assert np.max(np.abs(v - (1 + dst.points @ [1.0, -2.0, 3.0]))) < 1e-12


def test_mesh_error_names_the_mesh():
    points, cells = two_tets()
    with pytest.raises(MeshError, match=r"^solid\.msh: .*inverted"):
        Mesh(points, cells[:, [1, 0, 2, 3]], "tetra", name="solid.msh")


def test_bad_shapes_and_types_are_rejected():
    points, cells = two_tets()
    with pytest.raises(MeshError, match="vertices"):
        Mesh(points, cells[:, :3], "tetra")
    with pytest.raises(MeshError, match="unsupported cell type"):
        Mesh(points, cells, "pyramid")
    with pytest.raises(MeshError, match="no cells"):
        Mesh(points, np.zeros((0, 4), int), "tetra")
    with pytest.raises(MeshError, match="shape"):
        Mesh(points[:, :1], cells, "tetra")
    assert issubclass(MeshError, transfer.TransferError) and issubclass(MeshError, ValueError)


@pytest.mark.parametrize("scale", [1e-6, 1e-3, 1.0, 1e3, 1e6])
def test_validation_is_scale_invariant(scale):
    """A valid jittered mesh is valid at any unit; a flat cell is flat at any unit."""
    m = box_tetrahedra((2, 2, 2), jitter=0.2, seed=7)
    scaled = Mesh(m.points * scale, m.cells, "tetra")
    np.testing.assert_allclose(scaled.cell_measures().sum(), scale**3, rtol=1e-12)
    points, cells = two_tets()
    points = points.copy() * scale
    points[4] = np.array([0.3, 0.3, 0.4]) * scale
    with pytest.raises(MeshError, match="degenerate"):
        Mesh(points, cells, "tetra")


def test_nearly_flat_but_valid_tet_is_accepted():
    """Relative volume 1e-6 is a (bad) cell, not a degenerate one."""
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1e-6]])
    m = Mesh(points, [[0, 1, 2, 3]], "tetra")
    np.testing.assert_allclose(m.cell_measures(), [1e-6 / 6], rtol=1e-9)


def test_two_dimensional_points_are_padded():
    m = Mesh([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]], "triangle")
    assert m.points.shape == (3, 3) and np.all(m.points[:, 2] == 0)
    np.testing.assert_allclose(m.cell_measures(), [0.5])


@pytest.mark.parametrize("shape", [(2, 3, 2), (3, 1, 2)])
def test_generated_boxes_are_valid_and_fill_the_box(shape):
    lower, upper = np.array([-1.0, 0.5, 2.0]), np.array([1.0, 2.0, 2.5])
    vol = np.prod(upper - lower)
    t = box_tetrahedra(shape, lower, upper, jitter=0.24, seed=3)
    h = box_hexahedra(shape, lower, upper, jitter=0.24, seed=3)
    assert t.num_cells == 6 * np.prod(shape) and h.num_cells == np.prod(shape)
    np.testing.assert_allclose(t.cell_measures().sum(), vol, rtol=1e-13)
    np.testing.assert_allclose(h.cell_measures().sum(), vol, rtol=1e-13)
    assert np.all(signed_volumes(t) > 0)
    lo, hi = t.bounding_box()
    np.testing.assert_allclose(lo, lower, atol=1e-15)
    np.testing.assert_allclose(hi, upper, atol=1e-15)


# -- meshio ------------------------------------------------------------------
def test_from_meshio_tetra():
    m = box_tetrahedra((2, 2, 2), jitter=0.1, seed=1)
    mio = meshio.Mesh(m.points, [("tetra", m.cells)])
    back = Mesh.from_meshio(mio, name="in.vtu")
    assert back.cell_type == "tetra" and back.name == "in.vtu"
    np.testing.assert_array_equal(back.cells, m.cells)
    np.testing.assert_array_equal(back.points, m.points)


def test_from_meshio_picks_the_volume_cells_and_joins_blocks():
    m = box_tetrahedra((2, 2, 1), jitter=0.1, seed=1)
    half = m.num_cells // 2
    mio = meshio.Mesh(m.points, [("vertex", np.array([[0]])), ("triangle", np.array([[0, 1, 3]])),
                                 ("tetra", m.cells[:half]), ("tetra", m.cells[half:])])
    back = Mesh.from_meshio(mio)
    assert back.cell_type == "tetra"
    np.testing.assert_array_equal(back.cells, m.cells)
    tri = Mesh.from_meshio(mio, cell_type="triangle")
    assert tri.cell_type == "triangle" and tri.num_cells == 1


def test_from_meshio_validates_and_round_trips_files(tmp_path):
    m = box_tetrahedra((2, 1, 1), jitter=0.1, seed=2)
    path = tmp_path / "m.vtu"
    m.to_meshio().write(path)
    back = Mesh.from_meshio(meshio.read(path))
    np.testing.assert_allclose(back.points, m.points)
    np.testing.assert_array_equal(back.cells, m.cells)
    mirrored = meshio.Mesh(m.points, [("tetra", m.cells[:, [1, 0, 2, 3]])])
    back = Mesh.from_meshio(mirrored)  # a file's orientation is a convention: reordered, not rejected
    assert back.reoriented == back.num_cells == 12 and np.all(signed_volumes(back) > 0)
    with pytest.raises(MeshError, match="inverted"):
        Mesh.from_meshio(mirrored, reorient=False)
    with pytest.raises(MeshError, match="no tetra, hexahedron"):
        Mesh.from_meshio(meshio.Mesh(m.points, [("line", np.array([[0, 1]]))]))


# -- function spaces ---------------------------------------------------------
def test_space_family_must_fit_the_cells():
    hexes = box_hexahedra((1, 1, 1))
    tets = box_tetrahedra((1, 1, 1))
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (1, 1, 1))
    for mesh, family in [(hexes, "P1"), (hexes, "P0"), (grid, "P1"), (tets, "Q1"), (tets, "Q0")]:
        with pytest.raises(SpaceError, match="is defined on"):
            FunctionSpace(mesh, family)
    with pytest.raises(SpaceError, match="unknown family"):
        FunctionSpace(tets, "P2")
    assert FunctionSpace(hexes, "Q1").num_dofs == 8 and FunctionSpace(tets, "P0").num_dofs == 6


@pytest.mark.parametrize("family", ["P1", "P0"])
def test_simplex_mass_matrix_integrates_polynomials(family):
    """1^T M 1 = volume; for P1, u^T M v = int u v for affine u, v (checked with an
    independent rule on every tet)."""
    from vc_helpers import tet_rule

    m = box_tetrahedra((2, 3, 2), jitter=0.2, seed=5)
    V = FunctionSpace(m, family)
    M = V.mass_matrix()
    one = np.ones(V.num_dofs)
    np.testing.assert_allclose(one @ M @ one, 1.0, rtol=1e-13)
    assert abs(M - M.T).max() <= 1e-15 * abs(M).max()
    if family == "P1":
        u = lambda x: 1 + x @ [1.0, -2.0, 0.5]
        v = lambda x: -3 + x @ [0.2, 0.7, 1.5]
        x, w = tet_rule(4)
        p = m.points[m.cells]
        phys = p[:, :1] + np.einsum("qe,med->mqd", x, p[:, 1:] - p[:, :1])
        det = np.abs(np.linalg.det(p[:, 1:] - p[:, :1]))
        exact = np.sum(det[:, None] * w * (u(phys) * v(phys)))
        np.testing.assert_allclose(V.interpolate(u) @ M @ V.interpolate(v), exact, rtol=1e-13)


def test_q1_mass_matrix_of_distorted_hexes_has_the_trilinear_volume():
    """Sum of the Q1 mass matrix = the volume of the trilinear cells; on a box mesh
    (planar boundary) that is the box volume."""
    m = box_hexahedra((2, 2, 3), jitter=0.24, seed=9)
    M = FunctionSpace(m, "Q1").mass_matrix()
    np.testing.assert_allclose(M.sum(), 1.0, rtol=1e-13)
    assert np.all(np.linalg.eigvalsh(M.toarray()) > 0)


def test_bounding_box_of_the_used_points_computed_once():
    """Points no cell uses are outside the box; the box is cached (Transfer.assemble asks
    for it several times), and what a caller does to the arrays returned stays its own."""
    t = box_tetrahedra((2, 2, 2), jitter=0.1, seed=1)
    far = Mesh(np.vstack([t.points, [[5.0, -7.0, 9.0]]]), t.cells, "tetra")
    lo, hi = far.bounding_box()
    np.testing.assert_array_equal(lo, [0, 0, 0])
    np.testing.assert_array_equal(hi, [1, 1, 1])
    lo[:] = -1.0
    np.testing.assert_array_equal(far.bounding_box()[0], [0, 0, 0])
    assert "box" in far._cache
    np.testing.assert_array_equal(far.cell_measures(), np.abs(far.cell_measures(signed=True)))


def test_tet_shapes_equal_the_numpy_versions_bit_for_bit():
    """Mesh validation takes a tet mesh's longest edges and signed volumes from the kernel
    (one pass) and a hex mesh's from numpy: the two give the same values."""
    from transfer import _kernels
    from transfer.mesh import _longest_edges, _signed_tet_volumes

    mesh = box_tetrahedra((7, 6, 5), (1e4, -3.0, 0.0), (1e4 + 3.0, 0.5, 2.0), jitter=0.2, seed=4)
    cells = mesh.cells[:, [0, 2, 1, 3]]  # negative volumes too
    longest, volumes = _kernels.tet_shapes(mesh.points, cells)
    p = mesh.points[cells]
    assert np.array_equal(longest, _longest_edges(p))
    assert np.array_equal(volumes, _signed_tet_volumes(p))
    assert (volumes < 0).all()
    assert np.array_equal(mesh.cell_measures(signed=True), _signed_tet_volumes(mesh.points[mesh.cells]))
