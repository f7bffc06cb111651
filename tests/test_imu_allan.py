"""Allan deviation through allantools against a direct overlapping estimate and the white-noise closed form."""

import math

import numpy as np
import pytest

from leosop.ins import allan

RATE_HZ = 100.0
SIGMA = 0.01  # per-sample standard deviation of the white rate noise


def _direct_oadev(x, rate_hz, m):
    """Overlapping Allan deviation at m samples (IEEE Std 952, C.1): half the mean square of differences
    of adjacent overlapping m-sample averages, from the cumulative sum (the "phase")."""
    phase = np.r_[0.0, np.cumsum(x)] / rate_hz
    tau = m / rate_hz
    d = phase[2 * m:] - 2 * phase[m:-m] + phase[:-2 * m]
    return math.sqrt(np.mean(d**2) / (2 * tau**2))


def test_white_noise_matches_direct_estimate_and_closed_form():
    rng = np.random.default_rng(21)
    x = rng.normal(0.0, SIGMA, (100_000, 3))
    res = allan.allan(x, RATE_HZ)
    # allantools and the direct formula compute the same estimator: equal to rounding.
    for i in (0, 5, 10):
        m = int(round(res.tau_s[i] * RATE_HZ))
        assert res.adev[i, 0] == pytest.approx(_direct_oadev(x[:, 0], RATE_HZ, m), rel=1e-9)
    # White noise of density N = SIGMA / sqrt(rate): sigma^2(tau) = N^2 / tau. The estimate's relative
    # scatter at m samples is at most about 1 / sqrt(n / m) (less when overlapping): up to m = n / 1000 that is
    # 3 %, so 10 % is over 3 sigma.
    N = SIGMA / math.sqrt(RATE_HZ)
    short = res.tau_s * RATE_HZ <= x.shape[0] / 1000
    assert short.sum() >= 10
    assert np.allclose(res.adev[short], N / np.sqrt(res.tau_s[short, None]), rtol=0.10)
    # The read-off white density: within 2 % (averaged over the slope -1/2 region).
    assert np.allclose(res.white_density, N, rtol=0.02)


def test_bias_instability_of_a_random_walk_free_flat_floor():
    # White noise plus a constant bias: the bias drops out, the minimum is at the longest tau.
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, SIGMA, (50_000, 3)) + [1.0, -2.0, 0.5]
    res = allan.allan(x, RATE_HZ)
    assert np.all(res.tau_min_s == res.tau_s[-1])
    assert np.allclose(res.bias_instability * allan.BIAS_INSTABILITY_FACTOR, res.adev[-1])
