"""Conservation over the overlap: int_overlap T u = int_overlap u, for l2 and pseudo_l2.

The source is the unit cube, the target the unit box shifted by SHIFT: the overlap
is the box [max(0, s), min(1, 1 + s)] per axis, and the integral of a linear field
over it is known in closed form (volume times the value at its centre).
"""

import numpy as np
import pytest

from transfer import FunctionSpace, StructuredGrid, Transfer
from transfer.generate import box_tetrahedra

from vc_helpers import SHIFT, Linear

OVERLAP_LO = np.maximum(0.0, SHIFT)
OVERLAP_HI = np.minimum(1.0, 1.0 + SHIFT)
OVERLAP_VOLUME = float(np.prod(OVERLAP_HI - OVERLAP_LO))
TOL = 1e-12


def rel(a, b):
    a, b = np.atleast_1d(a), np.atleast_1d(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="module")
def shifted_p1(shifted_tets):
    return FunctionSpace(shifted_tets, "P1")


def test_overlap_volume_is_not_trivial():
    assert 0.2 < OVERLAP_VOLUME < 0.8


@pytest.mark.parametrize("k", [None, 3])
def test_p1_conservation_on_partial_overlap(src_tets, shifted_p1, method, k):
    src = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(src, shifted_p1, method)
    u = Linear(31, k=k)
    exact = u.box_integral(OVERLAP_LO, OVERLAP_HI)
    v = T(src.interpolate(u))
    assert rel(T.integral_target(v), exact) < TOL
    assert rel(T.integral_source(src.interpolate(u)), exact) < TOL
    assert T.conservation_error(src.interpolate(u)) < TOL


def test_overlap_volume_from_the_operators(src_tets, shifted_p1, method):
    src = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(src, shifted_p1, method)
    assert rel(T.B.sum(), OVERLAP_VOLUME) < TOL
    assert rel(T.coupling.overlap.sum(), OVERLAP_VOLUME) < TOL
    assert rel(T.D.sum(), OVERLAP_VOLUME) < TOL


def test_p0_coupling_sums_to_overlap_volume(src_tets, shifted_tets, method):
    S, D = FunctionSpace(src_tets, "P0"), FunctionSpace(shifted_tets, "P0")
    T = Transfer.assemble(S, D, method)
    assert rel(T.B.sum(), OVERLAP_VOLUME) < TOL
    u = np.random.default_rng(3).uniform(1, 2, S.num_dofs)
    assert T.conservation_error(u) < TOL


def test_conservation_of_a_nonlinear_field(shifted_p1, method):
    """For any source field, int T u over the overlap = int u over the overlap
    (1 is in the target space on the overlap): compare with the source integral
    computed independently of B, on the source cells inside the overlap box.
    The field vanishes on every source cell that is not inside the overlap box."""
    src_tets = box_tetrahedra((8, 8, 8), jitter=0.2, seed=9)
    src = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(src, shifted_p1, method)
    x = src_tets.points
    inside = np.all((x > OVERLAP_LO + 1e-9) & (x < OVERLAP_HI - 1e-9), axis=1)
    cell_inside = inside[src_tets.cells].all(axis=1)
    # vertices all of whose cells lie inside the overlap box: their hat functions do too
    outside_cells = src_tets.cells[~cell_inside].ravel()
    support_inside = np.ones(len(x), bool)
    support_inside[outside_cells] = False
    assert 10 < support_inside.sum() < len(x) / 2
    u = np.where(support_inside, np.sin(3 * x[:, 0]) * np.exp(x[:, 1]) + x[:, 2] ** 2, 0.0)
    cells_volume = src_tets.cell_measures()
    exact = np.sum(cells_volume * u[src_tets.cells].mean(axis=1))  # P1 integral: volume x mean of vertices
    assert rel(T.integral_target(T(u)), exact) < TOL


def test_hexahedral_source_conservation(src_hexes, shifted_p1, method):
    """Quadrature path (Q1 source): a linear field's integral over the overlap."""
    H = FunctionSpace(src_hexes, "Q1")
    T = Transfer.assemble(H, shifted_p1, method)
    u = Linear(33)
    assert rel(T.integral_target(T(H.interpolate(u))), u.box_integral(OVERLAP_LO, OVERLAP_HI)) < TOL


def test_grid_target_conservation(src_tets, method):
    """Target: a structured grid over the shifted box."""
    g = StructuredGrid.from_bounds(SHIFT, 1 + SHIFT, (3, 4, 3))
    src = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(src, FunctionSpace(g, "Q1"), method)
    u = Linear(34)
    assert rel(T.integral_target(T(src.interpolate(u))), u.box_integral(OVERLAP_LO, OVERLAP_HI)) < TOL


def test_target_inside_source_conserves_over_the_target(src_tets, method):
    """A target strictly inside the source: the overlap is the whole target box."""
    lo, hi = np.array([0.11, 0.23, 0.31]), np.array([0.83, 0.71, 0.97])
    dst = FunctionSpace(box_tetrahedra((3, 3, 3), lo, hi, jitter=0.2, seed=8), "P1")
    src = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(src, dst, method)
    assert T.covered_fraction == 1.0
    u = Linear(35)
    assert rel(T.integral_target(T(src.interpolate(u))), u.box_integral(lo, hi)) < TOL


def test_conservation_error_of_a_given_transfer(src_tets, shifted_p1, method):
    """conservation_error(u, v) takes v as T u instead of applying T again (the CLI has it)."""
    src = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(src, shifted_p1, method)
    u = src.interpolate(Linear(31))
    v = T(u)
    assert T.conservation_error(u, v) == T.conservation_error(u)
    assert T.conservation_error(u, 2 * v) == pytest.approx(1.0, rel=1e-12)
