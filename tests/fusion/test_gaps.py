"""IMU gaps (:mod:`leosop.ins.gaps`) and their process noise in the engine: closed forms and the real flight log."""

import math
import warnings

import numpy as np

from leosop.fusion import engine
from leosop.fusion.common import N_INS
from leosop.ins import flight_mat, gaps
from leosop.ins.error_model import DV, PHI
from leosop.ins.imu_io import ImuLog
from leosop.ins.strapdown import NavState

from tests.helpers import data_path

DT = 0.02  # the flight log's 50 Hz


def _log(t_s, rate):
    """A rate-sampled log (each increment the rate at its end times its interval) of samples ``rate`` (n, 6)."""
    dt = np.diff(t_s)
    inc = rate[1:] * dt[:, None]
    return ImuLog(t_s[1:] - t_s[0], dt, inc[:, :3], inc[:, 3:], None, "test", {})


def _holed(n, hole_every, hole_len):
    """Indices of the samples kept when ``hole_len - 1`` are dropped every ``hole_every``, and the log index
    (:func:`_log`) of the increment over each hole."""
    keep = np.ones(n, dtype=bool)
    starts = np.arange(hole_every, n - hole_len, hole_every)
    for s in starts:
        keep[s + 1:s + hole_len] = False
    kept = np.flatnonzero(keep)
    return kept, np.searchsorted(kept, starts + hole_len) - 1


def test_a_linear_rate_is_bridged_exactly_and_its_variance_is_the_rectangle_sums_closed_form():
    """Rate ``a + b t``: the trapezoid over a hole is the exact integral; the variance is the squared
    difference between it and the intact data's rectangle sums over the same span, ``(b DT T / 2)^2``."""
    n, hole = 2000, 7
    kept, holes = _holed(n, 90, hole)
    t = DT * kept
    b = np.array([0.1, -0.2, 0.3, 1.0, 2.0, -3.0])
    log = _log(t, 0.5 + t[:, None] * b)
    dth, dvl, var = gaps.bridge(log)
    t0, t1 = t[holes], t[holes + 1]
    exact = 0.5 * b * (t1**2 - t0**2)[:, None] + 0.5 * (t1 - t0)[:, None]
    np.testing.assert_allclose(np.c_[dth, dvl][holes], exact, rtol=1e-12)
    np.testing.assert_allclose(var[holes], np.broadcast_to((b * DT * hole * DT / 2) ** 2, (holes.size, 6)),
                               rtol=1e-6)
    off = np.ones(log.t_s.size, dtype=bool)
    off[holes] = False
    assert not var[off].any()
    np.testing.assert_array_equal(dth[off], log.dtheta_b_rad[off])


def test_white_rate_noise_gives_the_closed_form_variance():
    """White rate samples of sigma ``s``: the bridge over ``n`` periods errs by ``s^2 ((T/2)^2 + (T/2 - DT)^2 +
    (n - 1) DT^2)``; estimated from 1000 s of intact data (the whole log), within 10 % (a mean of ~5e4
    overlapping squared Gaussians, ~7e3 independent: ~3 % sigma)."""
    n, hole, s = 50_000, 7, 0.01
    kept, holes = _holed(n, 90, hole)
    rng = np.random.default_rng(1)
    log = _log(DT * kept, rng.normal(0.0, s, (kept.size, 6)))
    _, _, var = gaps.bridge(log, window_s=2000.0)
    T = hole * DT
    expected = s**2 * ((T / 2) ** 2 + (T / 2 - DT) ** 2 + (hole - 1) * DT**2)
    np.testing.assert_allclose(var[holes], expected, rtol=0.10)


