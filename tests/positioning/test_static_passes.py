"""Honest sigmas and physical solutions of the multi-pass static fix: residual correlation, horizon, mirror,
pass offsets.

The two simulated VHF passes of the ``two_passes`` fixture (one satellite, 2 s rows above 10 deg,
a cubic clock per pass) with white or AR(1) Doppler noise; for the pass offsets, the 7 Starlink-like
satellites of the ``starlink_like`` fixture (one receiver clock) with each satellite's states offset
or its time shifted (along its inertial orbit, or with the Earth: a time tag).
"""

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm as norm_dist

from leosop.frames import rotate_to_later_ecef
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef, state_ecef_pairs
from leosop.geometry.dop import cofactor
from leosop.positioning.passes_model import PassesModel, pass_rows
from leosop.positioning.passes_noise import integrated_autocorrelation, pass_disagreement
from leosop.positioning.robust_ls import FixStatus
from leosop.positioning.static_passes import SAT_OFFSET_SIGMA_HZ, TIME_OFFSET_SIGMA_S, _sees, solve_static_passes

from tests.positioning.helpers import F0_HZ, common_truth, doppler_hz


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


def test_white_residuals_leave_the_fix_unchanged(two_passes):
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


def test_correlated_noise_gets_an_honest_sigma(two_passes):
    (dop, pos, vel, f0, t_s, pass_id), station, _, _ = two_passes
    rng = np.random.default_rng(11)
    kw = dict(alt_m=95.0, alt_sigma_m=1.0, time_bias=False, alpha=None, pos0_ecef_m=station)
    nees = {True: [], False: []}
    for _ in range(16):
        noise = np.concatenate([_ar1(rng, int((pass_id == p).sum()), 0.8, 2.0) for p in (0, 1)])
        for decorrelate in (True, False):
            # The baseline without the disagreement test either: its variance factor takes up part of the
            # excess (mean NEES 5.3 instead of the white sigma's ~9x).
            fix = solve_static_passes(dop + noise, 2.0, pos, vel, f0, t_s, pass_id, decorrelate=decorrelate,
                                      pass_offsets=decorrelate, **kw)
            assert fix.status == FixStatus.OK
            d = fix.pos_ecef_m - station
            nees[decorrelate].append(d @ np.linalg.solve(fix.cov[:3, :3], d))
    # Position NEES (3 dof, ~2 with the height held by its 1 m prior): the white-noise sigma ignores the
    # AR(1) correlation (tau = 9) and is ~3x too small, NEES ~9x too large (achieved: see the bounds' margin);
    # with each pass's sigma scaled by sqrt(tau estimated from its residuals) the mean NEES is near its dof.
    # Bounds: 16 seeds put the mean of a consistent NEES within ~[1, 4.5]; the white one is above 8.
    assert 1.0 < np.mean(nees[True]) < 4.5
    assert np.mean(nees[False]) > 8.0


def test_a_solution_must_see_the_satellites(two_passes):
    (dop, pos, vel, f0, t_s, pass_id), station, _, _ = two_passes
    used = np.ones((2, len(dop)), bool)
    # The station sees every row (all above 10 deg); its antipode sees none.
    np.testing.assert_array_equal(_sees(np.stack([station, -station]), pos, used), [True, False])
    # A row below the horizon that is not used does not count.
    low = np.zeros((1, len(dop)), bool)
    assert _sees(-station[None], pos, low)[0]


def _offset_truth(p, v, sat, rng, sigma_m):
    """Satellite positions moved by each satellite's own radial and cross-track offset, N(0, sigma_m^2) each."""
    e_r = p / np.linalg.norm(p, axis=-1, keepdims=True)
    h = np.cross(p, v)
    e_c = h / np.linalg.norm(h, axis=-1, keepdims=True)
    b = rng.normal(0.0, sigma_m, (sat.max() + 1, 2))
    return p + b[sat, :1] * e_r + b[sat, 1:] * e_c


