"""Semi-geometric hierarchy and truncated nonsmooth multigrid (paper section 2.4).

The multilevel solution is compared with independent solvers (primal-dual active
set with AMG, and a dense bounded least-squares solve), never with itself."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
from scipy.optimize import lsq_linear

from nonsmooth import BoundConstrainedQP
from nonsmooth.hierarchy import (HierarchyError, connected_bodies, enclosing_grids, per_body_hierarchy,
                                 semi_geometric_hierarchy)
from nonsmooth.multilevel import solve_multilevel
from nonsmooth.obstacle import box_obstacle, p1_elasticity_stiffness, rigid_body_modes
from nonsmooth.smoothers import csr_int32, projected_gauss_seidel
from nonsmooth.solvers import solve
from transfer.grid import StructuredGrid
from transfer.mesh import lattice_tetrahedra

SIZE, E, NU, PUSH = 0.01, 1e10, 0.25, (0.0, 0.0, -3e-4)
#: fine cells per axis of the cube for 2..5 levels (cases/cube_obstacle)
CELLS = {2: 6, 3: 13, 4: 25, 5: 51}


def cube(cells, tilt=0.0):
    return box_obstacle(cells, SIZE, E, NU, PUSH, tilt=tilt)


def hierarchy(points, tets, levels, margin=0.05, block_size=3):
    return semi_geometric_hierarchy(points, tets, levels, 3, margin=margin, block_size=block_size)


# -- hierarchy ---------------------------------------------------------------

def test_prolongations_reproduce_affine_fields_on_non_nested_levels():
    """Q1 grids and the P1 fine space contain the affine functions, so the
    pseudo-L2 projections of eq. 17 carry them exactly, level after level."""
    grid = StructuredGrid.from_bounds([0.1, 0.0, -0.2], [1.0, 0.7, 0.5], [9, 7, 8])
    points = grid.points + 0.02 * np.sin(7 * grid.points[:, ::-1])  # interior jitter, boundary stays a box
    H = hierarchy(points, lattice_tetrahedra(grid.shape), 4, margin=0.13, block_size=1)
    f = lambda p: 1.0 + 2.0 * p[:, 0] - p[:, 1] + 0.5 * p[:, 2]
    u = f(H.grids[0].points[H.kept[0]])
    for P in H.prolongations:
        u = P @ u
    np.testing.assert_allclose(u, f(points), atol=1e-12)
    assert H.levels == 4 and H.sizes[-1] == len(points)


def test_coarse_dofs_without_support_on_the_fine_mesh_are_dropped():
    grid = StructuredGrid.from_bounds([0, 0, 0], [1, 1, 1], [4, 4, 4])
    H = hierarchy(grid.points, lattice_tetrahedra(grid.shape), 3, margin=0.6, block_size=1)
    finest_grid = H.grids[-1]
    dropped = np.setdiff1d(np.arange(finest_grid.num_points), H.kept[-1])
    assert dropped.size > 0
    # a dropped node's whole support (its neighbouring cells) lies outside the unit cube
    spacing = finest_grid.spacing
    p = finest_grid.points[dropped]
    assert np.all(np.any((p < -spacing + 1e-12) | (p > 1 + spacing - 1e-12), axis=1))
    for P in H.prolongations:
        assert np.all(abs(P).sum(axis=0) > 0)


def test_per_body_hierarchy_has_no_coarse_function_on_two_bodies():
    """Two boxes 0.1 apart (a contact pair): each gets its own grids, so every coarse
    function lives on one body, and each body's affine field is carried exactly."""
    grid = StructuredGrid.from_bounds([0, 0, 0], [1, 1, 0.5], [4, 4, 2])
    tets = lattice_tetrahedra(grid.shape)
    upper = grid.points * [0.8, 0.8, 1.0] + [0.1, 0.1, 0.6]  # the upper body, a smaller box
    points = np.vstack([upper, grid.points])  # upper body first: fine rows are permuted back
    tets = np.vstack([tets, tets + len(grid.points)])
    body = connected_bodies(len(points), tets)
    assert np.array_equal(body, np.repeat([0, 1], len(grid.points)))
    H = per_body_hierarchy(points, tets, 3, 2, block_size=1)
    assert len(H.bodies) == 2 and H.sizes[0] == sum(h.sizes[0] for h in H.bodies)
    chain = H.prolongations[-1] @ H.prolongations[0]
    columns_on = [np.diff((abs(chain[body == b]).tocsc() > 0).indptr) > 0 for b in (0, 1)]
    assert not np.any(columns_on[0] & columns_on[1]) and np.all(columns_on[0] | columns_on[1])
    f = [lambda p: 1.0 + p[:, 0] - 2 * p[:, 2], lambda p: -3.0 + 0.5 * p[:, 1]]
    u = np.concatenate([fb(h.grids[0].points[h.kept[0]]) for fb, h in zip(f, H.bodies)])
    for P in H.prolongations:
        u = P @ u
    expected = np.where(body == 0, f[0](points), f[1](points))
    np.testing.assert_allclose(u, expected, atol=1e-12)
    # one body: the plain hierarchy
    single = per_body_hierarchy(grid.points, lattice_tetrahedra(grid.shape), 3, 2, block_size=1)
    plain = semi_geometric_hierarchy(grid.points, lattice_tetrahedra(grid.shape), 3, 2, block_size=1)
    assert not single.bodies and all((a != b).nnz == 0 for a, b in zip(single.prolongations, plain.prolongations))


