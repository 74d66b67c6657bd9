"""The volume kernel's rejection of candidate pairs (source boxes and vertices outside a
face plane of the target tet, target vertices outside a face plane of the source tet)
never drops an intersecting pair: with the tests on and off (every candidate clipped),
the same pairs intersect and B, D and the overlaps agree, on jittered meshes and on
touching configurations (shared faces, shared edges, coplanar faces, identical meshes)."""

import numpy as np
import pytest

from transfer import FunctionSpace, StructuredGrid, _kernels
from transfer.assembly import _kind, integration_rule
from transfer.generate import box_hexahedra, box_tetrahedra

#: relative agreement of the matrices with and without the rejection tests
RTOL = 1e-14


def kernel(source: FunctionSpace, target: FunctionSpace, reject: bool, quadrature_degree=None, stages=5):
    """assemble_volume on the two spaces (l2), with or without the rejection tests."""
    rule = integration_rule(source, target, quadrature_degree)
    smesh, tmesh = source.mesh, target.mesh
    grid = None
    if isinstance(smesh, StructuredGrid):
        grid = (tuple(smesh.origin), tuple(smesh.spacing), tuple(smesh.shape))
    return _kernels.assemble_volume(smesh.points, smesh.cells, _kind(smesh), source.degree, tmesh.points,
                                    tmesh.cells, _kind(tmesh), target.degree, rule.bary, rule.weights, False, False,
                                    source.num_dofs, target.num_dofs, grid, 1, stages=stages, reject=reject)


def assert_same(source, target, **kwargs):
    on, off = kernel(source, target, True, **kwargs), kernel(source, target, False, **kwargs)
    assert on["pairs_tested"] == off["pairs_tested"]
    assert on["pairs_intersected"] == off["pairs_intersected"]
    for name in ("B", "D"):
        (p1, i1, v1), (p0, i0, v0) = on[name], off[name]
        np.testing.assert_array_equal(p1, p0, err_msg=f"{name}: rows differ")
        np.testing.assert_array_equal(i1, i0, err_msg=f"{name}: columns differ")
        scale = max(np.abs(v0).max(initial=0.0), np.finfo(float).tiny)
        assert np.abs(v1 - v0).max(initial=0.0) <= RTOL * scale, name
    np.testing.assert_allclose(on["overlap"], off["overlap"], rtol=RTOL, atol=RTOL * on["measure"].max())
    return on


def tets(shape, lower=(0, 0, 0), upper=(1, 1, 1), jitter=0.0, seed=0):
    return box_tetrahedra(shape, lower, upper, jitter=jitter, seed=seed)


@pytest.mark.parametrize("families, degree", [(("P1", "P1"), None), (("P0", "P1"), None), (("P1", "P0"), None),
                                              (("P1", "P1"), 2)])
def test_jittered_meshes(families, degree):
    src, dst = tets((5, 5, 5), jitter=0.2, seed=1), tets((6, 6, 6), jitter=0.2, seed=2)
    out = assert_same(FunctionSpace(src, families[0]), FunctionSpace(dst, families[1]), quadrature_degree=degree)
    assert 0 < out["pairs_intersected"] < out["pairs_tested"]
    np.testing.assert_allclose(out["overlap"].sum(), 1.0, rtol=1e-13)


def test_a_rule_inexact_on_products_clips_the_source():
    """With exact (moment) integration a tet-tet pair may clip the target tet by the source's
    faces when fewer of them cut it (the same intersection); a rule of degree 1 is not exact
    on products of P1 bases and depends on how the intersection is cut into tets, so there
    the source is clipped, as without the rejection tests."""
    src, dst = tets((5, 5, 5), jitter=0.2, seed=1), tets((6, 6, 6), jitter=0.2, seed=2)
    assert_same(FunctionSpace(src, "P1"), FunctionSpace(dst, "P1"), quadrature_degree=1)


def test_identical_meshes_share_every_face():
    mesh = tets((3, 3, 3), jitter=0.2, seed=4)
    out = assert_same(FunctionSpace(mesh, "P1"), FunctionSpace(mesh, "P1"))
    assert out["pairs_intersected"] == mesh.num_cells  # each tet meets only itself in volume


@pytest.mark.parametrize("shift, what", [((1, 0, 0), "shared face"), ((1, 1, 0), "shared edge"),
                                         ((1, 1, 1), "shared corner")])
def test_meshes_touching_without_overlap(shift, what):
    src = tets((3, 3, 3))
    dst = tets((4, 4, 4), lower=shift, upper=np.add(shift, 1))
    out = assert_same(FunctionSpace(src, "P1"), FunctionSpace(dst, "P1"))
    assert out["pairs_tested"] > 0, what  # the boxes touch: candidates, none of volume
    assert out["pairs_intersected"] == 0, what
    assert len(out["B"][2]) == 0 and not out["overlap"].any(), what


def test_coplanar_faces_of_different_meshes():
    """Lattices of 2 and 4 cells per axis: the planes x, y, z = 0.5 and the boundary hold
    faces of both, source faces lying in target faces and cutting across them."""
    out = assert_same(FunctionSpace(tets((2, 2, 2)), "P1"), FunctionSpace(tets((4, 4, 4)), "P1"))
    np.testing.assert_allclose(out["overlap"].sum(), 1.0, rtol=1e-13)


def test_half_overlapping_meshes():
    src, dst = tets((4, 4, 4), jitter=0.1, seed=5), tets((5, 5, 5), lower=(0.5, 0, 0), upper=(1.5, 1, 1))
    out = assert_same(FunctionSpace(src, "P1"), FunctionSpace(dst, "P1"))
    np.testing.assert_allclose(out["overlap"].sum(), 0.5, rtol=1e-12)


def test_hexahedra_and_grids():
    hexes = box_hexahedra((3, 3, 3), jitter=0.15, seed=6)
    mesh = tets((4, 4, 4), jitter=0.2, seed=7)
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (5, 5, 5))
    for source, target in [(FunctionSpace(hexes, "Q1"), FunctionSpace(mesh, "P1")),
                           (FunctionSpace(mesh, "P1"), FunctionSpace(hexes, "Q1")),
                           (FunctionSpace(grid, "Q1"), FunctionSpace(mesh, "P1")),
                           (FunctionSpace(mesh, "P1"), FunctionSpace(grid, "Q1"))]:
        out = assert_same(source, target)
        np.testing.assert_allclose(out["overlap"].sum(), 1.0, rtol=1e-12)


def test_stages_stop_early():
    """Benchmarks split the kernel's time by stopping it: before the integration nothing
    intersects, at the integration (4) every pair is found but no row is written."""
    S, T = FunctionSpace(tets((3, 3, 3), jitter=0.2, seed=1), "P1"), FunctionSpace(tets((4, 4, 4)), "P1")
    full = kernel(S, T, True)
    for stage in (1, 2, 3, 4):
        out = kernel(S, T, True, stages=stage)
        assert out["pairs_tested"] == full["pairs_tested"]
        assert out["pairs_intersected"] == (full["pairs_intersected"] if stage == 4 else 0)
        assert len(out["B"][2]) == 0
