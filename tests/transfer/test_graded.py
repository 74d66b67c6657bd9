"""transfer.generators.graded through measured_fracture's ``grading`` (issue 30 item 2): the
graded blocks are one conforming mesh of well-shaped tets, their faces the uniform mesh's, and
their nodes grow with the face's area, not with the blocks' height."""

from __future__ import annotations

import numpy as np
import pytest

from solid_fenicsx.contact_halfspace import fracture_map
from transfer.generators import generate, lattices_of
from transfer.generators.graded import layer_plan
from transfer.generators.height_maps import write_npz
from transfer.mesh import TET_FACES

SIZE = 0.02


@pytest.fixture(scope="module")
def surfaces(tmp_path_factory):
    lower, upper = fracture_map(32, SIZE, 40e-6, 20e-6, mismatch_length=SIZE / 4)
    return str(write_npz(tmp_path_factory.mktemp("map") / "s.npz", lower.T, upper.T, (SIZE / 32,) * 2))


def _blocks(surfaces, **values):
    return generate("measured_fracture", {"surfaces": surfaces, "height": 0.005, "periodic": True, **values})


def _boundary_area(block) -> float:
    """The area of the faces of the tets that belong to one tet only (a hanging node or a face
    split differently on its two sides adds faces that belong to one tet inside the mesh)."""
    faces = block.cells[:, TET_FACES].reshape(-1, 3)
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    assert counts.max() <= 2
    p = block.points[faces[first[counts == 1]]]
    return float(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())


def _triangles(block, face) -> np.ndarray:
    """Each triangle of `face` as its centroid and its area vector (whatever its first vertex),
    sorted by centroid."""
    p = block.points[block.faces[face]]
    rows = np.column_stack([p.mean(axis=1), 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])])
    return rows[np.lexsort(np.round(rows[:, :3] / (1e-9 * SIZE)).T[::-1])]


def _quality(block) -> np.ndarray:
    """6 sqrt(2) volume / (root mean square edge)^3: 1 for the regular tet, 0 for a flat one."""
    p = block.points[block.cells]
    edges = sum(((p[:, a] - p[:, b]) ** 2).sum(axis=1) for a in range(4) for b in range(a + 1, 4)) / 6
    volume = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6
    return 6 * np.sqrt(2) * volume / edges ** 1.5


@pytest.mark.parametrize("coarsen, ratio", [(1, 1), (2, 2)])
def test_graded_blocks_are_conforming_well_shaped_and_have_the_uniform_faces(surfaces, coarsen, ratio):
    """The graded mesh's boundary is the uniform mesh's (the same outer box and fracture faces:
    any non-conforming transition would add faces inside), the same volume, tets of quality at
    least 0.3 (measured 0.36 to 0.49; the uniform 4 layers: 0.39 here, 0.01 on the 256 x 256 map
    at coarsen 1), and it is made whole (no lattice)."""
    uniform = _blocks(surfaces, coarsen=coarsen, ratio=ratio, height=0.01)
    graded = _blocks(surfaces, coarsen=coarsen, ratio=ratio, height=0.01, grading=1.5)
    assert lattices_of("measured_fracture", {"surfaces": surfaces, "height": 0.005, "grading": 1.5}) is None
    assert graded.volume() == pytest.approx(uniform.volume(), rel=1e-12)
    assert _boundary_area(graded) == pytest.approx(_boundary_area(uniform), rel=1e-12)
    for face in ("fracture_lower", "fracture_upper"):  # the same outward triangles: the lattice's face
        mine, theirs = (_triangles(b, face) for b in (graded, uniform))
        assert np.allclose(mine, theirs, rtol=0, atol=1e-12 * SIZE)
    assert _quality(graded).min() >= 0.3
    assert max(graded.info["grading_halvings"]) >= 1


def test_graded_nodes_grow_with_the_face_not_the_height(surfaces):
    """Four times the block height adds fewer nodes than the faces have (the flat zone's coarse
    levels: measured 0.92 times; the lattice at the fracture's spacing would add 12 times), and
    halving the lattice spacing multiplies the nodes by about four."""
    thin, thick = (_blocks(surfaces, coarsen=2, grading=1.5, height=h) for h in (0.005, 0.02))
    face_nodes = 2 * 17 * 17
    assert thick.num_points - thin.num_points < face_nodes
    fine = _blocks(surfaces, coarsen=1, grading=1.5, height=0.005)
    assert 3.0 < fine.num_points / thin.num_points < 4.5


def test_layer_plan():
    rough, flat, halve = layer_plan(1.0, 1.5, 2.0, 40.0)
    assert rough.tolist() == [1.0, 1.5, 2.25]  # at least twice the relief
    assert flat.sum() == pytest.approx(40.0 - rough.sum())
    assert np.all(np.diff(flat) > 0) and halve.any()
    with pytest.raises(ValueError, match="grading: .*increase height"):
        layer_plan(1.0, 1.5, 2.0, 5.0)


def test_grading_is_checked(surfaces):
    with pytest.raises(ValueError, match="grading: must be a ratio above 1"):
        _blocks(surfaces, grading=1.0)
