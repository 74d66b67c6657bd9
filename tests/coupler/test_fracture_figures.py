"""The per-step figures of the hydro-mechanical fracture (coupler/fsi/apertures.py, flow_rate.py,
open_gap.py): exact values on small arrays, conservation of the contact area."""

from __future__ import annotations

import numpy as np
import pytest

from coupler.fsi.apertures import contact_area_fraction, hydraulic_aperture, mechanical_aperture
from coupler.fsi.flow_rate import column_open_lengths, percolates, section_flow_rates, throat_aperture
from coupler.fsi.open_gap import contact_share
from transfer import FunctionSpace, Mesh, StructuredGrid


def test_mechanical_aperture_counts_contacts_as_zero():
    gap = np.array([2e-4, 1e-4, 3e-9, -1e-12])  # a closed node's gap is round-off, either sign
    closed = np.array([False, False, True, True])
    weights = np.array([1.0, 3.0, 2.0, 2.0])
    assert mechanical_aperture(gap, closed, weights) == pytest.approx((2e-4 + 3e-4) / 8, rel=1e-15)
    assert contact_area_fraction(closed, weights) == 0.5


def test_hydraulic_aperture_inverts_the_cubic_law():
    e, mu, L, W, dp = 1.3e-4, 1e-3, 0.02, 0.01, 250.0
    Q = W * e ** 3 * dp / (12 * mu * L)
    assert hydraulic_aperture(Q, mu, L, W, dp) == pytest.approx(e, rel=1e-14)


def test_section_flow_rate_is_the_velocity_times_the_face_areas():
    grid = StructuredGrid((0, 0, 0), (0.1, 0.2, 0.5), (3, 2, 2))
    velocity = np.zeros((12, 3))
    velocity[:, 0] = np.arange(12)  # cell (i, j, k) at i + 3 j + 6 k
    Q = section_flow_rates(grid, velocity)
    expected = [sum(i + 3 * j + 6 * k for j in range(2) for k in range(2)) * 0.1 for i in range(3)]
    np.testing.assert_allclose(Q, expected, rtol=1e-15)


def test_percolation_needs_an_open_path_through_shared_faces():
    grid = StructuredGrid((0, 0, 0), (1, 1, 1), (4, 3, 1))
    fraction = np.ones((1, 3, 4))
    fraction[0, 1, :] = 0.0  # an open channel along x
    assert percolates(grid, fraction.ravel())
    fraction[0, 1, 2] = 0.9  # blocked
    assert not percolates(grid, fraction.ravel())
    fraction[0, 0, 1:4] = 0.2  # a bypass in the row beside the channel, around the block
    assert percolates(grid, fraction.ravel())
    fraction[0, 0, 1] = 1.0
    fraction[0, 2, 2] = 0.0  # open cells meeting the channel diagonally only: no shared face
    assert not percolates(grid, fraction.ravel())


def test_a_column_is_open_by_the_open_share_of_its_cells():
    """Across z (axis 2) and across y (axis 1): sum of (1 - fraction) h over the column, the
    plane's last axis along x; a block of the grid gives its own columns, the rest zero."""
    grid = StructuredGrid((0, 0, 0), (1.0, 0.1, 0.002), (4, 3, 5))  # origin, spacing, shape
    rng = np.random.default_rng(3)
    fraction = rng.uniform(0, 1, (5, 3, 4))  # (z, y, x)
    across_z = column_open_lengths(grid, fraction.ravel(), 2)
    np.testing.assert_allclose(across_z, (1 - fraction).sum(axis=0) * 0.002, rtol=1e-14)
    across_y = column_open_lengths(grid, fraction.ravel(), 1)
    np.testing.assert_allclose(across_y, (1 - fraction).sum(axis=1) * 0.1, rtol=1e-14)
    block = column_open_lengths(grid, fraction[:, :, 1:3].ravel(), 2, block=((1, 0, 0), (3, 3, 5)))
    np.testing.assert_allclose(block[:, 1:3], across_z[:, 1:3], rtol=1e-14)
    assert not block[:, [0, 3]].any()


