"""The per-step figures of the hydro-mechanical fracture (coupler/fsi/apertures.py, flow_rate.py,
open_gap.py): exact values on small arrays."""

from __future__ import annotations

import numpy as np
import pytest

from coupler.fsi.apertures import contact_area_fraction, hydraulic_aperture, mechanical_aperture
from coupler.fsi.flow_rate import percolates, section_flow_rates
from coupler.fsi.open_gap import touching
from transfer import StructuredGrid


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


def test_touching_takes_the_slaves_contact_and_the_nearest_slave_for_the_master():
    points = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0.1, 0, 1e-6], [1.9, 0, 1e-6]], float)
    slave = np.array([True, True, True, False, False])
    in_contact = np.array([True, False, False, False, False])
    vertices = np.array([0, 1, 2, 3, 4])
    np.testing.assert_array_equal(touching(points, vertices, slave, in_contact), [True, False, False, True, False])
