"""Meshes by index (transfer.generators.lattices): any split of a generator's cells and points into
blocks, each made alone, joins to the whole mesh exactly (what the solid's ranks rely on)."""

from __future__ import annotations

import numpy as np
import pytest

from transfer.generate import box_tetrahedra
from transfer.generators import generate, lattices_of
from transfer.generators.lattices import box_lattices
from transfer.mesh import lattice_tetrahedra

ROUGH = {"shape": [5, 3, 2], "size": [0.05, 0.025], "height": 0.005, "aperture": 0.001, "min_aperture": 0.0005,
         "rms": 0.00015, "mismatch_length": 0.0125, "seed": 4}


def test_lattice_tetrahedra_by_range_are_the_whole_lattices_rows():
    whole = lattice_tetrahedra((3, 2, 4))
    for start, stop in ((0, 5), (3, 17), (7, len(whole)), (11, 12), (40, 40)):
        assert np.array_equal(lattice_tetrahedra((3, 2, 4), start, stop), whole[start:stop])


def test_blocks_of_a_generator_join_to_its_mesh():
    block = generate("rough_fracture", ROUGH)
    lattices = lattices_of("rough_fracture", ROUGH)
    bounds = [0, 1, 77, 180, 181, lattices.num_cells]  # across the two blocks' seam (180 cells each)
    parts = [lattices.cells(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
    assert np.array_equal(np.concatenate([p[0] for p in parts]), block.cells)
    assert np.array_equal(np.concatenate([p[1] for p in parts]), block.cell_tags)
    triangles, tags = block.tagged_triangles()
    joined = np.concatenate([np.column_stack([np.sort(p[2], axis=1), p[3]]) for p in parts])
    whole = np.column_stack([np.sort(triangles, axis=1), tags])
    assert np.array_equal(joined[np.lexsort(joined.T[::-1])], whole[np.lexsort(whole.T[::-1])])
    ids = np.random.default_rng(0).permutation(lattices.num_points)[:50]
    assert np.array_equal(lattices.points(ids), block.points[ids])
    assert lattices_of("hertz", {}) is None  # gmsh: built whole only


@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_box_lattices_are_the_box(jitter):
    """Jittered too: each block of points draws its rows of the whole box's random moves."""
    box = box_tetrahedra((3, 4, 2), (0, -1, 2), (1, 1, 3), jitter=jitter, seed=3)
    lattices = box_lattices((3, 4, 2), (0, -1, 2), (1, 1, 3), jitter, 3)
    points, cells, faces, _ = lattices.arrays()
    assert np.array_equal(points, box.points) and np.array_equal(cells, box.cells) and faces == {}
    ids = np.array([50, 7, 8, 9, 21, 0, 59])  # runs of consecutive rows, unordered
    assert np.array_equal(lattices.points(ids), box.points[ids])
    assert jitter == 0 or not np.array_equal(points, box_tetrahedra((3, 4, 2), (0, -1, 2), (1, 1, 3)).points)