def test_p1_stiffness_passes_the_patch_test():
    """An affine displacement: no force at interior nodes, and the energy of its uniform
    strain, 1/2 eps : C : eps times the volume."""
    grid = StructuredGrid.from_bounds([0, 0, 0], [2.0, 1.0, 0.5], [5, 4, 3])
    K = p1_elasticity_stiffness(grid.points, lattice_tetrahedra(grid.shape), E, NU)
    G = np.array([[1.0, 2.0, 0.0], [0.0, -1.0, 0.5], [3.0, 0.0, 2.0]]) * 1e-3  # du_i / dx_j
    u = (grid.points @ G.T).ravel()
    inner = np.all((grid.points > [0, 0, 0]) & (grid.points < [2.0, 1.0, 0.5]), axis=1)
    forces = (K @ u).reshape(-1, 3)
    assert np.abs(forces[inner]).max() < 1e-10 * np.abs(forces).max()
    eps = 0.5 * (G + G.T)
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    energy = 0.5 * (lam * np.trace(eps) ** 2 + 2 * mu * np.sum(eps * eps)) * 1.0
    assert 0.5 * u @ (K @ u) == pytest.approx(energy, rel=1e-12)


def test_block_prolongation_and_galerkin_operators_keep_rigid_body_modes():
    points, tets, _ = cube(4)
    H = hierarchy(points, tets, 3)
    assert [P.shape[1] % 3 for P in H.prolongations] == [0, 0]
    K = p1_elasticity_stiffness(points, tets, E, NU)
    ops = H.galerkin(K)
    # coarse rigid motions (affine, so carried exactly) have zero coarse energy
    R = rigid_body_modes(H.grids[0].points[H.kept[0]])
    assert np.abs(ops[0] @ R).max() < 1e-6 * abs(ops[0]).max()
    assert [op.shape[0] for op in ops] == H.sizes


def test_bad_hierarchy_input_is_a_typed_error():
    points, tets, _ = cube(2)
    with pytest.raises(HierarchyError, match="levels"):
        semi_geometric_hierarchy(points, tets, 1)
    with pytest.raises(HierarchyError, match="coarse_shape"):
        enclosing_grids(points, (2, 0, 2), 2)
    _, _, qp = cube(3)
    with pytest.raises(ValueError, match="fine level has"):
        solve_multilevel(qp, hierarchy=hierarchy(points, tets, 2))


# -- smoother ----------------------------------------------------------------

def test_projected_gauss_seidel_is_feasible_monotone_and_reaches_the_dense_solution():
    """Against scipy's bounded least squares on min |L^T x - L^-1 b| (A = L L^T)."""
    rng = np.random.default_rng(3)
    M = rng.standard_normal((40, 40))
    A = M @ M.T + 40 * np.eye(40)
    b = 10 * rng.standard_normal(40)
    qp = BoundConstrainedQP(sp.csr_matrix(A), b, -0.1 * np.ones(40), np.r_[0.05 * np.ones(20), np.inf * np.ones(20)])
    L = la.cholesky(A, lower=True)
    ref = lsq_linear(L.T, la.solve_triangular(L, b, lower=True), bounds=(qp.lower, qp.upper), tol=1e-15,
                     method="bvls").x
    Ai, x = csr_int32(qp.A), np.zeros(40)
    energy = [qp.energy(x)]
    for order in ["forward", "backward", "symmetric"] * 60:
        projected_gauss_seidel(Ai, qp.b, qp.lower, qp.upper, x, 1, order)
        assert qp.infeasibility(x) == 0.0
        energy.append(qp.energy(x))
    assert np.all(np.diff(energy) <= 1e-12 * abs(energy[-1]))
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-10 * np.abs(ref).max())