def test_the_throat_is_the_narrowest_column_of_the_widest_path():
    """Plates: the aperture. A channel closed to 1 by one column: 1, however wide the rest. A
    bypass of 2 beside it: 2 (the widest path detours). Columns touching at a corner only do
    not connect; no path at all: 0."""
    plates = np.full((3, 5), 7.0)
    assert throat_aperture(plates) == 7.0
    channel = np.zeros((3, 5))
    channel[1] = [9, 9, 1, 9, 9]
    assert throat_aperture(channel) == 1.0
    channel[0, 1:4] = 2.0
    assert throat_aperture(channel) == 2.0
    diagonal = np.zeros((2, 4))
    diagonal[0, :2], diagonal[1, 2:] = 5.0, 5.0
    assert throat_aperture(diagonal) == 0.0
    assert throat_aperture(np.zeros((3, 5))) == 0.0


def test_the_throat_of_random_maps_is_the_bottleneck_of_a_brute_force_search():
    """Against an independent search: the widest path by a maximin Dijkstra over the columns."""
    import heapq

    rng = np.random.default_rng(7)
    for _ in range(20):
        e = rng.uniform(0, 1, (6, 9)) * (rng.uniform(0, 1, (6, 9)) > 0.3)
        best = np.zeros_like(e)
        heap = [(-e[j, 0], j, 0) for j in range(6)]
        best[:, 0] = e[:, 0]
        heapq.heapify(heap)
        while heap:
            w, j, i = heapq.heappop(heap)
            for jj, ii in ((j + 1, i), (j - 1, i), (j, i + 1), (j, i - 1)):
                if 0 <= jj < 6 and 0 <= ii < 9 and min(-w, e[jj, ii]) > best[jj, ii]:
                    best[jj, ii] = min(-w, e[jj, ii])
                    heapq.heappush(heap, (-best[jj, ii], jj, ii))
        assert throat_aperture(e) == best[:, -1].max()


def square_face(n: int, m: int, z: float, shift: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit square at height z, n x m cells of two triangles; vertex ids from `shift`."""
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, m + 1), indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    ids = np.arange(x.size).reshape(n + 1, m + 1)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
    return points, shift + np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def patch_in_contact():
    """(points, triangles, on_slave, in_contact): a fine slave face (7 x 6) in contact on a patch,
    the coarse face (3 x 2) above it."""
    sp, st = square_face(7, 6, 0.0, 0)
    mp, mt = square_face(3, 2, 1e-4, len(sp))
    points, triangles = np.concatenate([sp, mp]), np.concatenate([st, mt])
    on_slave = np.arange(len(points)) < len(sp)
    in_contact = on_slave & (points[:, 0] < 0.45) & (points[:, 1] > 0.3)
    return points, triangles, on_slave, in_contact


def lumped(points, triangles) -> np.ndarray:
    vertices, local = np.unique(triangles, return_inverse=True)
    D = FunctionSpace(Mesh(points[vertices], local.reshape(-1, 3), "triangle"), "P1").mass_matrix()
    out = np.zeros(len(points))
    out[vertices] = np.asarray(D.sum(axis=1)).ravel()
    return out


def test_the_other_face_loses_the_slaves_contact_area():
    """A fine slave face (7 x 6) in contact on a patch, the coarse face (3 x 2) above it: the
    slave nodes keep their in_contact, the other face's shares lie in [0, 1] and its contact
    area (lumped areas times chi) equals the slave's to round-off, so a uniform fluid pressure
    pushes both faces with the same force; no contact, or full contact, is 0 or 1 everywhere."""
    points, triangles, on_slave, in_contact = patch_in_contact()
    chi = contact_share(points, triangles, on_slave, in_contact)
    np.testing.assert_array_equal(chi[on_slave], in_contact[on_slave])
    assert np.all((chi >= 0) & (chi <= 1)) and 0 < chi[~on_slave].max() < 1
    area = lumped(points, triangles) * chi
    assert area[~on_slave].sum() == pytest.approx(area[on_slave].sum(), rel=1e-12)
    np.testing.assert_array_equal(contact_share(points, triangles, on_slave, np.zeros(len(points), bool)), 0.0)
    np.testing.assert_allclose(contact_share(points, triangles, on_slave, on_slave), 1.0, rtol=0, atol=1e-14)


def test_a_face_that_does_not_face_the_slave_stays_open():
    sp, st = square_face(4, 4, 0.0, 0)
    far, ft = square_face(2, 2, 0.0, len(sp))
    far[:, 0] += 5.0  # beside the slave, not across it
    points, triangles = np.concatenate([sp, far]), np.concatenate([st, ft])
    on_slave = np.arange(len(points)) < len(sp)
    chi = contact_share(points, triangles, on_slave, on_slave)
    assert np.all(chi[on_slave] == 1) and np.all(chi[~on_slave] == 0)
