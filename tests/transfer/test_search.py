"""The volume kernel's search for candidate pairs (transfer/_kernels/cells.hpp,
SourceSearch): every source cell whose bounding box overlaps a target cell's box is tested
once, also when the source cells differ much in size (a cell is filed in the bin of its
box's lower corner, and a query reaches down by the largest box)."""

import numpy as np
import pytest

from transfer import _kernels
from transfer.generate import box_tetrahedra


def boxes(points, cells):
    p = points[cells]
    return p.min(axis=1), p.max(axis=1)


def overlapping_pairs(src, dst) -> int:
    """The pairs of boxes that overlap within the kernel's tolerance, 1e-10 times the
    target box's diagonal, counted by brute force."""
    (slo, shi), (tlo, thi) = boxes(*src), boxes(*dst)
    tol = 1e-10 * np.linalg.norm(thi - tlo, axis=1)
    hits = (slo[None] <= thi[:, None] + tol[:, None, None]) & (tlo[:, None] <= shi[None] + tol[:, None, None])
    return int(hits.all(axis=2).sum())


def pairs_tested(src, dst) -> int:
    (sp, sc), (tp, tc) = src, dst
    out = _kernels.assemble_volume(sp, sc, _kernels.TET, 1, tp, tc, _kernels.TET, 1, np.empty((0, 4)), np.empty(0),
                                   False, False, len(sp), len(tp), None, 1, stages=1)
    return out["pairs_tested"]


def with_large_tet(mesh, corner, size):
    """The mesh's points and cells plus one tet of edge `size` at `corner` (no shared points)."""
    big = np.asarray(corner, float) + size * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    n = len(mesh.points)
    return np.vstack([mesh.points, big]), np.vstack([mesh.cells, np.arange(n, n + 4)[None]])


@pytest.mark.parametrize("corner, size", [((0, 0, 0), 1.0), ((-0.5, 0.2, -0.3), 1.2), ((0.4, 0.4, 0.4), 0.05)])
def test_every_overlapping_box_is_tested_once(corner, size):
    src = with_large_tet(box_tetrahedra((5, 5, 5), (0, 0, 0), (1, 1, 1), jitter=0.2, seed=1), corner, size)
    dst = box_tetrahedra((6, 7, 4), (-0.1, 0.05, 0), (1.1, 0.9, 1.0), jitter=0.2, seed=2)
    dst = (dst.points, dst.cells)
    expected = overlapping_pairs(src, dst)
    assert pairs_tested(src, dst) == expected
    # the large tet reaches targets far from the bin of its lower corner
    assert expected > overlapping_pairs((src[0], src[1][:-1]), dst)


def test_a_source_outside_the_targets_is_not_tested():
    src = box_tetrahedra((3, 3, 3), (2, 2, 2), (3, 3, 3))
    dst = box_tetrahedra((4, 4, 4), (0, 0, 0), (1, 1, 1))
    assert pairs_tested((src.points, src.cells), (dst.points, dst.cells)) == 0
