"""Kalman core against closed forms and a batch least-squares solution."""

import numpy as np
import pytest
from scipy import stats

from leosop.fusion.kalman import nees, nis, predict, update

# Closed forms are evaluated in double precision on well-conditioned numbers:
# agreement to 1e-12 relative leaves room for a few dozen rounding steps.
RTOL = 1e-12


def test_scalar_constant_matches_inverse_variance_weighting():
    # A constant observed n times: the posterior is the precision-weighted mean.
    rng = np.random.default_rng(1)
    p0, r, x0 = 4.0, 0.25, np.array([1.0])
    z = 3.0 + rng.normal(0.0, np.sqrt(r), 10)
    x, P = x0, np.array([[p0]])
    for zk in z:
        x, P, _, _ = update(x, P, np.array([zk]), np.eye(1), np.array([[r]]))
    p_expect = 1.0 / (1.0 / p0 + z.size / r)
    x_expect = p_expect * (x0[0] / p0 + z.sum() / r)
    assert P[0, 0] == pytest.approx(p_expect, rel=RTOL)
    assert x[0] == pytest.approx(x_expect, rel=RTOL)


def test_random_walk_reaches_the_riccati_steady_state():
    # x_{k+1} = x_k + w (var q), z = x + v (var r): the steady prior variance
    # solves P^2 - q P - q r = 0.
    q, r = 0.3, 2.0
    x, P = np.zeros(1), np.array([[100.0]])
    for _ in range(200):
        x, P = predict(x, P, np.eye(1), np.array([[q]]))
        x, P, _, S = update(x, P, np.zeros(1), np.eye(1), np.array([[r]]))
    p_prior = (q + np.sqrt(q * q + 4 * q * r)) / 2
    assert S[0, 0] == pytest.approx(p_prior + r, rel=1e-10)  # geometric convergence, 200 steps
    assert P[0, 0] == pytest.approx(p_prior * r / (p_prior + r), rel=1e-10)


def test_sequential_updates_equal_batch_least_squares():
    # Linear-Gaussian: a prior plus measurements is one weighted least squares.
    rng = np.random.default_rng(2)
    n, m = 4, 3
    x0 = rng.normal(size=n)
    A = rng.normal(size=(n, n))
    P0 = A @ A.T + n * np.eye(n)
    Hs = [rng.normal(size=(m, n)) for _ in range(3)]
    Rs = [np.diag(rng.uniform(0.5, 2.0, m)) for _ in range(3)]
    zs = [rng.normal(size=m) for _ in range(3)]
    x, P = x0, P0
    for z, H, R in zip(zs, Hs, Rs):
        x, P, _, _ = update(x, P, z, H, R)
    info = np.linalg.inv(P0) + sum(H.T @ np.linalg.inv(R) @ H for H, R in zip(Hs, Rs))
    rhs = np.linalg.inv(P0) @ x0 + sum(H.T @ np.linalg.inv(R) @ z for z, H, R in zip(zs, Hs, Rs))
    np.testing.assert_allclose(P, np.linalg.inv(info), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(x, np.linalg.solve(info, rhs), rtol=1e-10, atol=1e-12)


def test_predict_constant_velocity_closed_form():
    dt, q = 0.5, 0.1
    Phi = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    P0 = np.diag([4.0, 1.0])
    x, P = predict(np.array([1.0, 2.0]), P0, Phi, Q)
    np.testing.assert_allclose(x, [2.0, 2.0], rtol=RTOL)
    expect = np.array([[4.0 + dt**2 + q * dt**3 / 3, dt + q * dt**2 / 2], [dt + q * dt**2 / 2, 1.0 + q * dt]])
    np.testing.assert_allclose(P, expect, rtol=RTOL)


def test_nis_and_nees_are_chi_square_on_a_simulated_linear_system():
    # Constant-velocity target, position measured: a correct filter's NIS is
    # chi2(1) and NEES chi2(2) per step.
    rng = np.random.default_rng(3)
    dt, q, r = 1.0, 0.05, 1.0
    Phi = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    H, R = np.array([[1.0, 0.0]]), np.array([[r]])
    L = np.linalg.cholesky(Q)
    nis_all, nees_all = [], []
    for _ in range(50):
        P = np.diag([10.0, 1.0])
        truth = rng.multivariate_normal(np.zeros(2), P)
        x = np.zeros(2)
        for _ in range(40):
            truth = Phi @ truth + L @ rng.normal(size=2)
            x, P = predict(x, P, Phi, Q)
            z = H @ truth + rng.normal(0.0, np.sqrt(r), 1)
            x, P, y, S = update(x, P, z, H, R)
            nis_all.append(nis(y, S))
            nees_all.append(nees(truth - x, P))
    k = len(nis_all)
    # Means of k = 2000 chi-square draws: a 99.9 % two-sided interval.
    for values, dof in ((nis_all, 1), (nees_all, 2)):
        lo, hi = stats.chi2.ppf([0.0005, 0.9995], dof * k) / k
        assert lo < np.mean(values) < hi


def test_nis_is_vectorised_and_matches_the_quadratic_form():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(5, 3, 3))
    S = A @ np.swapaxes(A, 1, 2) + np.eye(3)
    y = rng.normal(size=(5, 3))
    expect = [yk @ np.linalg.inv(Sk) @ yk for yk, Sk in zip(y, S)]
    np.testing.assert_allclose(nis(y, S), expect, rtol=1e-10)