def test_pass_offsets_are_found_and_priced_into_the_covariance(starlink_like):
    geo, rate, p, v, t_s, sat, rx = starlink_like
    kw = dict(clock="common", pos0_ecef_m=rx, alpha=None)
    nees = {True: [], False: []}
    found = []
    for seed in range(12):
        rng = np.random.default_rng(200 + seed)
        extra, *_ = common_truth(rate, t_s, sat, rng)
        # Truth: each satellite's states off by 30 m radial and cross-track (1 sigma), the solver given the
        # nominal ones; 7 satellites x 60 s at 0.3 Hz determine the position to ~1 m, so such offsets are
        # seen as disagreement between the satellites.
        moved = _offset_truth(p, v, sat, rng, 30.0)
        y = doppler_hz(moved[None], v[None], rx[None], np.zeros((1, 3)), np.zeros(1))[0] + extra
        y = y + rng.normal(0.0, 0.3, y.shape)
        for on in (True, False):
            fix = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, pass_offsets=on, **kw)
            assert fix.status in (FixStatus.OK, FixStatus.INCONSISTENT)
            d = fix.pos_ecef_m - rx
            nees[on].append(d @ np.linalg.solve(fix.cov[:3, :3], d))
            if on:
                found.append(fix.pass_offset_sigma_m)
    # The score test finds the offsets in every seed (achieved 12/12; bound 9/12) and the estimated s is
    # the injected 30 m's (achieved median 29 m, 13-48 m per seed: a variance from 14 offsets scatters
    # by ~40%; bounds 15-60 m on the median).
    found = np.array(found)
    assert (found > 0).mean() >= 0.75 and 15.0 < np.median(found) < 60.0
    # Position NEES (3 dof): without the offsets' variance it is in the hundreds (achieved mean 904); with
    # it near its dof (achieved mean 5.8: an s estimated low costs more NEES than one estimated high
    # saves, so the mean sits above 3). Bounds: 1-8 and above 100.
    assert 1.0 < np.mean(nees[True]) < 8.0
    assert np.mean(nees[False]) > 100.0


def test_consistent_passes_leave_the_covariance_bit_identical(starlink_like):
    geo, rate, p, v, t_s, sat, rx = starlink_like
    extra, *_ = common_truth(rate, t_s, sat, np.random.default_rng(2))
    y = geo + extra + np.random.default_rng(3).normal(0.0, 0.3, geo.shape)
    kw = dict(clock="common", pos0_ecef_m=rx, alpha=None)
    on = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, **kw)
    off = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, pass_offsets=False, **kw)
    # No offsets injected: the score test stays below dof + 3 sqrt(2 dof) and nothing is added. 7 passes x 2
    # offsets, less one direction whose information is 3e-9 of the largest (below the rank cut, near round-off).
    assert on.pass_offset_sigma_m == 0.0 and on.pass_offset_dof == 13
    assert on.pass_offset_chi2 < on.pass_offset_dof + 3 * np.sqrt(2 * on.pass_offset_dof)
    np.testing.assert_array_equal(on.cov, off.cov)
    np.testing.assert_array_equal(on.pos_ecef_m, off.pos_ecef_m)
    assert off.pass_offset_sigma_m is None


#: Eigenvalues of the pass offsets' information F on DopTrack 2020-04-07 (three passes, time offsets on;
#: [Hz^2/m^2]): the spread of a real few-pass day, with directions the offsets' variance could take.
DOPTRACK_3_PASS_F_EIGENVALUES = (2.51e-11, 5.02e-11, 1.11e-10, 1.11e-8, 3.88e-7, 1.82e-6)


def test_a_variance_factor_from_three_passes_keeps_the_nees_at_its_dof():
    # The fix's error (along N^-1, variance k2 N^-1) is independent of the offsets' score (it is a residual
    # contrast), so its NEES against k2_hat N^-1 has mean dim x E[k2 / k2_hat]. Truth: a factor 4 (DopTrack's
    # all-pass fit gives ~5), no offsets, 6 dof. A plug-in ML factor gives E[k2 / k2_hat] = 6 / 4 for a
    # factor alone (its NEES is F-distributed; achieved 1.52 with the offsets' component fitted beside it).
    # With the Student-t factor: achieved 1.056; sd of one ratio 0.77, so 0.017 over 2000 draws; the 5 %
    # left is the offsets' component taking part of the excess in the third of the draws that fit one
    # (which lowers k2_hat). Bounds 0.95-1.15.
    lam = np.array(DOPTRACK_3_PASS_F_EIGENVALUES)
    rng = np.random.default_rng(7)
    k2 = 4.0
    ratio = [k2 / pass_disagreement(np.diag(lam), np.sqrt(k2 * lam) * rng.standard_normal(lam.size))[0]
             for _ in range(2000)]
    assert 0.95 < np.mean(ratio) < 1.15


