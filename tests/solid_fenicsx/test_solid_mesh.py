"""solid_fenicsx.mesh: distributed tet meshes with named boundaries (arrays, files, graded boxes)."""

from __future__ import annotations

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")
pytest.importorskip("dolfinx")

from mpi4py import MPI  # noqa: E402

from solid_fenicsx.mesh import BOX_FACES, SolidMeshError, box_mesh, from_arrays, read_mesh, tag_counts  # noqa: E402
from transfer.generators.lattice import box_arrays, graded_nodes  # noqa: E402


def _count(solid, name):
    return MPI.COMM_WORLD.allreduce(len(solid.facets(name)))


def test_box_faces_named_and_complete():
    solid = box_mesh(upper=(2.0, 1.0, 1.0), shape=(4, 3, 2))
    assert list(solid.boundaries) == list(BOX_FACES)
    assert solid.num_cells == 6 * 4 * 3 * 2 and solid.num_points == 5 * 4 * 3
    # two triangles per lattice face square
    assert [_count(solid, f) for f in BOX_FACES] == [2 * 3 * 2] * 2 + [2 * 4 * 2] * 2 + [2 * 4 * 3] * 2
    assert _count(solid, ["xmin", "xmax"]) == 24


def test_predicate_overrides_face_on_selected_facets():
    disk = {"disk": lambda x: np.isclose(x[2], 0.0) & (x[0] ** 2 + x[1] ** 2 < 0.5 ** 2)}
    solid = box_mesh(shape=(4, 4, 2), boundaries=disk)
    n_disk, n_zmin = _count(solid, "disk"), _count(solid, "zmin")
    assert n_disk > 0 and n_disk + n_zmin == 2 * 16
    with pytest.raises(SolidMeshError, match="unknown boundary"):
        solid.facets("nowhere")


def test_graded_nodes():
    x = graded_nodes(0.0, 8.0, 0.0625, 1.25, 1.3)
    h = np.diff(x)
    assert x[0] == 0.0 and x[-1] == 8.0 and np.all(h > 0)
    assert np.allclose(h[:20], 0.0625)
    ratio = h[21:] / h[20:-1]
    assert np.all(ratio <= 1.3 + 1e-12) and np.allclose(ratio, ratio[0])
    down = graded_nodes(1.0, 0.0, 0.1, 0.0, 1.2)
    assert down[0] == 1.0 and down[-1] == 0.0 and np.isclose(down[0] - down[1], 0.1)
    solid = box_mesh(axes=[down, [0, 1], [0, 0.5, 1]])  # axes are sorted
    assert solid.num_points == len(down) * 2 * 3


def _tagged_cube():
    """Unit cube, 3^3 lattice, an unused point first; top triangles tagged 7, bottom 3."""
    points, cells = box_arrays([np.linspace(0, 1, 4)] * 3)
    points = np.vstack([[9.0, 9.0, 9.0], points])
    cells = cells + 1
    tris, tags = [], []
    for c in cells:
        for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]):
            z = points[c[f], 2]
            if np.allclose(z, 1.0) or np.allclose(z, 0.0):
                tris.append(c[f])
                tags.append(7 if z[0] == 1.0 else 3)
    return points, cells, np.array(tris), np.array(tags, dtype=np.int32)


def test_from_arrays_with_tags_and_predicates():
    points, cells, tris, tags = _tagged_cube()
    solid = from_arrays(points, cells, tris, tags, tag_names={"top": 7},
                        boundaries={"xmin": lambda x: np.isclose(x[0], 0.0)})
    assert solid.boundaries == {"3": 3, "top": 7, "xmin": 8}
    assert [_count(solid, n) for n in ("3", "top", "xmin")] == [18, 18, 18]
    assert solid.num_points == 64  # the unused point 0 is dropped: input id i is point i + 1
    ids = np.asarray(solid.mesh.geometry.input_global_indices)
    assert np.array_equal(solid.mesh.geometry.x, points[ids + 1])


def test_a_predicate_that_selects_no_facet_is_warned_of_and_tag_counts_count_each_facet_once():
    points, cells, tris, tags = _tagged_cube()
    with pytest.warns(UserWarning, match="boundary 'nowhere' has no facets"):
        solid = from_arrays(points, cells, tris, tags, tag_names={"top": 7},
                            boundaries={"nowhere": lambda x: x[0] > 2.0})
    tdim = solid.mesh.topology.dim
    assert tag_counts(solid.mesh, tdim - 1, solid.facet_tags, solid.boundaries) == {"3": 18, "top": 18, "nowhere": 0}
    assert tag_counts(solid.mesh, tdim, None, {"rock": 1}) == {"rock": 0}


@pytest.mark.parametrize("fmt", ["gmsh22", "vtu", "xdmf"])
def test_read_mesh_keeps_boundary_tags(tmp_path_factory, fmt):
    points, cells, tris, tags = _tagged_cube()
    path = None
    if MPI.COMM_WORLD.rank == 0:
        path = tmp_path_factory.mktemp("meshes") / f"cube.{'msh' if fmt == 'gmsh22' else fmt}"
        if fmt == "gmsh22":
            m = meshio.Mesh(points, [("tetra", cells), ("triangle", tris)],
                            cell_data={"gmsh:physical": [np.ones(len(cells), int), tags],
                                       "gmsh:geometrical": [np.ones(len(cells), int), tags]},
                            field_data={"top": np.array([7, 2]), "bottom": np.array([3, 2]),
                                        "body": np.array([1, 3])})
            m.write(path, file_format="gmsh22", binary=False)
        else:
            meshio.Mesh(points, [("tetra", cells), ("triangle", tris)],
                        cell_data={"boundary": [np.zeros(len(cells), np.int32), tags]}).write(path)
    path = MPI.COMM_WORLD.bcast(path, root=0)
    solid = read_mesh(path)
    expected = {"bottom": 3, "top": 7} if fmt == "gmsh22" else {"3": 3, "7": 7}
    assert solid.boundaries == expected
    assert all(_count(solid, n) == 18 for n in expected)
    assert solid.num_cells == len(cells) and solid.num_points == 64


def test_bad_meshes_raise_clear_errors(tmp_path):
    points, cells = box_arrays([np.linspace(0, 1, 2)] * 3)
    with pytest.raises(SolidMeshError, match="degenerate"):
        from_arrays(np.zeros_like(points), cells)
    with pytest.raises(SolidMeshError, match="out of range"):
        from_arrays(points, cells + 100)
    with pytest.raises(SolidMeshError, match="tetrahedra"):
        from_arrays(points, cells[:, :3])
    if MPI.COMM_WORLD.size == 1:
        path = tmp_path / "surface.vtu"
        meshio.Mesh(points, [("triangle", cells[:, :3])]).write(path)
        with pytest.raises(SolidMeshError, match="no tetrahedra"):
            read_mesh(path)
