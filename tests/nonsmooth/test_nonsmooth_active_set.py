"""The primal-dual active set solver and the SNES VI baseline on obstacle
problems with independent solutions: the discrete 1D obstacle problem without
load is the upper concave envelope of the obstacle (a convex hull, computed
here by a monotone chain), the 2D one is checked against projected
red-black Gauss-Seidel run to a fixed point."""

import numpy as np
import pytest
import scipy.sparse as sp

from nonsmooth import BoundConstrainedQP, NonsmoothSolveError
from nonsmooth.solvers import SOLVERS, available, get, solve


def laplacian_1d(n):
    """FD -u'' on n interior nodes of (0, 1), scaled by h (so the entries are O(1/h))."""
    h = 1.0 / (n + 1)
    return sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr") / h


def laplacian_2d(m):
    I = sp.identity(m)
    T = sp.diags([-np.ones(m - 1), 2 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    return sp.csr_matrix(sp.kron(I, T) + sp.kron(T, I))


def upper_concave_envelope(x, y):
    """Values at x of the least concave majorant of the points (x, y) (x sorted)."""
    hull = []
    for p in zip(x, y):
        while len(hull) >= 2 and ((hull[-1][0] - hull[-2][0]) * (p[1] - hull[-2][1])
                                  - (hull[-1][1] - hull[-2][1]) * (p[0] - hull[-2][0])) >= 0:
            hull.pop()
        hull.append(p)
    hx, hy = np.array(hull).T
    return np.interp(x, hx, hy)


def obstacle_1d(n, height=0.3, curvature=4.0):
    x = np.linspace(0, 1, n + 2)[1:-1]
    psi = height - curvature * (x - 0.45) ** 2
    return x, psi, BoundConstrainedQP(laplacian_1d(n), np.zeros(n), psi, np.inf)


def obstacle_2d(m=24, load=-40.0):
    """-Laplace u = load on the unit square, u = 0 outside, u >= psi (a bump)."""
    h = 1.0 / (m + 1)
    g = np.linspace(h, 1 - h, m)
    X, Y = np.meshgrid(g, g, indexing="ij")
    psi = 0.2 - 3.0 * ((X - 0.4) ** 2 + (Y - 0.55) ** 2)
    return BoundConstrainedQP(laplacian_2d(m), load * h * h * np.ones(m * m), psi.ravel(), np.inf), m


def projected_gauss_seidel(m, b, lower, sweeps=20000, tol=1e-15):
    """Red-black projected Gauss-Seidel for the 5-point Laplacian (independent of the solvers)."""
    u = np.maximum(np.zeros((m + 2, m + 2)), 0.0)
    lo = np.full((m + 2, m + 2), -np.inf)
    lo[1:-1, 1:-1] = lower.reshape(m, m)
    f = np.zeros((m + 2, m + 2))
    f[1:-1, 1:-1] = b.reshape(m, m)
    u[1:-1, 1:-1] = np.maximum(0.0, lower.reshape(m, m))
    I, J = np.meshgrid(np.arange(m + 2), np.arange(m + 2), indexing="ij")
    colours = [((I + J) % 2 == c) & (I > 0) & (I < m + 1) & (J > 0) & (J < m + 1) for c in (0, 1)]
    for _ in range(sweeps):
        old = u.copy()
        for mask in colours:
            nb = np.zeros_like(u)
            nb[1:-1, 1:-1] = u[:-2, 1:-1] + u[2:, 1:-1] + u[1:-1, :-2] + u[1:-1, 2:]
            u[mask] = np.maximum(lo[mask], (f[mask] + nb[mask]) / 4.0)
        if np.max(np.abs(u - old)) < tol:
            break
    return u[1:-1, 1:-1].ravel()


@pytest.mark.parametrize("method", ["active_set", "snes_vi"])
def test_1d_obstacle_is_the_concave_envelope(method):
    x, psi, qp = obstacle_1d(200)
    xs = np.concatenate([[0.0], x, [1.0]])
    exact = upper_concave_envelope(xs, np.concatenate([[0.0], psi, [0.0]]))[1:-1]
    sol = solve(qp, method)
    assert sol.converged and sol.solver == method
    assert np.max(np.abs(sol.x - exact)) < 1e-10
    assert qp.kkt_residual(sol.x) < 1e-9
    assert qp.infeasibility(sol.x) < 1e-12
    contact = np.flatnonzero(np.isclose(exact, psi, atol=1e-14, rtol=0))
    assert 20 < contact.size < 150  # a real contact zone, not all or nothing


@pytest.mark.parametrize("method", ["active_set", "snes_vi"])
def test_2d_obstacle_against_projected_gauss_seidel(method):
    qp, m = obstacle_2d()
    reference = projected_gauss_seidel(m, qp.b, qp.lower)
    sol = solve(qp, method)
    assert np.max(np.abs(sol.x - reference)) < 1e-9 * np.max(np.abs(reference))
    assert qp.kkt_residual(sol.x) < 1e-9
    lam = qp.multiplier(sol.x)
    at_bound = np.isclose(sol.x, qp.lower, atol=1e-12, rtol=0)
    assert at_bound.sum() > 10 and (~at_bound).sum() > 10
    assert np.all(lam[at_bound] <= 1e-9)  # the obstacle pushes up: A x - b >= 0
    assert np.max(np.abs(lam[~at_bound])) < 1e-9


def test_solvers_agree_on_a_two_sided_elastic_problem():
    """A 3D vector-valued problem with block size 3, rigid-body-like near-nullspace
    and both bounds: the two solvers agree to 1e-8."""
    m = 8
    L = laplacian_2d(m)
    A = sp.csr_matrix(sp.kron(L, sp.csr_matrix(np.array([[2.0, 0.5, 0.0], [0.5, 1.5, 0.2], [0.0, 0.2, 1.0]]))))
    n = A.shape[0]
    rng = np.random.default_rng(3)
    b = rng.normal(size=n)
    lower = np.full(n, -np.inf)
    upper = np.full(n, np.inf)
    lower[0::3] = -0.05
    upper[2::3] = 0.02
    Z = np.kron(np.ones((m * m, 1)), np.eye(3))
    qp = BoundConstrainedQP(A, b, lower, upper, block_size=3, near_nullspace=Z)
    a, s = solve(qp, "active_set"), solve(qp, "snes_vi")
    assert np.max(np.abs(a.x - s.x)) <= 1e-8 * np.max(np.abs(a.x))
    assert a.active.sum() > 0 and a.iterations >= 2
    assert a.krylov_iterations > 0 and len(a.history) == a.iterations
    assert qp.kkt_residual(a.x) < 1e-9


def test_warm_start_from_the_solution_takes_one_iteration():
    qp, _ = obstacle_2d()
    x = solve(qp, "active_set").x
    again = solve(qp, "active_set", x0=x)
    # the same solution to the solver's tolerance (the first solve's later CG solves use the
    # AMG of its first system: their error is CG's tolerance in another norm)
    assert again.iterations == 1 and np.max(np.abs(again.x - x)) < 1e-10 * np.max(np.abs(x))


def test_fixed_components_stay_at_their_value():
    qp, _ = obstacle_2d(10)
    lower, upper = qp.lower.copy(), qp.upper.copy()
    lower[5] = upper[5] = 0.123
    fixed = BoundConstrainedQP(qp.A, qp.b, lower, upper)
    for method in ("active_set", "snes_vi"):
        assert solve(fixed, method).x[5] == pytest.approx(0.123, abs=1e-12)


def test_registry():
    assert {"active_set", "snes_vi", "multilevel"} <= set(available())
    assert get("active_set") is SOLVERS["active_set"]
    with pytest.raises(ValueError, match="unknown nonsmooth solver 'nope'.*active_set"):
        get("nope")


@pytest.mark.parametrize("method, options, tolerance", [("active_set", {"tol": 1e-10}, 1e-10),
                                                      ("snes_vi", {"rtol": 1e-12}, 1e-12)])
def test_the_iteration_limit_is_reported_not_raised(method, options, tolerance):
    """Hitting max_iter returns the iterate with converged False, the final criterion above
    the tolerance and the reason; a full solve reports its criterion below the tolerance."""
    qp, _ = obstacle_2d()
    capped = solve(qp, method, max_iter=1, **options)
    assert not capped.converged and capped.iterations == 1 and capped.reason.startswith("iteration limit")
    assert capped.tolerance == tolerance and capped.residual > 1e3 * tolerance
    assert np.all(np.isfinite(capped.x))
    assert capped.describe().startswith(f"{method} did not converge: criterion {capped.residual:.3g} > "
                                        f"{tolerance:g} after 1 iteration (iteration limit")
    with pytest.raises(NonsmoothSolveError, match=f"obstacle: {method} did not converge"):
        capped.raise_if_unconverged("obstacle")
    full = solve(qp, method, **options)
    assert full.converged and full.iterations > 1 and full.residual <= full.tolerance == tolerance
    assert full.as_dict()["residual"] == full.residual and full.raise_if_unconverged("obstacle") is full


def test_bad_input():
    A = sp.identity(3, format="csr")
    with pytest.raises(ValueError, match="NaN"):
        BoundConstrainedQP(A, [1.0, np.nan, 0.0], 0.0, 1.0)
    with pytest.raises(ValueError, match="empty feasible set"):
        BoundConstrainedQP(A, np.ones(3), 1.0, 0.0)
    with pytest.raises(NonsmoothSolveError, match="non-positive diagonal"):
        solve(BoundConstrainedQP(-A, np.ones(3), 0.0, 1.0), "active_set")


#: an SPD matrix (not an M-matrix) on which the plain primal-dual active set method cycles
#: from x0 = P(0) (found by a random search: 1 in about 10^4 such 5 x 5 problems)
CYCLING_A = np.array([
    [7.001236226624374, 1.116107403581959, -2.2140706015474585, 3.9516559421011435, -4.0366122285584805],
    [1.116107403581959, 3.780446123450858, -1.1852003568894014, 0.37666880309182516, 1.8617726397071714],
    [-2.2140706015474585, -1.1852003568894014, 2.6005681560796523, -2.0514295738680546, 2.100918989302311],
    [3.9516559421011435, 0.37666880309182516, -2.0514295738680546, 3.054487935648484, -3.8931193728929876],
    [-4.0366122285584805, 1.8617726397071714, 2.100918989302311, -3.8931193728929876, 7.207663747964706]])
CYCLING_B = np.array([0.6973044656302902, -0.7457827487686597, -2.0307685221136045, -0.5268024802656868,
                      1.412202582702718])
CYCLING_U = np.array([-0.07124536981239166, 0.6289389934711002, 0.03892925989839267, 0.3072766808838656,
                      0.45871587374734807])


def enumerate_kkt(A, b, upper):
    """The solution of min 1/2 x'Ax - b'x, x <= upper, by trying every active set."""
    n = len(b)
    for mask in range(1 << n):
        act = np.array([(mask >> i) & 1 for i in range(n)], bool)
        x = np.where(act, upper, 0.0)
        free = ~act
        if free.any():
            x[free] = np.linalg.solve(A[np.ix_(free, free)], b[free] - A[np.ix_(free, act)] @ upper[act])
        lam = b - A @ x
        if np.all(x <= upper + 1e-12) and np.all(lam[act] >= -1e-12):
            return x
    raise AssertionError("no KKT point")


def plain_pdas_cycles(A, b, upper, iterations=30):
    """True when the unsafeguarded method (sets from y = x + lam / diag(A)) revisits a set."""
    d, x, seen = np.diag(A), np.minimum(0.0, upper), set()
    act = x + (b - A @ x) / d > upper
    for _ in range(iterations):
        if act.tobytes() in seen:
            return True
        seen.add(act.tobytes())
        x = np.where(act, upper, 0.0)
        free = ~act
        x[free] = np.linalg.solve(A[np.ix_(free, free)], b[free] - A[np.ix_(free, act)] @ upper[act])
        lam = np.where(free, 0.0, b - A @ x)
        new = x + lam / d > upper
        if np.array_equal(new, act):
            return False
        act = new
    return False


def test_cycling_is_detected_and_the_safeguard_converges():
    assert plain_pdas_cycles(CYCLING_A, CYCLING_B, CYCLING_U)
    qp = BoundConstrainedQP(CYCLING_A, CYCLING_B, -np.inf, CYCLING_U)
    sol = solve(qp, "active_set")
    assert sol.converged and sol.info["monotone_from"] is not None
    assert np.max(np.abs(sol.x - enumerate_kkt(CYCLING_A, CYCLING_B, CYCLING_U))) < 1e-10
    assert np.max(np.abs(solve(qp, "snes_vi").x - sol.x)) < 1e-10  # with its backtracking line search


def test_a_long_active_set_solve_logs_its_progress(monkeypatch, caplog):
    """Without a monitor, every PROGRESS_SECONDS (here 0: every iteration) a line names the iteration and residual: a
    long solid solve is seen working (the coupler's timeout counts from such lines) instead of
    silent for 17 minutes."""
    import logging

    from nonsmooth import active_set

    monkeypatch.setattr(active_set, "PROGRESS_SECONDS", 0.0)
    qp, _ = obstacle_2d()
    with caplog.at_level(logging.INFO, logger="varcouple.nonsmooth"):
        sol = active_set.solve_active_set(qp)
    lines = [r.getMessage() for r in caplog.records if r.name == "varcouple.nonsmooth"]
    assert sol.converged and len(lines) == sol.iterations >= 2, lines
    assert lines[0].startswith("active set iteration 1: residual ") and "Krylov iterations so far" in lines[0]


@pytest.mark.parametrize("problem", ["obstacle_2d", "two_sided_block"])
def test_the_amg_set_up_once_gives_the_from_scratch_solution(problem):
    """The AMG of the first iteration's system reused for the later ones (amg_reuse, the
    default) gives the solution of one set up anew at every iteration to the solver's
    tolerance, with one set-up per solve instead of one per iteration."""
    if problem == "obstacle_2d":
        qp, _ = obstacle_2d(32)
    else:
        m = 12
        A = sp.csr_matrix(sp.kron(laplacian_2d(m), sp.csr_matrix(np.array([[2.0, 0.5, 0.0], [0.5, 1.5, 0.2],
                                                                            [0.0, 0.2, 1.0]]))))
        b = np.random.default_rng(5).normal(size=A.shape[0])
        lower, upper = np.full(A.shape[0], -np.inf), np.full(A.shape[0], np.inf)
        lower[0::3], upper[2::3] = -0.05, 0.02
        qp = BoundConstrainedQP(A, b, lower, upper, block_size=3, near_nullspace=np.kron(np.ones((m * m, 1)), np.eye(3)))
    reused, scratch = solve(qp, "active_set"), solve(qp, "active_set", amg_reuse=False)
    assert reused.converged and scratch.converged and scratch.iterations >= 3
    assert np.array_equal(reused.active, scratch.active)
    assert np.max(np.abs(reused.x - scratch.x)) <= 1e-9 * np.max(np.abs(scratch.x))
    assert qp.kkt_residual(reused.x) < 1e-9
    assert reused.info["amg_setups"] == 1 and scratch.info["amg_setups"] == scratch.iterations


def test_a_reused_amg_whose_cg_stops_short_is_reported_unconverged():
    """The reused preconditioner's CG still has to reach ksp_rtol: capped where the first
    iteration's CG (its AMG freshly set up) still converges and a later one's (the AMG reused)
    does not, the solve says so at that iteration, never success."""
    qp, _ = obstacle_2d(32)
    capped = solve(qp, "active_set", ksp_max_it=12)
    assert not capped.converged and capped.info["amg_setups"] == 1
    assert "inner CG + GAMG reached its 12 iterations at active set iteration 2" in capped.reason


def test_snes_vi_takes_a_monitor_too():
    """The monitor is a keyword of every registered solver (the solid passes it whatever its
    solver: it tested for "active_set" and gave the others no progress lines)."""
    qp, _ = obstacle_2d(16)
    heard = []
    sol = solve(qp, "snes_vi", monitor=lambda **values: heard.append(values))
    assert sol.converged and [v["newton_iteration"] for v in heard] == list(range(sol.iterations + 1))
    assert heard[-1]["residual"] < 1e-10 * heard[0]["residual"]  # the function norm, iteration 0 first


def test_the_monitor_hears_every_active_set_and_cg_iteration():
    qp, _ = obstacle_2d(16)
    heard = []
    sol = solve(qp, "active_set", monitor=lambda **values: heard.append(values))
    outer = [v for v in heard if "active_set_iteration" in v]
    assert [v["active_set_iteration"] for v in outer] == list(range(1, sol.iterations + 1))
    assert [v["residual"] for v in outer] == sol.history
    assert sum(1 for v in heard if "cg_iteration" in v) >= sol.krylov_iterations


def test_a_control_reaches_its_target_in_one_solve():
    """A string pushed up against an obstacle (x <= 0.05), its left end fixed at a value c that
    is one more unknown (:class:`nonsmooth.Control`): c is found so that the string's mean is
    -0.1 in the one active-set solve, and the result solves the QP at that c (the same
    solution from scratch, KKT residual at round-off); the active sets change as c moves."""
    from nonsmooth import Control

    n = 60
    A = laplacian_1d(n)
    lower, upper = np.full(n, -np.inf), np.full(n, 0.05)
    lower[0] = upper[0] = 0.0  # the fixed end, moved by the control
    qp = BoundConstrainedQP(A, np.full(n, 0.5), lower, upper, block_size=1)
    unit = np.zeros(n)
    unit[0] = 1.0
    control = Control(np.zeros(n), unit, np.full(n, 1.0 / n), -0.1, 1.0)
    sol = solve(qp, "active_set", control=control, tol=1e-12)
    c = sol.info["control"]
    assert sol.converged and sol.x[0] == pytest.approx(c, abs=1e-14) and c < 0
    assert np.mean(sol.x) == pytest.approx(-0.1, rel=1e-9)
    assert qp.lower[0] == qp.upper[0] == pytest.approx(c, abs=1e-14)
    assert np.any(sol.x >= 0.05 - 1e-12)  # some of the string on the obstacle
    fresh = BoundConstrainedQP(A, np.full(n, 0.5), np.where(unit > 0, c, lower), np.where(unit > 0, c, upper))
    again = solve(fresh, "active_set", tol=1e-12)
    assert np.allclose(again.x, sol.x, rtol=0, atol=1e-9)