def test_element_set_sigma_floors_the_offsets_variance(starlink_like):
    """The element sets' radial / cross-track sigma enters the covariance as the fix's sensitivity to them.

    Reference: the fix solved again with one satellite's states moved by one sigma along one axis, for
    each satellite and axis (a second, finite-difference computation of the sandwich term): the
    covariance the prior adds must be the sum of those shifts' outer products (sigmas 35-69 m here).
    The shifts are linear in the 30 / 60 m offsets to ~1e-4 (offset over range), the fixes converge to
    1e-3 of their sigma (0.3 m of the shifts' tens of metres); achieved 2e-4 of the largest element,
    bound 1e-3.
    """
    geo, rate, p, v, t_s, sat, rx = starlink_like
    extra, *_ = common_truth(rate, t_s, sat, np.random.default_rng(2))
    y = geo + extra + np.random.default_rng(3).normal(0.0, 0.3, geo.shape)
    kw = {"clock": "common", "pos0_ecef_m": rx, "alpha": None}
    sigma_rc = np.array([30.0, 60.0])
    off = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, **kw)
    on = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, orbit_sigma_rc_m=sigma_rc, **kw)
    np.testing.assert_array_equal(on.pos_ecef_m, off.pos_ecef_m)  # the fix itself is unchanged
    e_r = p / np.linalg.norm(p, axis=-1, keepdims=True)
    e_c = np.cross(p, v)
    e_c /= np.linalg.norm(e_c, axis=-1, keepdims=True)
    added = np.zeros((3, 3))
    for k in range(7):
        for axis, s in zip((e_r, e_c), sigma_rc):
            moved = p + np.where((sat == k)[:, None], s * axis, 0.0)
            d = solve_static_passes(y, 0.3, moved, v, F0_HZ, t_s, sat, pass_offsets=False, **kw).pos_ecef_m - \
                off.pos_ecef_m
            added += np.outer(d, d)
    np.testing.assert_allclose(on.cov[:3, :3] - off.cov[:3, :3], added, atol=1e-3 * np.abs(added).max())


def test_each_time_offset_model_fits_its_own_shift_and_not_the_other(starlink_like):
    """A time-tag error (ECEF states at t + dt, the Earth turned with them) against an element set's along-track
    error (inertial orbit at t + dt, the Earth not turned: the same states rotated east by omega_e dt).

    The Doppler is built from SGP4 states at the shifted times (no first-order column involved); each model
    fits its own shift to second order and leaves the other's east shift, ~7 % of the along-track one, in the
    residuals and the position.
    """
    geo, rate, p, v, t_s, sat, rx = starlink_like
    const = load_constellation()
    t0 = np.datetime64("2025-01-01T04:00:00", "ns")  # the fixture's epoch
    pos0, _, _ = state_ecef(const, [t0])
    sat_index = np.argmin(np.linalg.norm(pos0[:, 0][None] - p[t_s == 0][:, None], axis=-1), axis=1)
    dt_s = np.random.default_rng(5).normal(0.0, 0.01, 7)[sat]  # 75 m along-track, 5 m east
    t_shift = t0 + np.round((t_s + dt_s) * 1e9).astype("timedelta64[ns]")
    p_tag, v_tag, _ = state_ecef_pairs(const, sat_index[sat], t_shift)
    shifted = {"earth_fixed": (p_tag, v_tag),
               "inertial": (rotate_to_later_ecef(p_tag, -dt_s), rotate_to_later_ecef(v_tag, -dt_s))}
    clock_hz = 1.5e3 - 0.7 * (t_s - 29.5)
    sigma_hz = 1e-3
    for truth, (p_true, v_true) in shifted.items():
        y = doppler_hz(p_true[None], v_true[None], rx[None], np.zeros((1, 3)), np.zeros(1))[0] + clock_hz
        fits = {model: solve_static_passes(y, sigma_hz, p, v, F0_HZ, t_s, sat, clock="common", pos0_ecef_m=rx,
                                           time_bias_sigma_s=None, alpha=None, decorrelate=False, pass_offsets=False,
                                           time_offset_model=model) for model in ("earth_fixed", "inertial")}
        right, wrong = fits[truth], fits["inertial" if truth == "earth_fixed" else "earth_fixed"]
        assert right.status == wrong.status == FixStatus.OK and right.time_offset_model == truth
        # Its own model: left over is the second-order term dt^2 / 2 x the Doppler's acceleration (~1e-4 Hz
        # at 0.01 s). Achieved rms 5e-5 Hz (chi2/dof 0.003), 2 cm, offsets to 3 us. Bounds: chi2/dof 0.01,
        # 10 cm, 20 us.
        assert right.chi2 / right.dof < 0.01 and np.linalg.norm(right.pos_ecef_m - rx) < 0.1
        np.testing.assert_allclose(right.time_bias_s, dt_s[t_s == 0], rtol=0, atol=2e-5)
        # The other model leaves the east shift omega_e |r| dt (up to 5 m here) partly in the position, partly
        # in residuals of ~3 mHz. Achieved chi2/dof 8.8 and 10.2 (3,000x its own model's), 3.9 and 4.1 m.
        # Bounds: chi2/dof 3 and 300x, 1 m.
        assert wrong.chi2 / wrong.dof > max(3.0, 300 * right.chi2 / right.dof)
        assert np.linalg.norm(wrong.pos_ecef_m - rx) > 1.0