# -- multilevel --------------------------------------------------------------

@pytest.fixture(scope="module")
def partial_contact():
    """The cube over a tilted plane: part of the bottom touches, part does not."""
    points, tets, qp = cube(CELLS[3], tilt=0.1)
    return qp, hierarchy(points, tets, 3), points


def test_multilevel_equals_active_set_and_snes_vi(partial_contact):
    qp, H, points = partial_contact
    ml = solve(qp, "multilevel", hierarchy=H)
    bottom = points[:, 2] == 0.0
    touching = np.count_nonzero(ml.active[2::3] & bottom)
    assert 0.2 < touching / np.count_nonzero(bottom) < 0.9  # partial contact
    assert not np.any(ml.active[2::3][points[:, 2] > 0.0] & np.isinf(qp.upper[2::3][points[:, 2] > 0.0]))
    for method, options in (("active_set", {"tol": 1e-13}), ("snes_vi", {})):
        other = solve(qp, method, **options)
        assert other.converged
        rel = np.linalg.norm(ml.x - other.x) / np.linalg.norm(other.x)
        assert rel < 1e-8, (method, rel)
    assert ml.converged and ml.history[-1] < 1e-12


def test_the_multilevel_solver_takes_a_monitor(partial_contact):
    """Through nonsmooth.solvers.solve, as the solid calls every solver: one call per iteration
    with its step length (the criterion)."""
    qp, H, _ = partial_contact
    heard = []
    sol = solve(qp, "multilevel", hierarchy=H, monitor=lambda **values: heard.append(values))
    assert sol.converged and [v["step_length"] for v in heard] == sol.history
    assert [v["multigrid_iteration"] for v in heard] == list(range(1, sol.iterations + 1))


def test_every_iterate_is_feasible_and_the_energy_never_increases(partial_contact):
    qp, H, _ = partial_contact
    violations = []
    sol = solve_multilevel(qp, hierarchy=H, presmooth=1, postsmooth=1, coarse_smooth=1,
                           callback=lambda k, x: violations.append(qp.infeasibility(x)))
    assert sol.converged and len(violations) == sol.iterations > 5
    assert max(violations) == 0.0
    energies = np.asarray(sol.info["energies"])
    assert np.all(np.diff(energies) <= 1e-14 * abs(energies[-1]))
    assert energies[-1] < energies[1] < energies[0]


def test_multilevel_converges_from_a_bad_start(partial_contact):
    """Global convergence: a start far outside the bounds is projected and still converges."""
    qp, H, _ = partial_contact
    x0 = np.random.default_rng(0).standard_normal(qp.size)
    ref = solve(qp, "multilevel", hierarchy=H)
    sol = solve(qp, "multilevel", x0=x0, hierarchy=H, maxiter=100)
    assert sol.converged
    assert np.linalg.norm(sol.x - ref.x) < 1e-8 * np.linalg.norm(ref.x)


def test_multilevel_reports_its_criterion_and_the_iteration_limit(partial_contact):
    """The step length is the criterion: below tol when converged; maxiter reached returns
    the (feasible) iterate unconverged with its last step length, nothing raised."""
    qp, H, _ = partial_contact
    full = solve(qp, "multilevel", hierarchy=H, tol=1e-12)
    assert full.converged and full.residual == full.history[-1] <= full.tolerance == 1e-12
    assert full.reason == "step length below the tolerance"
    capped = solve(qp, "multilevel", hierarchy=H, tol=1e-12, maxiter=2)
    assert not capped.converged and capped.iterations == 2 and capped.reason == "iteration limit"
    assert capped.residual == capped.history[-1] > 1e3 * capped.tolerance
    assert qp.infeasibility(capped.x) == 0.0


def _cube_iterations(levels):
    points, tets, qp = cube(CELLS[levels])
    sol = solve_multilevel(qp, hierarchy=hierarchy(points, tets, levels), tol=1e-12)
    assert sol.converged
    assert sol.info["max_infeasibility"] == 0.0
    return sol.iterations, sol.info["asymptotic_rate"]


