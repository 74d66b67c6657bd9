"""Accelerators of the coupling iteration on a synthetic linear fixed point ``x = H(x) = A x + b``.

``A = P diag(lambda) P^-1`` with a non-orthogonal ``P`` (so ``A`` is not
symmetric) and prescribed eigenvalues: with ``lambda`` in [-1.5, 0.5] the plain
iteration diverges (spectral radius 1.5, a strong added-mass-like effect), with
``lambda`` in [0.3, 0.95] it converges slowly. Iteration counts are evaluations of
``H`` per window as the coupling loop counts them (the last one is the
evaluation that finds the residual below the tolerance).
"""

from __future__ import annotations

import numpy as np
import pytest

from coupler.coupling.acceleration import IQNILS, Aitken, ConstantRelaxation, filtered_qr, make_accelerator
from coupler.coupling.loop import CouplingDiverged, run_coupled


def linear_problem(n, lo, hi, seed=0):
    rng = np.random.default_rng(seed)
    P = np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)
    A = P @ np.diag(np.linspace(lo, hi, n)) @ np.linalg.inv(P)
    b = rng.standard_normal(n)
    return A, b, np.linalg.solve(np.eye(n) - A, b)


def iterations(A, b, accelerator, tolerance=1e-10, max_iterations=2000, weights=None):
    result = run_coupled(1, 1.0, lambda window, k, x: A @ x + b, np.zeros(len(b)), accelerator,
                         tolerance=tolerance, max_iterations=max_iterations, weights=weights)
    assert result.all_converged
    return result.iterations[0], result.x


def nonuniform_masses(n, seed=3):
    return np.random.default_rng(seed).uniform(0.01, 10.0, n)


# ---------------------------------------------------------------------------------------------- IQN-ILS


@pytest.mark.parametrize("n", [10, 20])
@pytest.mark.parametrize("spectrum", [(-1.5, 0.5), (0.3, 0.95)], ids=["divergent", "slow"])
@pytest.mark.parametrize("weighted", [False, True], ids=["euclidean", "mass"])
def test_iqnils_solves_a_linear_fixed_point_in_n_plus_one_iterations(n, spectrum, weighted):
    """After n+1 iterations (n secant columns span R^n) the iterate is the fixed point (GMRES-equivalence).

    In floating point the secant matrix V is ill-conditioned by then (the residual
    differences shrink with the residual: cond(V) ~ 1e10 for the slow n = 20
    case), which limits the accuracy of iterate n+1 there to ~1e-9; iterate n+2
    is exact to rounding in all cases.
    """
    A, b, x_star = linear_problem(n, *spectrum)
    weights = nonuniform_masses(n) if weighted else None
    acc = IQNILS(omega0=0.5, filter="QR2", filter_eps=1e-12, weights=weights)
    acc.start_window()
    x = np.zeros(n)
    errors = []
    for _ in range(n + 2):
        x = acc.update(x, A @ x + b)
        errors.append(np.linalg.norm(x - x_star) / np.linalg.norm(x_star))
    ill_conditioned = (n, spectrum) == (20, (0.3, 0.95))
    assert errors[n] <= (1e-8 if ill_conditioned else 1e-10)  # iterate x_{n+1}
    assert errors[n + 1] <= 1e-12
    # the loop: at most n+1 iterations with updates, the (n+2)-th evaluation finds the residual < 1e-10
    # (one more where x_{n+1} is only accurate to ~1e-9)
    its, x_loop = iterations(A, b, IQNILS(0.5, filter_eps=1e-12), weights=weights)
    assert its <= n + 2 + ill_conditioned
    np.testing.assert_allclose(x_loop, x_star, rtol=0, atol=1e-9 * np.linalg.norm(x_star))


