"""LAMBDA against the published three-ambiguity example and against brute-force enumeration."""

import itertools

import numpy as np
import pytest

from leosop.gnss.lambda_ import decorrelate, ils, ltdl, partial_fix

#: The example of [Teunissen 1995] reworked by [de Jonge 1996] (section 3) and in Strang & Borre (1997,
#: "Linear Algebra, Geodesy and GPS", section 15.5): float ambiguities and their covariance [cycles].
Q_EXAMPLE = np.array([[6.290, 5.978, 0.544], [5.978, 6.292, 2.340], [0.544, 2.340, 6.288]])
A_HAT = np.array([5.45, 3.10, 2.97])
#: Published results: the integer least-squares solution and the decorrelated covariance Z^T Q Z
#: (printed to 3 decimals there, hence the 1e-3 tolerance).
A_FIXED = np.array([5.0, 3.0, 4.0])
QZ_PUBLISHED = np.array([[4.476, 0.334, 0.230], [0.334, 1.146, 0.082], [0.230, 0.082, 0.626]])


def test_ltdl_reconstructs():
    L, D = ltdl(Q_EXAMPLE)
    assert np.allclose(np.diag(L), 1.0) and np.allclose(np.triu(L, 1), 0.0)
    np.testing.assert_allclose(L.T @ np.diag(D) @ L, Q_EXAMPLE, atol=1e-12)
    with pytest.raises(ValueError):
        ltdl(-Q_EXAMPLE)


def test_published_example():
    Z, L, D = decorrelate(Q_EXAMPLE)
    assert abs(round(np.linalg.det(Z))) == 1 and np.array_equal(Z, np.round(Z))
    # The decorrelated covariance is unique up to the order and sign of the z's: compare as printed.
    np.testing.assert_allclose(np.abs(Z.T @ Q_EXAMPLE @ Z), QZ_PUBLISHED, atol=1e-3)
    a, norms = ils(A_HAT, Q_EXAMPLE)
    np.testing.assert_array_equal(a[0], A_FIXED)
    # Squared norm of the best and second-best candidates, recomputed here in closed form.
    Qi = np.linalg.inv(Q_EXAMPLE)
    assert norms[0] == pytest.approx((A_HAT - A_FIXED) @ Qi @ (A_HAT - A_FIXED), rel=1e-10)
    assert norms[1] == pytest.approx((A_HAT - a[1]) @ Qi @ (A_HAT - a[1]), rel=1e-10) and norms[1] > norms[0]


def test_matches_brute_force():
    # Exhaustive search of a +-4 box around the rounded float solution is the definition of ILS for these
    # sizes (the box holds the optimum: every float sigma here is below 2 cycles after the scaling below).
    rng = np.random.default_rng(7)
    for _ in range(25):
        n = int(rng.integers(2, 5))
        A = rng.normal(size=(n, n))
        Q = A @ A.T * rng.uniform(0.05, 0.5) + 0.01 * np.eye(n)
        a_hat = rng.normal(size=n) * 5.0
        Qi = np.linalg.inv(Q)
        grid = itertools.product(*[range(int(v) - 4, int(v) + 5) for v in np.round(a_hat)])
        cost = sorted(((a_hat - np.array(g)) @ Qi @ (a_hat - np.array(g)), g) for g in grid)
        a, norms = ils(a_hat, Q)
        assert tuple(a[0]) == cost[0][1] and tuple(a[1]) == cost[1][1]
        np.testing.assert_allclose(norms, [cost[0][0], cost[1][0]], rtol=1e-9)


def test_partial_fix_drops_the_imprecise():
    # Five precise ambiguities (sigma 0.03 cycle) near integers and one hopeless one (sigma 3 cycles, at .5):
    # the full set can still pass; with the bad one made correlated and central, only the subset passes.
    rng = np.random.default_rng(3)
    truth = rng.integers(-20, 20, 6).astype(float)
    Q = np.diag([0.03**2] * 5 + [0.6**2])
    a_hat = truth + np.r_[rng.normal(0, 0.03, 5), 0.5]
    fixed, a_fix, ratio = partial_fix(a_hat, Q, ratio_min=3.0)
    assert fixed[:5].all() and not fixed[5] and ratio >= 3.0
    np.testing.assert_array_equal(a_fix[:5], truth[:5])
    # Nothing passes when every ambiguity sits half-way between integers.
    fixed, _, _ = partial_fix(np.full(4, 0.5), np.eye(4) * 0.01, min_fixed=2)
    assert not fixed.any()