def _block_rows(starlink_like, rng, block_sigma_hz):
    """``starlink_like`` rows with white noise (0.2-0.6 Hz) plus a frequency error common to each instant's rows."""
    geo, rate, p, v, t_s, sat, rx = starlink_like
    extra, *_ = common_truth(rate, t_s, sat, rng)
    sigma = rng.uniform(0.2, 0.6, t_s.size)
    block = t_s.astype(int)
    common = block_sigma_hz * rng.standard_normal(block.max() + 1)
    return geo + extra + sigma * rng.standard_normal(t_s.size) + common[block], sigma, block


def test_block_states_are_the_generalised_least_squares_of_the_correlated_rows(starlink_like):
    """One state per block with prior q is GLS with the block covariance diag(sigma^2) + q 1 1^T.

    Reference: that GLS written out densely (420 x 420 covariance, its inverse) on the linearised model
    (position by central differences, receiver offset and drift, satellite offsets and time offsets with
    their priors), iterated from the truth. It and the fix differ by the time offsets' Doppler-rate
    column, evaluated at the truth here and at the iterate in the fix (achieved 2 cm and 0.3 % of the
    covariance; bounds 0.1 m, 1.5 % of the ~5 m sigma, and 2 %).
    Second: a block per row is the independent model with q added to each row's variance (the two
    iterations stop within 1e-3 of the sigma of each other, 5 mm; achieved 0.06 mm).
    """
    geo, rate, p, v, t_s, sat, rx = starlink_like
    q_sig = 0.31  # the consumer preset's LO noise over a 20 ms snapshot
    y, sigma, block = _block_rows(starlink_like, np.random.default_rng(40), q_sig)
    kw = dict(clock="common", pos0_ecef_m=rx, alpha=None, decorrelate=False, pass_offsets=False)
    fix = solve_static_passes(y, sigma, p, v, F0_HZ, t_s, sat, block_id=block, block_sigma_hz=q_sig, **kw)
    assert fix.status == FixStatus.OK and fix.cov.shape == (19, 19)  # the blocks' states marginalised out

    def model(x):
        return doppler_hz(p[None], v[None], x[None], np.zeros((1, 3)), np.zeros(1))[0]

    one_hot = np.eye(block.max() + 1)[block]
    C_inv = np.linalg.inv(np.diag(sigma**2) + q_sig**2 * one_hot @ one_hot.T)
    prior = np.diag([0.0] * 5 + [1.0 / SAT_OFFSET_SIGMA_HZ**2] * 7 + [1.0 / TIME_OFFSET_SIGMA_S**2] * 7)
    x = rx.copy()
    for _ in range(3):
        D = np.stack([model(x + e) - model(x - e) for e in np.eye(3)], 1) / 2.0
        H = np.hstack([D, np.ones((t_s.size, 1)), (t_s - 29.5)[:, None], np.eye(7)[sat],
                       np.eye(7)[sat] * rate[:, None]])
        N = H.T @ C_inv @ H + prior
        x = x + np.linalg.solve(N, H.T @ C_inv @ (y - model(x)))[:3]
    cov = np.linalg.inv(N)[:3, :3]
    assert np.linalg.norm(fix.pos_ecef_m - x) < 0.1
    np.testing.assert_allclose(fix.cov[:3, :3], cov, rtol=0.02, atol=0.02 * np.abs(cov).max())
    per_row = solve_static_passes(y, sigma, p, v, F0_HZ, t_s, sat, block_id=np.arange(t_s.size),
                                  block_sigma_hz=q_sig, **kw)
    inflated = solve_static_passes(y, np.hypot(sigma, q_sig), p, v, F0_HZ, t_s, sat, **kw)
    np.testing.assert_allclose(per_row.pos_ecef_m, inflated.pos_ecef_m, rtol=0, atol=5e-3)
    np.testing.assert_allclose(per_row.cov[:3, :3], inflated.cov[:3, :3], rtol=1e-6)


