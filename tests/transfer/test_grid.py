"""StructuredGrid: numbering, point location, agreement with box_hexahedra."""

import numpy as np
import pytest

from transfer import FunctionSpace, MeshError, StructuredGrid
from transfer.generate import box_hexahedra

LOWER, UPPER, SHAPE = np.array([-1.0, 0.5, 2.0]), np.array([2.0, 1.5, 4.0]), (3, 2, 4)


@pytest.fixture
def g():
    return StructuredGrid.from_bounds(LOWER, UPPER, SHAPE)


def contains(grid, cell_ids, x, tol=1e-12):
    p = grid.points[grid.cells[cell_ids]]
    lo, hi = p.min(axis=1), p.max(axis=1)
    return np.all((lo - tol <= x) & (x <= hi + tol), axis=1)


def test_points_and_cells_match_box_hexahedra(g):
    box = box_hexahedra(SHAPE, LOWER, UPPER)
    np.testing.assert_allclose(g.points, box.points, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(g.cells, box.cells)
    assert g.num_cells == box.num_cells == 24 and g.num_points == box.num_points == 60
    lo, hi = g.bounding_box()
    np.testing.assert_allclose(lo, LOWER)
    np.testing.assert_allclose(hi, UPPER)


def test_numbering_is_x_fastest(g):
    nx, ny, _ = SHAPE
    i, j, k = 2, 1, 3
    c = i + nx * (j + ny * k)
    np.testing.assert_allclose(g.points[g.cells[c][0]], LOWER + g.spacing * [i, j, k])
    np.testing.assert_allclose(g.points[g.cells[c][6]], LOWER + g.spacing * [i + 1, j + 1, k + 1])
    np.testing.assert_allclose(g.cell_centers()[c], LOWER + g.spacing * [i + 0.5, j + 0.5, k + 0.5])


def test_grid_is_a_valid_hexahedral_mesh(g):
    m = g.to_mesh()
    assert m.cell_type == "hexahedron"
    np.testing.assert_allclose(m.cell_measures(), g.cell_measures(), rtol=1e-13)
    np.testing.assert_allclose(g.cell_measures().sum(), np.prod(UPPER - LOWER), rtol=1e-14)
    Mg = FunctionSpace(g, "Q1").mass_matrix()
    Mm = FunctionSpace(m, "Q1").mass_matrix()
    assert abs(Mg - Mm).max() <= 1e-14 * abs(Mm).max()
    np.testing.assert_allclose(Mg.sum(), np.prod(UPPER - LOWER), rtol=1e-13)


def test_locate_random_points(g, rng):
    x = rng.uniform(LOWER, UPPER, (2000, 3))
    ids = g.locate(x)
    assert np.all(ids >= 0)
    assert np.all(contains(g, ids, x))
    # and cell centres locate to their own cell
    np.testing.assert_array_equal(g.locate(g.cell_centers()), np.arange(g.num_cells))


def test_locate_outside_is_minus_one(g, rng):
    x = rng.uniform(LOWER, UPPER, (600, 3))
    ext = UPPER - LOWER
    for d in range(3):
        below, above = x[:100].copy(), x[100:200].copy()
        below[:, d] = LOWER[d] - rng.uniform(1e-9, 1.0, 100) * ext[d]
        above[:, d] = UPPER[d] + rng.uniform(1e-9, 1.0, 100) * ext[d]
        assert np.all(g.locate(below) == -1)
        assert np.all(g.locate(above) == -1)


def test_locate_on_faces(g):
    # the upper boundary belongs to the last cells, the lower one to the first
    assert g.locate(UPPER)[0] == g.num_cells - 1
    assert g.locate(LOWER)[0] == 0
    # points on interior faces land in a cell that contains them
    x = LOWER + g.spacing * np.array([[1.0, 0.5, 0.5], [2.0, 1.0, 3.0], [0.25, 1.0, 2.0]])
    ids = g.locate(x)
    assert np.all(ids >= 0) and np.all(contains(g, ids, x))
    # a single point gives a length-1 array
    assert g.locate([0.0, 1.0, 3.0]).shape == (1,)


def test_grid_rejects_bad_parameters():
    with pytest.raises(MeshError, match="spacing must be positive"):
        StructuredGrid((0, 0, 0), (1, 0, 1), (1, 1, 1))
    with pytest.raises(MeshError, match="at least 1 cell"):
        StructuredGrid((0, 0, 0), (1, 1, 1), (1, 0, 1))
    with pytest.raises(MeshError, match="finite"):
        StructuredGrid((0, np.nan, 0), (1, 1, 1), (1, 1, 1))
