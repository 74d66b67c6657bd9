"""solid_fenicsx.vertex_io and output: arrays for the coupler in input numbering,
field scatter/gather, XDMF and VTU files."""

from __future__ import annotations

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")
pytest.importorskip("dolfinx")

from mpi4py import MPI  # noqa: E402

from solid_fenicsx import Elasticity, VTUSeries, XDMFSeries, box_mesh, from_arrays  # noqa: E402
from transfer.generators.lattice import box_arrays  # noqa: E402

ROOT = MPI.COMM_WORLD.rank == 0


@pytest.fixture(scope="module")
def jittered():
    """A jittered box (so numbering mistakes cannot hide behind symmetry)."""
    points, cells = box_arrays([np.linspace(0, 1, 5), np.linspace(0, 2, 4), np.linspace(0, 1, 3)])
    rng = np.random.default_rng(7)
    inner = np.all((points > 1e-9) & (points < np.array([1, 2, 1]) - 1e-9), axis=1)
    points[inner] += rng.uniform(-0.05, 0.05, (inner.sum(), 3))
    faces = {"top": lambda x: np.isclose(x[2], 1.0), "bottom": lambda x: np.isclose(x[2], 0.0)}
    return points, cells, from_arrays(points, cells, boundaries=faces)


def test_geometry_arrays_in_input_numbering(jittered):
    points, cells, solid = jittered
    s = Elasticity(solid, E=1e9, nu=0.3)
    vio = s.vertices
    pts, tets = vio.points(), vio.tetrahedra()
    boundary = vio.boundary_triangles()
    top = vio.boundary_triangles("top")
    if not ROOT:
        assert pts is None and tets is None and boundary is None and top is None
        return
    tris, tags = boundary
    assert np.array_equal(pts, points) and np.array_equal(tets, cells)
    assert len(tris) == 2 * (4 * 3 + 4 * 2 + 3 * 2) * 2
    assert np.count_nonzero(tags == solid.boundaries["top"]) == 2 * 4 * 3 == len(top[0])
    assert set(np.unique(tags)) == {0, solid.boundaries["top"], solid.boundaries["bottom"]}
    # outward orientation: normals point away from the box centre, areas add up
    p = pts[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, p.mean(axis=1) - [0.5, 1.0, 0.5]) > 0)
    assert np.isclose(0.5 * np.linalg.norm(n, axis=1).sum(), 2 * (2 + 1 + 2))


def test_scatter_gather_round_trip(jittered):
    points, cells, solid = jittered
    s = Elasticity(solid, E=1e9, nu=0.3, degree=2)
    f = s.add_traction_field("top", name="t")
    values = np.column_stack([points[:, 0], points[:, 1] ** 2, -points[:, 2]])
    s.set_vertex_field("t", values if ROOT else None)
    back = s.vertices.gather(f)
    # the same with every rank passing the full array, gathered on all ranks
    s.vertices.scatter(f, values, root=None)
    everywhere = s.vertices.gather(f, root=None)
    assert np.array_equal(everywhere, values)
    # a P2 field is gathered through its vertex values
    s.u.interpolate(lambda x: np.stack([x[0] * x[1], x[2], x[0] + 1.0]))
    u = s.vertex_values("displacement")
    if ROOT:
        assert np.array_equal(back, values)
        assert np.allclose(u, np.column_stack([points[:, 0] * points[:, 1], points[:, 2], points[:, 0] + 1]))
    with pytest.raises(ValueError, match="vertex values"):
        s.vertices.scatter(f, np.zeros(3), root=None)


def test_xdmf_and_vtu_series(tmp_path_factory):
    out = MPI.COMM_WORLD.bcast(str(tmp_path_factory.mktemp("out")) if ROOT else None, root=0)
    solid = box_mesh(shape=(2, 2, 2))
    s = Elasticity(solid, E=1e9, nu=0.3, density=1000.0, degree=2, scheme="newmark", dt=1e-4, solver="lu")
    s.add_dirichlet("zmin", 0.0)
    s.add_pressure("zmax", 1e5)
    vtu = VTUSeries(f"{out}/vtu", s)
    with XDMFSeries(f"{out}/solid.xdmf", s) as xdmf:
        for _ in range(2):
            s.step()
            xdmf.write()
            vtu.write()
    MPI.COMM_WORLD.barrier()
    if ROOT:
        m = meshio.read(f"{out}/vtu/solid_00001.vtu")
        assert set(m.point_data) == {"displacement", "velocity"} and "von_mises" in m.cell_data
        assert m.points.shape == (27, 3) and m.cells[0].data.shape == (48, 4)
        assert np.abs(m.point_data["displacement"][:, 2]).max() > 0
        assert "solid_00001.vtu" in open(f"{out}/vtu/solid.pvd").read()
        text = open(f"{out}/solid.xdmf").read()
        assert all(name in text for name in ("displacement", "velocity", "von_mises"))


def test_scatter_on_boundary_vertices_only(jittered):
    points, cells, solid = jittered
    s = Elasticity(solid, E=1e9, nu=0.3)
    p = s.add_pressure_field("top", name="p")
    ids = s.vertices.boundary_vertices("top")
    if ROOT:
        assert np.allclose(points[ids, 2], 1.0) and len(ids) == 5 * 4
    s.vertices.scatter(p, 2.0 + points[ids, 0] if ROOT else None, vertex_ids=ids)
    full = s.vertices.gather(p)
    if ROOT:
        expected = np.where(np.isclose(points[:, 2], 1.0), 2.0 + points[:, 0], 0.0)
        assert np.array_equal(full, expected)
    p2 = Elasticity(solid, E=1e9, nu=0.3, degree=2)
    with pytest.raises(ValueError, match="P1"):
        p2.vertices.scatter(p2.u, np.zeros((len(points), 3)), root=None)