def test_block_states_are_consistent_and_beat_independent_inflation(starlink_like):
    """Rows sharing each instant's error of 0.31 Hz on white 0.2-0.6 Hz, over 40 draws: the fix with one state
    per block has a position NEES near 3 (achieved mean 2.64; 40 draws of a 3-dof chi-square have a mean
    within 3 +- 0.39, bounds three of those, 1.8-4.2) and an RMS error at most that of the rows' variances
    raised independently (the same draws; achieved 6.9 against 7.5 m, and below on three other seed sets:
    7.2 / 9.1, 8.0 / 9.9, 9.0 / 9.3 m)."""
    geo, rate, p, v, t_s, sat, rx = starlink_like
    kw = dict(clock="common", pos0_ecef_m=rx, alpha=None, decorrelate=False, pass_offsets=False)
    q_sig = 0.31
    nees, err2 = [], {"blocks": [], "inflated": []}
    for seed in range(40):
        y, sigma, block = _block_rows(starlink_like, np.random.default_rng(300 + seed), q_sig)
        fix = solve_static_passes(y, sigma, p, v, F0_HZ, t_s, sat, block_id=block, block_sigma_hz=q_sig, **kw)
        d = fix.pos_ecef_m - rx
        nees.append(d @ np.linalg.solve(fix.cov[:3, :3], d))
        err2["blocks"].append(d @ d)
        inflated = solve_static_passes(y, np.hypot(sigma, q_sig), p, v, F0_HZ, t_s, sat, **kw)
        err2["inflated"].append(np.sum((inflated.pos_ecef_m - rx) ** 2))
    assert 1.8 < np.mean(nees) < 4.2
    assert np.mean(err2["blocks"]) <= np.mean(err2["inflated"])