@pytest.mark.parametrize("n", [10, 20])
def test_accelerators_ranked_constant_aitken_iqnils(n):
    """Aitken beats the best constant relaxation; IQN-ILS beats Aitken (lambda in [-1.5, 0.5])."""
    A, b, x_star = linear_problem(n, -1.5, 0.5)
    # 1 - omega (1 - lambda) with 1 - lambda in [0.5, 2.5]: omega = 2/3 is the optimal constant (rate 2/3)
    constant, _ = iterations(A, b, ConstantRelaxation(2.0 / 3.0))
    aitken, x_aitken = iterations(A, b, Aitken(omega0=0.5))
    iqn, _ = iterations(A, b, IQNILS(omega0=0.5, filter_eps=1e-12))
    assert aitken < constant
    assert iqn < aitken
    assert iqn <= n + 2
    np.testing.assert_allclose(x_aitken, x_star, atol=1e-8 * np.linalg.norm(x_star))


def test_aitken_beats_constant_relaxation_on_a_slow_problem():
    """lambda in [0.3, 0.95]: plain iteration converges slowly; Aitken over-relaxes."""
    A, b, _ = linear_problem(20, 0.3, 0.95)
    constant, _ = iterations(A, b, ConstantRelaxation(1.0))
    aitken, _ = iterations(A, b, Aitken(omega0=1.0))
    assert aitken < constant / 2


def test_aitken_factor_is_the_secant_formula():
    """omega_1 = -omega_0 (r_0, r_1 - r_0) / ||r_1 - r_0||^2 (Küttler & Wall 2008), M-weighted."""
    rng = np.random.default_rng(0)
    m = nonuniform_masses(6)
    acc = Aitken(omega0=0.4, weights=m)
    acc.start_window()
    x0, Hx0 = rng.standard_normal(6), rng.standard_normal(6)
    x1 = acc.update(x0, Hx0)
    np.testing.assert_allclose(x1, x0 + 0.4 * (Hx0 - x0))
    Hx1 = rng.standard_normal(6)
    r0, r1 = Hx0 - x0, Hx1 - x1
    omega = -0.4 * np.sum(m * r0 * (r1 - r0)) / np.sum(m * (r1 - r0) ** 2)
    np.testing.assert_allclose(acc.update(x1, Hx1), x1 + omega * r1, rtol=1e-14)
    assert acc.omega == pytest.approx(omega)
    # |omega| is capped at omega_max, in the first iteration as in the later ones
    A, b, _ = linear_problem(10, -1.5, 0.5)
    capped = Aitken(omega0=0.9, omega_max=0.3)
    capped.start_window()
    x = np.zeros(10)
    for _ in range(8):
        x = capped.update(x, A @ x + b)
    assert capped.history[0] == 0.3 and max(abs(w) for w in capped.history) <= 0.3


def test_constant_relaxation_with_too_large_omega_diverges_clearly():
    A, b, _ = linear_problem(10, -1.5, 0.5)
    # |1 - omega (1 - lambda)| = |1 - 1.0 * 2.5| = 1.5 > 1
    with pytest.raises(CouplingDiverged) as info:
        run_coupled(3, 0.1, lambda window, k, x: A @ x + b, np.zeros(10), ConstantRelaxation(1.0),
                    tolerance=1e-10, max_iterations=500)
    err = info.value
    assert err.step == 0 and err.reason == "divergence"
    assert "time step 0" in str(err) and "diverges" in str(err) and "constant" in str(err)
    # without the blow-up check the iteration runs to max_iterations and says so
    with pytest.raises(CouplingDiverged) as info:
        run_coupled(3, 0.1, lambda window, k, x: A @ x + b, np.zeros(10), ConstantRelaxation(0.9),
                    tolerance=1e-10, max_iterations=30, divergence_factor=None)
    err = info.value
    assert (err.step, err.iterations, err.reason) == (0, 30, "max_iterations")
    assert err.residual == err.residuals[-1] > 1e-10
    assert "did not converge in time step 0" in str(err) and "30 iterations" in str(err)
    assert f"{err.residual:.3g}" in str(err)
    assert err.result is not None and err.result.steps == []