def test_iterations_grow_by_at_most_two_per_level():
    """Cube benchmark (paper figure 13/14) at 2, 3 and 4 levels (1k, 8k, 53k unknowns)."""
    runs = [_cube_iterations(levels) for levels in (2, 3, 4)]
    its = [r[0] for r in runs]
    assert all(b - a <= 2 for a, b in zip(its, its[1:])), its
    assert all(rate < 0.3 for _, rate in runs), runs


@pytest.mark.slow
def test_five_levels_take_at_most_two_iterations_more_than_four():
    (n4, _), (n5, rate5) = _cube_iterations(4), _cube_iterations(5)
    assert n5 - n4 <= 2 and rate5 < 0.3, (n4, n5, rate5)


def test_multilevel_in_a_rotated_basis_matches_the_active_set():
    """The contact form (paper eq. 10): bottom nodes rotated to (t1, t2, n) of an inclined
    plane, non-penetration a bound on the normal component; the hierarchy follows with
    Q^T P. Both solvers see the same transformed problem."""
    points, tets, qp = cube(8)
    theta = 0.2
    n = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    frame = np.array([[np.cos(theta), 0.0, np.sin(theta)], [0.0, 1.0, 0.0], n]).T  # columns t1, t2, n
    bottom = np.flatnonzero(points[:, 2] == 0.0)
    blocks = [np.eye(3)] * len(points)
    for i in bottom:
        blocks[i] = frame
    Q = sp.block_diag(blocks, format="csr")
    lower = np.full(qp.size, -np.inf)
    fixed = qp.lower == qp.upper
    lower[fixed] = qp.lower[fixed]
    # the plane n . p = n . (size / 2, 0, 0) - 1e-4: the bottom at x < size / 2 comes into contact
    lower[3 * bottom + 2] = n @ [SIZE / 2, 0.0, 0.0] - 1e-4 - points[bottom] @ n
    qp_rot = BoundConstrainedQP(Q.T @ qp.A @ Q, Q.T @ qp.b, lower, np.where(fixed, qp.upper, np.inf), block_size=3)
    H = hierarchy(points, tets, 3).in_basis(Q)
    ml = solve(qp_rot, "multilevel", hierarchy=H)
    ref = solve(qp_rot, "active_set", tol=1e-13)
    assert ml.converged and 0 < np.count_nonzero(ml.active[3 * bottom + 2]) < len(bottom)
    assert np.linalg.norm(ml.x - ref.x) < 1e-8 * np.linalg.norm(ref.x)
    assert ml.iterations <= 20


def test_truncated_galerkin_update_equals_the_direct_product():
    from nonsmooth.multilevel import _TruncatedGalerkin

    points, tets, qp = cube(5)
    P = hierarchy(points, tets, 2).prolongations[-1]
    A = sp.csr_matrix(qp.A)
    free = np.random.default_rng(1).random(qp.size) > 0.3
    free[np.repeat(points[:, 0] < 0.5 * SIZE, 3)] = False  # coarse nodes at x < 0 lose all support
    DP, Ac = _TruncatedGalerkin(A, P)(free)
    direct = (sp.diags(free.astype(float)) @ P).T @ A @ (sp.diags(free.astype(float)) @ P)
    supported = Ac.diagonal() > 0
    assert 0 < np.count_nonzero(~supported) and np.abs(direct.diagonal()[~supported]).max() < 1e-6 * direct.diagonal().max()
    keep = sp.diags(supported.astype(float))
    assert abs(Ac - keep @ direct @ keep).max() < 1e-12 * abs(direct).max()
    assert abs(DP - sp.diags(free.astype(float)) @ P @ keep).max() == 0


def test_upper_bounds_mirror_lower_bounds():
    """x -> -x turns the obstacle's lower bounds into upper ones (the contact form x_n <= gap)."""
    points, tets, qp = cube(6, tilt=0.1)
    mirrored = BoundConstrainedQP(qp.A, -qp.b, -qp.upper, -qp.lower, block_size=3)
    H = hierarchy(points, tets, 2)
    a, b = solve(qp, "multilevel", hierarchy=H), solve(mirrored, "multilevel", hierarchy=H)
    assert a.converged and b.converged and a.iterations == b.iterations
    np.testing.assert_allclose(b.x, -a.x, rtol=0, atol=1e-12 * np.abs(a.x).max())