def test_a_weak_fix_answers_a_tiny_input_change_linearly(starlink_like):
    """3 s of 7 satellites (GDOP ~700, sigma ~500 m), one receiver clock: Dopplers moved by U(-1e-6, 1e-6) Hz
    move the converged fix by the linear response ``(H^T W H)^-1 H^T W dy`` (position block) and leave its
    covariance unchanged, whichever start. Reference: that response written out with the position columns by
    central differences at the fix, the clock offset and drift, the satellites' offsets and time offsets with
    their priors. Stopped on a damped step shrunk by round-off rejections, the fix sat up to ~1e-3 of its
    sigma short of the minimum wherever its path ended (the replay's cleaning moved one by 0.6 m this way).
    Achieved: response error 2e-7 of the sigma, covariance 2e-9 relative; bounds 1e-6 (the old iteration: 1e-5)
    and 1e-6 (the linearisation's change over a ~5e-4 m move is ~1e-9).
    """
    geo, rate, p, v, t_s, sat, rx = starlink_like
    k = t_s < 3
    rng = np.random.default_rng(5)
    extra, *_ = common_truth(rate, t_s, sat, rng)
    y = (geo + extra + rng.standard_normal(t_s.size))[k]
    p, v, t_s, sat, rate = p[k], v[k], t_s[k], sat[k], rate[k]
    kw = dict(clock="common", alpha=None, decorrelate=False, pass_offsets=False)
    dy = rng.uniform(-1e-6, 1e-6, y.size)
    starts = {"100 km off": rx + np.array([6e4, 0.0, 8e4]), "global": None}
    for start, pos0 in starts.items():
        fix = solve_static_passes(y, 1.0, p, v, F0_HZ, t_s, sat, pos0_ecef_m=pos0, **kw)
        moved = solve_static_passes(y + dy, 1.0, p, v, F0_HZ, t_s, sat, pos0_ecef_m=pos0, **kw)
        assert fix.status == moved.status == FixStatus.OK, start
        x = fix.pos_ecef_m
        D = np.stack([doppler_hz(p[None], v[None], (x + e)[None], np.zeros((1, 3)), np.zeros(1))[0]
                      - doppler_hz(p[None], v[None], (x - e)[None], np.zeros((1, 3)), np.zeros(1))[0]
                      for e in np.eye(3)], 1) / 2.0
        H = np.hstack([D, np.ones((t_s.size, 1)), t_s[:, None], np.eye(7)[sat], np.eye(7)[sat] * rate[:, None]])
        N = H.T @ H + np.diag([0.0] * 5 + [1.0 / SAT_OFFSET_SIGMA_HZ**2] * 7 + [1.0 / TIME_OFFSET_SIGMA_S**2] * 7)
        response = np.linalg.solve(N, H.T @ dy)[:3]
        sigma_m = np.sqrt(np.trace(fix.cov[:3, :3]))
        assert sigma_m > 300.0, start  # a weak fix indeed
        assert np.linalg.norm(moved.pos_ecef_m - x - response) < 1e-6 * sigma_m, start
        np.testing.assert_allclose(moved.cov[:3, :3], fix.cov[:3, :3], rtol=1e-6, err_msg=start)


def _leverage_case(starlink_like, clock):
    """``starlink_like`` with satellite 6 cut to 5 rows; rows, model, weights and the dense design of ``clock``.

    Dense design (rows' input order): position by central differences, then for ``"common"`` the receiver
    offset and drift, satellite offsets and time offsets and one state per second (the blocks of a
    snapshot receiver, 0.31 Hz); for ``"per_pass"`` a cubic and a time offset per pass. Its prior
    pseudo-rows as the fix's.
    """
    geo, rate, p, v, t_s, sat, rx = starlink_like
    keep = (sat != 6) | (t_s < 5)
    geo, rate, p, v, t_s, sat = geo[keep], rate[keep], p[keep], v[keep], t_s[keep], sat[keep]
    sigma = np.random.default_rng(41).uniform(0.2, 0.6, t_s.size)
    common = clock == "common"
    block, q_sig = t_s.astype(int), 0.31
    blocks = dict(block_id=block, block_sigma_hz=q_sig) if common else {}
    rows = pass_rows(geo, sigma, p, v, F0_HZ, t_s, sat, mask=None, common=common, deg=1 if common else 3,
                     time_bias=True, sat_offset_sigma_hz=SAT_OFFSET_SIGMA_HZ, time_bias_sigma_s=TIME_OFFSET_SIGMA_S,
                     clock_group=None, alt_m=None, alt_sigma_m=None, **blocks)

    def predict(x):
        return doppler_hz(p[None], v[None], x[None], np.zeros((1, 3)), np.zeros(1))[0]

    D = np.stack([predict(rx + e) - predict(rx - e) for e in np.eye(3)], 1) / 2.0
    one = np.eye(7)[sat]
    u = (t_s - 29.5) / 30.0
    if common:
        n_b = block.max() + 1
        H = np.hstack([D, np.ones((t_s.size, 1)), u[:, None], one, one * rate[:, None], np.eye(n_b)[block]])
        prior = [0.0] * 5 + [SAT_OFFSET_SIGMA_HZ**-2] * 7 + [TIME_OFFSET_SIGMA_S**-2] * 7 + [q_sig**-2] * n_b
    else:
        H = np.hstack([D] + [one * u[:, None] ** k for k in range(4)] + [one * rate[:, None]])
        prior = [0.0] * 31 + [TIME_OFFSET_SIGMA_S**-2] * 7
    return rows, PassesModel(rows), np.where(rows.used, 1.0 / rows.sigma**2, 0.0)[None], H, np.array(prior), sigma


