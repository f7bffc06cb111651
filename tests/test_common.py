"""Satellite error-state bookkeeping shared by the loose and tight filters."""

import numpy as np
import pytest

from leosop.fusion import common


@pytest.mark.parametrize("orbit_model, per_sat", [("independent", 4), ("common", 1)])
def test_satellites_get_their_prior_and_are_marginalised_when_stale(orbit_model, per_sat):
    sats = common.SatelliteStates(16, orbit_model, 2.5, 1.5, 30.0)
    rng = np.random.default_rng(1)
    A = rng.standard_normal((16, 16))
    x_hat, P = sats.initial(np.arange(16.0), A @ A.T)
    n0 = 16 + (3 if orbit_model == "common" else 0)
    assert x_hat.size == n0
    x_hat, P = sats.see(x_hat, P, [7, 3], 0.0)
    x_hat, P = sats.see(x_hat, P, [3, 9], 10.0)
    assert P.shape == (n0 + 3 * per_sat,) * 2
    # Priors, exactly: offset mean and variance, orbit variance, uncorrelated.
    c7, o7 = sats.columns(7)
    c9, o9 = sats.columns(9)
    assert (x_hat[c7], P[c7, c7]) == (2.5, 1.5**2)
    np.testing.assert_array_equal(np.diag(P)[o9], np.full(3, 900.0))
    assert not P[c9, :c9].any()
    # Common model: every satellite shares the same orbit columns after the first 16.
    assert (o7 == o9) == (orbit_model == "common")
    # Correlate everything, then let satellite 7 go stale (last seen at 0 s):
    # dropping its states is Gaussian marginalisation, i.e. the other states'
    # mean and covariance are the sub-vector and sub-matrix, to the bit.
    B = rng.standard_normal(P.shape)
    P = B @ B.T
    x_hat = rng.standard_normal(x_hat.size)
    keep = np.setdiff1d(np.arange(P.shape[0]), np.arange(c7, c7 + per_sat))
    x_kept, P_kept = sats.see(x_hat, P, [9], common.DROP_AFTER_S + 0.5)
    assert sats.ids == [3, 9]
    np.testing.assert_array_equal(x_kept, x_hat[keep])
    np.testing.assert_array_equal(P_kept, P[np.ix_(keep, keep)])
    # Satellite 3 was last seen at 10 s: kept until 10 + DROP_AFTER_S.
    sats.see(x_kept, P_kept, [], 10.0 + common.DROP_AFTER_S)
    assert sats.ids == [3, 9]
