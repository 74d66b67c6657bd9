"""Volume -> surface transfer: the trace of a volume field (tets, hexahedra,
structured grid) on a surface inside the volume (triangles, quads), e.g. the
fluid pressure on fracture faces (paper 2.3, Steps 2-3)."""

import numpy as np
import pytest

from transfer import FunctionSpace, NoOverlapError, StructuredGrid, Transfer, TransferError
from transfer.generate import box_hexahedra, box_tetrahedra, rectangle

METHODS = ["l2", "pseudo_l2"]


def linear(x):
    return 1 + 2 * x[:, 0] - 3 * x[:, 1] + 0.5 * x[:, 2]


def tilted(cell_type, shape=(7, 6), jitter=0.2):
    return rectangle(shape, lower=(0.1, 0.1), upper=(0.9, 0.9), cell_type=cell_type, jitter=jitter, seed=2,
                     height=lambda x, y: 0.3 + 0.2 * x + 0.1 * y)


VOLUMES = {
    "tets": lambda: FunctionSpace(box_tetrahedra((5, 5, 5), jitter=0.2, seed=1), "P1"),
    "grid": lambda: FunctionSpace(StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (6, 6, 6)), "Q1"),
    "hexes": lambda: FunctionSpace(box_hexahedra((4, 4, 4), jitter=0.15, seed=3), "Q1"),
}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("surface", ["triangle", "quad"])
@pytest.mark.parametrize("volume", VOLUMES)
def test_linear_fields_are_traced_exactly(volume, surface, method):
    S = VOLUMES[volume]()
    W = FunctionSpace(tilted(surface, jitter=0.2 if surface == "triangle" else 0.0),
                      "P1" if surface == "triangle" else "Q1")
    T = Transfer.assemble(S, W, method)
    assert T.covered_fraction == 1.0
    exact = W.interpolate(linear)
    assert np.abs(T(S.interpolate(linear)) - exact).max() <= 1e-12 * np.abs(exact).max()
    # the coupling matrix integrates over the whole surface exactly once
    np.testing.assert_allclose(T.B.sum(), W.mesh.cell_measures().sum(), rtol=1e-13)


@pytest.mark.parametrize("volume", ["grid", "tets"])
def test_a_surface_in_the_faces_of_the_volume_cells_is_counted_once(volume):
    """z = 0.5 is a plane of grid faces (and of lattice faces of the tets, whose
    jitter keeps boundary-plane vertices but moves interior ones)."""
    S = VOLUMES[volume]()
    flat = rectangle((5, 5), lower=(0.05, 0.05), upper=(0.95, 0.95), jitter=0.2, seed=4,
                     height=lambda x, y: 0 * x + 0.5)
    W = FunctionSpace(flat, "P1")
    T = Transfer.assemble(S, W, "l2")
    np.testing.assert_allclose(T.B.sum(), flat.cell_measures().sum(), rtol=1e-13)
    assert np.abs(T(S.interpolate(linear)) - W.interpolate(linear)).max() < 1e-12


@pytest.mark.parametrize("z", [0.0, 1.0])
@pytest.mark.parametrize("volume", VOLUMES)
def test_a_surface_on_the_boundary_of_the_volume_is_covered(volume, z):
    """On the outer faces of the volume mesh the only cell there owns the piece."""
    S = VOLUMES[volume]()
    flat = rectangle((3, 3), lower=(0.1, 0.1), upper=(0.9, 0.9), jitter=0.2, seed=1, height=lambda x, y: 0 * x + z)
    W = FunctionSpace(flat, "P1")
    T = Transfer.assemble(S, W, "l2")
    assert T.covered_fraction == 1.0
    np.testing.assert_allclose(T.B.sum(), flat.cell_measures().sum(), rtol=1e-13)


@pytest.mark.parametrize("volume", ["tets", "hexes"])
def test_a_surface_in_the_inner_faces_of_split_cells_is_counted_once(volume):
    """The plane x = y holds faces between the tets of each lattice cube (and of
    the six tets the kernels cut a hexahedron into)."""
    from transfer import Mesh

    S = FunctionSpace((box_tetrahedra if volume == "tets" else box_hexahedra)((3, 3, 3)), "P1" if volume == "tets" else "Q1")
    sheet = rectangle((4, 4), lower=(0.05, 0.1), upper=(0.95, 0.9))
    points = np.column_stack([sheet.points[:, 0], sheet.points[:, 0], sheet.points[:, 1]])
    W = FunctionSpace(Mesh(points, sheet.cells, "triangle"), "P1")
    T = Transfer.assemble(S, W, "l2")
    np.testing.assert_allclose(T.B.sum(), W.mesh.cell_measures().sum(), rtol=1e-13)
    assert np.abs(T(S.interpolate(linear)) - W.interpolate(linear)).max() < 1e-12