@pytest.mark.parametrize("clock", ["common", "per_pass"])
def test_a_rows_leverage_counts_the_terms_its_pass_absorbs_it_with(starlink_like, clock):
    """The w-test's leverage: the linear terms' (``PassesModel.leverage``) plus the projected Jacobian's is
    the diagonal of the whole fix's hat matrix.

    Reference: the hat matrix of the linearised fix written out densely (``_leverage_case``) at the truth,
    by the SVD of the whitened design with its prior rows, columns scaled (the normal equations lose
    ~0.1 of it with the per-pass cubic and time offset: condition number ~1e14). One satellite keeps 5
    of its 60 rows: its offset and time offset take a large part of each (clock common: leverage
    0.11-0.58, mean 0.31, where the rows' median is 0.14, mostly their block's state), of which the
    projected Jacobian alone shows 0.001-0.01. Agreement to 1e-6 with the clock common (central
    differences of the position columns; achieved 2e-10). Per pass to 1e-4 (achieved 8e-6): each pass's
    5x5 normal matrix has a condition number of ~1e14, inverted through its Jacobi scaling (6e-3 when the
    fit's projection, which the projected Jacobian comes from, inverted it unscaled; 2e-2 when the
    leverage's inverses did too).
    """
    rx = starlink_like[-1]
    rows, model, w, H, prior, sigma = _leverage_case(starlink_like, clock)
    _, J = model(rx[None], np.zeros(1, int), w)
    projected = w[0] * np.einsum("mi,ij,mj->m", J[0], cofactor(J[0], w[0]), J[0])
    h = model.leverage(rx[None], np.zeros(1, int), w)[0] + projected
    A = np.vstack([H / sigma[:, None], np.diag(np.sqrt(prior))[prior > 0]])
    A = A / np.linalg.norm(A, axis=0)
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    hat = np.sum(U[:, sv > 1e-12 * sv[0]] ** 2, axis=1)[:len(sigma)]
    np.testing.assert_allclose(h[:rows.n], hat[rows.order], rtol=0, atol=1e-6 if clock == "common" else 1e-4)
    short = rows.pass_index == 6
    assert hat[rows.order][short].mean() > 0.3 and np.all(projected[:rows.n][short] < 0.02)


def test_an_outlier_its_pass_absorbs_is_found_though_the_sum_passes(starlink_like):
    """Data snooping per pass: one satellite keeps 3 rows and its last is 5.5 sigma off. Its offset and time
    offset absorb a third of it (leverage 0.34), so the residual sum stays inside its chi-square bound and
    the row's plain residual, 3.3 sigma, is below the 3.59 that the largest of 3 rows is tested at; its
    standardised residual, with the pass's terms in its leverage, is ~4.0. The fix leaves it out and
    equals the fix without it (reference: the same rows with that one masked; no other row excluded,
    1e-6 m for the iteration's tolerance). Without the pass's terms in the leverage the row stays."""
    geo, rate, p, v, t_s, sat, rx = starlink_like
    keep = (sat != 6) | (t_s < 3)
    geo, rate, p, v, t_s, sat = geo[keep], rate[keep], p[keep], v[keep], t_s[keep], sat[keep]
    rng = np.random.default_rng(43)
    extra, *_ = common_truth(rate, t_s, sat, rng)
    y = geo + extra + rng.normal(0.0, 0.3, t_s.size)
    bad = np.flatnonzero(sat == 6)[2]
    y[bad] += 5.5 * 0.3
    kw = dict(clock="common", pos0_ecef_m=rx, decorrelate=False, pass_offsets=False)
    fix = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, **kw)
    without = np.arange(t_s.size) != bad
    ref = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, mask=without, alpha=None, **kw)
    assert not fix.used[bad] and fix.used[without].all()
    np.testing.assert_allclose(fix.pos_ecef_m, ref.pos_ecef_m, rtol=0, atol=1e-6)
    kept = solve_static_passes(y, 0.3, p, v, F0_HZ, t_s, sat, alpha=None, **kw)
    assert kept.chi2 < chi2_dist.isf(1e-3, kept.dof)  # the sum alone would not have been tested
    assert abs(kept.residuals_hz[bad]) / 0.3 < norm_dist.isf(1e-3 / 2 / 3)  # nor the plain residual