def test_flight_holes_cut_into_intact_data_are_bridged_better_than_held_and_their_variance_fits():
    """The real flight (in the air, 345-830 s): 0.14 s holes cut half-way between the logger's gaps, where the
    samples are known (265 holes). The bridge errs less than the held end rate on every gyro axis, by >= 1.1x
    (measured 1.3 / 2.5 / 2.9x, R / F / U), and the error over the variance read off the neighbouring data (not
    the hole) has a mean square in 0.6-1.6 per axis (1 if honest; a mean of 265 chi-square(1) values has a sigma
    of 9 %, the rest for the heavier tails of manoeuvres; measured 1.01-1.32)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        log, _, _ = flight_mat.read_flight_mat(data_path("gnss-ins", "gebre-egziabher_case1_flight",
                                                         "flight_data.mat"))
    t = np.r_[0.0, log.t_s]
    rate = np.c_[log.gyro_rad_per_s, log.accel_mps2]
    rate = np.r_[rate[:1], rate]
    real_gap = np.flatnonzero(log.dt_s > 0.1)
    mid = real_gap[:-1] + (np.diff(real_gap) // 2)  # sample index (in t) starting each cut hole
    mid = mid[(t[mid] > 345.0) & (t[mid] < 830.0)]
    assert np.all(np.diff(real_gap)[(t[real_gap[:-1]] > 345.0) & (t[real_gap[:-1]] < 830.0)] > 20)
    keep = np.ones(t.size, dtype=bool)
    for s in mid:
        keep[s + 1:s + 7] = False
    cut = _log(t[keep], rate[keep])
    holes = np.searchsorted(np.flatnonzero(keep), mid + 7) - 1  # the cut log's increment over each hole
    truth = (np.cumsum(np.r_[np.zeros((1, 6)), rate[1:] * np.diff(t)[:, None]], axis=0)[mid + 7]
             - np.cumsum(np.r_[np.zeros((1, 6)), rate[1:] * np.diff(t)[:, None]], axis=0)[mid])
    dth, dvl, var = gaps.bridge(cut)
    held = np.c_[cut.dtheta_b_rad, cut.dvel_b_mps][holes]
    err = np.c_[dth, dvl][holes] - truth
    rms = lambda x: np.sqrt(np.mean(x**2, axis=0))  # noqa: E731
    assert np.all(rms(held - truth)[:3] >= 1.1 * rms(err)[:3])
    z2 = np.mean(err**2 / var[holes], axis=0)
    assert np.all((z2 > 0.6) & (z2 < 1.6)), z2


def test_increment_variance_enters_the_attitude_and_velocity_covariance_as_C_var_C_T():
    """At rest, no other noise, no aids: one bridged increment with variances ``v`` adds ``C_n_b diag(v) C_n_b^T``
    to the attitude (gyro part; alone, since a tilt feeds the velocity) or the velocity (accelerometer part)
    covariance; the error dynamics over the 0.2 s couple the axes by ~Omega_earth dt (1e-5 of the variance)."""
    n, dt, g = 20, 0.01, 9.80
    C = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # yawed 90 deg
    dth = np.zeros((n, 3))
    dvl = np.tile(C.T @ [0.0, 0.0, g * dt], (n, 1))
    settings = engine.EngineSettings(0.0, 0.0, 0.0, 0.0, step_s=0.1, record_cov_ins=True)
    state0 = NavState.from_dcm(math.radians(45.0), 0.0, 300.0, [0.0, 0.0, 0.0], C)

    def final_cov(var7):
        v = np.zeros((n, 6))
        v[7] = var7
        return engine.run(state0, np.zeros((N_INS, N_INS)), dt * np.arange(1, n + 1), np.full(n, dt), dth, dvl,
                          [], settings, increment_var=v).cov_ins[-1]

    gyro, accel = np.array([1e-4, 4e-4, 9e-4]), np.array([1e-2, 4e-2, 9e-2])
    np.testing.assert_allclose(final_cov(np.r_[gyro, 0, 0, 0])[PHI, PHI], C @ np.diag(gyro) @ C.T, atol=2e-5 * 9e-4)
    P = final_cov(np.r_[0, 0, 0, accel])
    np.testing.assert_allclose(P[DV, DV], C @ np.diag(accel) @ C.T, atol=2e-5 * 9e-2)
    assert np.abs(P[PHI, PHI]).max() < 1e-15  # a velocity error tilts only through the transport rate, 1/R
    assert not final_cov(np.zeros(6)).any()