def test_grid_faces_exactly_on_a_cell_face_q0():
    """Q0 (cell values, like OpenFOAM's): a surface on the plane between two cell
    layers takes the values of one layer, never the sum of both."""
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (4, 4, 4))
    Q0 = FunctionSpace(grid, "Q0")
    flat = FunctionSpace(rectangle((3, 3), lower=(0.1, 0.1), upper=(0.9, 0.9), height=lambda x, y: 0 * x + 0.5), "P1")
    T = Transfer.assemble(Q0, flat, "pseudo_l2")
    np.testing.assert_allclose(T(np.full(Q0.num_dofs, 7.0)), 7.0, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(T.B.sum(axis=1)).ravel(), T.D.diagonal(), rtol=1e-13)


@pytest.mark.parametrize("method", METHODS)
def test_conservation_and_partial_coverage(method):
    """A surface sticking out of the volume: the part outside is uncovered (NaN),
    and the integral of the traced field equals that of the volume field over the
    covered part of the surface."""
    S = FunctionSpace(box_tetrahedra((4, 4, 4), upper=(0.6, 1, 1), jitter=0.2, seed=5), "P1")
    flat = rectangle((8, 4), lower=(0.05, 0.1), upper=(0.95, 0.9), height=lambda x, y: 0 * x + 0.37)
    W = FunctionSpace(flat, "P1")
    T = Transfer.assemble(S, W, method)
    assert 0 < T.covered_fraction < 1
    v = T(S.interpolate(linear))
    assert np.isnan(v[~T.covered]).all() and np.isfinite(v[T.covered]).all()
    # int over [0.05, 0.6] x [0.1, 0.9] at z = 0.37 of the linear field, exactly
    x0, x1, y0, y1, z = 0.05, 0.6, 0.1, 0.9, 0.37
    exact = (x1 - x0) * (y1 - y0) * (1 + (x0 + x1) - 1.5 * (y0 + y1) + 0.5 * z)
    np.testing.assert_allclose(T.integral_target(v), exact, rtol=1e-12)
    np.testing.assert_allclose(T.integral_source(S.interpolate(linear)), exact, rtol=1e-12)


def test_curved_surface_reproduces_constants_and_area():
    S = FunctionSpace(box_tetrahedra((6, 6, 6), jitter=0.2, seed=6), "P1")
    bump = rectangle((16, 16), lower=(0.1, 0.1), upper=(0.9, 0.9), jitter=0.1, seed=7,
                     height=lambda x, y: 0.5 + 0.1 * np.sin(2 * np.pi * x))
    W = FunctionSpace(bump, "P1")
    for method in METHODS:
        T = Transfer.assemble(S, W, method)
        np.testing.assert_allclose(T(np.ones(S.num_dofs)), 1.0, rtol=1e-13)
        np.testing.assert_allclose(T.B.sum(), bump.cell_measures().sum(), rtol=1e-12)


def test_disjoint_and_reversed_dimensions_are_clear_errors():
    S = FunctionSpace(box_tetrahedra((2, 2, 2)), "P1")
    far = FunctionSpace(rectangle((2, 2), height=lambda x, y: 0 * x + 5.0), "P1")
    with pytest.raises(NoOverlapError, match="do not overlap"):
        Transfer.assemble(S, far, "l2")
    with pytest.raises(TransferError, match="surface field cannot be projected onto a volume"):
        Transfer.assemble(far, S, "l2")


@pytest.mark.parametrize("method", METHODS)
def test_piecewise_constant_sources_keep_the_target_mass_exact(method):
    """Q0/P0 sources with P1/Q1 targets: the default quadrature must integrate the
    target mass (degree 2 p) too, not only source x target; with a one-point rule
    a triangle inside one cell had a rank-one mass and a garbage dual basis."""
    from transfer.generate import box_hexahedra

    grid = StructuredGrid.from_bounds((0, 0, -0.001), (0.05, 0.025, 0.001), (20, 10, 21))
    surf = rectangle((20, 10), upper=(0.05, 0.025), height=lambda x, y: 2e-4 * np.sin(300 * x) * np.cos(200 * y))
    cases = [(FunctionSpace(grid, "Q0"), FunctionSpace(surf, "P1")),
             (FunctionSpace(rectangle((5, 5), jitter=0.2, seed=1), "P0"),
              FunctionSpace(rectangle((4, 6), jitter=0.2, seed=2), "P1")),
             (FunctionSpace(StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (3, 3, 3)), "Q0"),
              FunctionSpace(box_hexahedra((4, 4, 4)), "Q1"))]
    for S, W in cases:
        T = Transfer.assemble(S, W, method)
        np.testing.assert_allclose(T.B.sum(), W.mesh.cell_measures().sum(), rtol=1e-12)
        np.testing.assert_allclose(T(np.full(S.num_dofs, 3.0)), 3.0, rtol=1e-12)
        M = W.mass_matrix()
        np.testing.assert_allclose(np.asarray(T.D.sum(axis=1)).ravel(), np.asarray(M.sum(axis=1)).ravel(), rtol=1e-12)