def test_reuse_of_past_windows_reduces_iterations():
    """b changes a little each window; the columns of past windows stay valid secants of the same A."""
    n = 20
    A, b, _ = linear_problem(n, -1.5, 0.5)
    perturbations = 0.01 * np.random.default_rng(7).standard_normal((10, n))

    def run(reuse):
        acc = IQNILS(omega0=0.5, reuse=reuse, filter="QR2", filter_eps=1e-8)
        result = run_coupled(10, 0.1, lambda w, k, x: A @ x + b + perturbations[w.index], np.zeros(n), acc,
                             tolerance=1e-8, max_iterations=100)
        return result.iterations, acc

    fresh, _ = run(0)
    reused, acc = run(4)
    kept_all, _ = run(9)
    assert reused[0] == fresh[0] == kept_all[0]  # nothing to reuse in the first window
    assert sum(reused[1:]) < 0.5 * sum(fresh[1:])
    assert max(kept_all[2:]) <= 3  # the first window's columns span R^n and are never dropped
    assert acc.filtered_columns > 0  # more columns than dofs: the dependent ones were filtered


# ------------------------------------------------------------------------------------------- QR filter


@pytest.mark.parametrize("kind", ["QR1", "QR2"])
def test_filter_removes_duplicated_columns(kind):
    rng = np.random.default_rng(1)
    v1, v2 = rng.standard_normal(12), rng.standard_normal(12)
    qr = filtered_qr(np.column_stack([v1, v2, v1, 2 * v2, v1 + v2]), kind, 1e-8)
    assert qr.kept == [0, 1] and qr.removed == [2, 3, 4]
    np.testing.assert_allclose(qr.Q @ qr.R, np.column_stack([v1, v2]), atol=1e-13)
    np.testing.assert_allclose(qr.Q.T @ qr.Q, np.eye(2), atol=1e-13)


def test_qr2_filters_nearly_dependent_columns_relative_to_their_norm():
    rng = np.random.default_rng(2)
    v1, v2, noise = rng.standard_normal((3, 30))
    V = np.column_stack([v1, 1e-3 * v2, v1 + 1e-6 * noise])
    assert filtered_qr(V, "QR2", 1e-4).kept == [0, 1]  # small but independent: kept
    assert filtered_qr(V, "QR2", 1e-8).kept == [0, 1, 2]
    # QR1 compares |R_ii| with eps ||R||_F: a small column is dropped like a dependent one
    assert filtered_qr(V, "QR1", 1e-2).kept == [0]
    assert filtered_qr(V, "QR1", 1e-8).kept == [0, 1, 2]


def test_iqnils_with_repeated_input_does_not_crash_and_gives_the_same_update():
    """Feeding the same (x, H(x)) twice adds a zero secant; it is filtered, the update is unchanged."""
    A, b, _ = linear_problem(10, -1.5, 0.5)
    plain, repeated = IQNILS(0.5), IQNILS(0.5)
    for acc in (plain, repeated):
        acc.start_window()
    x_a = x_b = np.zeros(10)
    for _ in range(4):
        x_a = plain.update(x_a, A @ x_a + b)
        x_b = repeated.update(x_b, A @ x_b + b)
    # repeat the last evaluation: a zero column (r_k - r_k) appears
    y_plain = plain.update(x_a, A @ x_a + b)
    y_first = repeated.update(x_b, A @ x_b + b)
    y_again = repeated.update(x_b, A @ x_b + b)
    np.testing.assert_allclose(y_first, y_plain, rtol=1e-14)
    np.testing.assert_allclose(y_again, y_first, rtol=1e-12, atol=1e-14)
    assert repeated.filtered_columns >= 1


def solve_window(acc, A, b, x, tolerance=1e-10, max_iterations=100):
    """One window by hand: start_window, update until converged, end_window; returns (iterations, x)."""
    acc.start_window()
    for k in range(1, max_iterations + 1):
        Hx = A @ x + b
        if np.linalg.norm(Hx - x) <= tolerance * np.linalg.norm(Hx):
            acc.end_window(x, Hx)
            return k, Hx
        x = acc.update(x, Hx)
    raise AssertionError("no convergence")


