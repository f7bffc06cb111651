"""Honest sigmas and physical solutions of the multi-pass static fix: residual correlation, horizon, mirror.

The two simulated VHF passes of ``test_doppler_ls.two_passes`` (one satellite, 2 s rows above 10 deg,
a cubic clock per pass) with white or AR(1) Doppler noise.
"""

import numpy as np
import pytest

from leosop.positioning.robust_ls import FixStatus
from leosop.positioning.static_passes import _sees, integrated_autocorrelation, solve_static_passes
from test_doppler_ls import two_passes  # noqa: F401  (the fixture)


def _ar1(rng, n, phi, sigma):
    """AR(1) series of stationary standard deviation ``sigma``: tau = (1 + phi) / (1 - phi)."""
    e = rng.normal(0.0, sigma * np.sqrt(1.0 - phi**2), n)
    x = np.empty(n)
    x[0] = rng.normal(0.0, sigma)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    return x


def test_integrated_autocorrelation_of_ar1_and_white_noise():
    rng = np.random.default_rng(1)
    # Reference: an AR(1) series with coefficient phi has tau = (1 + phi) / (1 - phi) exactly (9 for 0.8).
    # The estimator's standard deviation is ~tau sqrt(2 (2M + 1) / n) (Sokal): ~4% at M ~ 45, n = 1e5;
    # bound 15%.
    tau, M = integrated_autocorrelation(_ar1(rng, 100_000, 0.8, 1.0))
    assert tau == pytest.approx(9.0, rel=0.15) and 30 <= M <= 80
    # White noise: tau ~ 1 within 2 sqrt(M / n) per standard deviation (bound 4 of them).
    tau, M = integrated_autocorrelation(rng.normal(size=5000))
    assert abs(tau - 1.0) < 4 * 2 * np.sqrt(M / 5000)
    assert integrated_autocorrelation(np.ones(10)) == (1.0, 0) and integrated_autocorrelation([1.0, 2.0]) == (1.0, 0)


def test_white_residuals_leave_the_fix_unchanged(two_passes):  # noqa: F811
    (dop, pos, vel, f0, t_s, pass_id), station, _, _ = two_passes
    noisy = dop + np.random.default_rng(4).normal(0.0, 2.0, dop.shape)
    kw = dict(alt_m=95.0, alt_sigma_m=1.0, time_bias=False)
    on = solve_static_passes(noisy, 2.0, pos, vel, f0, t_s, pass_id, **kw)
    off = solve_static_passes(noisy, 2.0, pos, vel, f0, t_s, pass_id, decorrelate=False, **kw)
    # White residuals: no pass's tau is significantly above 1, so nothing is scaled or solved again.
    np.testing.assert_array_equal(on.tau, [1.0, 1.0])
    np.testing.assert_array_equal(on.pos_ecef_m, off.pos_ecef_m)
    np.testing.assert_array_equal(on.cov, off.cov)
    assert off.tau is None


def test_correlated_noise_gets_an_honest_sigma(two_passes):  # noqa: F811
    (dop, pos, vel, f0, t_s, pass_id), station, _, _ = two_passes
    rng = np.random.default_rng(11)
    kw = dict(alt_m=95.0, alt_sigma_m=1.0, time_bias=False, alpha=None, pos0_ecef_m=station)
    nees = {True: [], False: []}
    for _ in range(16):
        noise = np.concatenate([_ar1(rng, int((pass_id == p).sum()), 0.8, 2.0) for p in (0, 1)])
        for decorrelate in (True, False):
            fix = solve_static_passes(dop + noise, 2.0, pos, vel, f0, t_s, pass_id, decorrelate=decorrelate, **kw)
            assert fix.status == FixStatus.OK
            d = fix.pos_ecef_m - station
            nees[decorrelate].append(d @ np.linalg.solve(fix.cov[:3, :3], d))
    # Position NEES (3 dof, ~2 with the height held by its 1 m prior): the white-noise sigma ignores the
    # AR(1) correlation (tau = 9) and is ~3x too small, NEES ~9x too large (achieved: see the bounds' margin);
    # with each pass's sigma scaled by sqrt(tau estimated from its residuals) the mean NEES is near its dof.
    # Bounds: 16 seeds put the mean of a consistent NEES within ~[1, 4.5]; the white one is above 8.
    assert 1.0 < np.mean(nees[True]) < 4.5
    assert np.mean(nees[False]) > 8.0


def test_a_solution_must_see_the_satellites(two_passes):  # noqa: F811
    (dop, pos, vel, f0, t_s, pass_id), station, _, _ = two_passes
    used = np.ones((2, len(dop)), bool)
    # The station sees every row (all above 10 deg); its antipode sees none.
    np.testing.assert_array_equal(_sees(np.stack([station, -station]), pos, used), [True, False])
    # A row below the horizon that is not used does not count.
    low = np.zeros((1, len(dop)), bool)
    assert _sees(-station[None], pos, low)[0]