@pytest.mark.parametrize("kind", ["QR1", "QR2"])
def test_iqnils_identical_windows_filter_reused_columns(kind):
    """The same window solved again and again with reuse: old and new columns are dependent; no crash, same x."""
    n = 10
    A, b, x_star = linear_problem(n, 0.3, 0.95)
    acc = IQNILS(0.5, reuse=3, filter=kind, filter_eps=1e-10)
    counts = []
    for _ in range(4):
        its, x = solve_window(acc, A, b, np.zeros(n))
        counts.append(its)
        np.testing.assert_allclose(x, x_star, atol=1e-9 * np.linalg.norm(x_star))
    assert counts[0] <= n + 2
    assert max(counts[1:]) <= 3  # the reused columns already span R^n
    assert acc.filtered_columns > 0
    assert acc.columns <= n


def test_factory_and_bad_parameters():
    assert isinstance(make_accelerator("constant", 0.3), ConstantRelaxation)
    assert isinstance(make_accelerator("aitken", 0.3), Aitken)
    acc = make_accelerator("iqn-ils", 0.3, reuse=8, filter="QR1", filter_eps=1e-6)
    assert isinstance(acc, IQNILS) and acc.reuse == 8 and acc.info()["filter"] == "QR1"
    with pytest.raises(ValueError, match="unknown acceleration"):
        make_accelerator("broyden")
    with pytest.raises(ValueError, match="filter"):
        IQNILS(0.5, filter="QR7")
    with pytest.raises(ValueError, match="omega"):
        ConstantRelaxation(0.0)
    with pytest.raises(ValueError, match="weights"):
        IQNILS(0.5, weights=[1.0, -1.0])
    acc = IQNILS(0.5)
    acc.start_window()
    acc.update(np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match="size"):
        acc.update(np.zeros(4), np.ones(4))


# ------------------------------------------------------------------- a limited number of columns


def test_column_limit_keeps_the_newest_secants():
    """``max_columns`` (scene: ``[coupling] columns``): at most that many secant pairs, the
    newest first, so that secants made far from the solution of a nonlinear map are forgotten."""
    A, b, _ = linear_problem(12, 0.3, 0.95)
    acc = IQNILS(omega0=0.5, max_columns=3, filter="none")
    x, r_prev, Hx_prev = np.zeros(12), None, None
    for k in range(6):
        Hx = A @ x + b
        r = Hx - x
        x_next = acc.update(x, Hx)
        assert acc.columns == min(k, 3)
        if r_prev is not None:
            np.testing.assert_allclose(acc.V[:, 0], r - r_prev, rtol=1e-14)
            np.testing.assert_allclose(acc.W[:, 0], Hx - Hx_prev, rtol=1e-14)
        r_prev, Hx_prev, x = r, Hx, x_next
    limited, x_limited = iterations(A, b, IQNILS(omega0=0.5, max_columns=3, filter_eps=1e-8))
    full, _ = iterations(A, b, IQNILS(omega0=0.5, filter_eps=1e-8))
    assert np.allclose(x_limited, np.linalg.solve(np.eye(12) - A, b), atol=1e-8)
    assert full <= 15 < 30 < limited, (full, limited)  # a linear map wants every column (measured 15 and 60)


def test_scene_columns_reach_the_accelerator(tmp_path):
    from coupler.errors import SceneError
    from coupler.scene import load
    from test_scene_plan import FLUID, scene_text, write

    scene = load(write(tmp_path, scene_text('["elasticity", "flow"]', FLUID + "columns = 3\n")))
    assert scene.coupling["columns"] == 3
    assert make_accelerator("iqn-ils", max_columns=scene.coupling["columns"]).max_columns == 3
    assert load(write(tmp_path, scene_text('["elasticity", "flow"]', FLUID))).coupling["columns"] == 100
    with pytest.raises(SceneError, match=r"\[coupling\] columns: must be an integer >= 1"):
        load(write(tmp_path, scene_text('["elasticity", "flow"]', FLUID + "columns = 0\n")))
