"""The aiding engine: every aid's H against finite differences of its model, lever-arm geometry, closed-form runs.

References: the nonlinear measurement functions themselves (central
differences), closed-form geometry of a lever arm, and simulated truth
(:mod:`leosop.ins.trajectory`, ideal increments integrated analytically,
independent of the strapdown algorithm).
"""

import dataclasses
import math

import numpy as np
import pytest
import scipy.stats


from leosop import frames
from leosop.fusion import aids, engine, kalman
from leosop.fusion.common import N_INS, pos_jacobian
from leosop.ins.error_model import DPOS, DV, EPS, NABLA, PHI
from leosop.ins.strapdown import NavState
from leosop.ins.trajectory import static
from leosop.rotations import euler_to_dcm, quat_to_dcm, rotvec_to_dcm

from tests.fusion.helpers import ALT, LAT, LON, STEP, computed_state, true_view


def _all_aids():
    lever = np.array([0.3, -0.8, 1.2])
    return [
        aids.GnssPosition(0.0, LAT + 1e-7, LON - 2e-7, ALT + 0.5, np.eye(3) * 1e-4, lever),
        aids.GnssVelocity(0.0, [4.1, -6.8, 0.2], np.eye(3) * 1e-3, lever, accel_sigma_s=0.1),
        aids.ZeroVelocity(0.0, 0.01),
        aids.ZeroRate(0.0, [1e-4, -1e-4, 2e-4], 1e-4),
        aids.NonHolonomic(0.0, 0.1, rotvec_to_dcm([0.01, -0.02, 0.03]), slip_s=0.1, offset_m=0.1),
        aids.Height(0.0, ALT - 1.0, 0.5),
        aids.WalkingSpeed(0.0, 7.9, 0.2),
    ]


@pytest.mark.parametrize("aid", _all_aids(), ids=lambda a: a.name)
def test_design_matrix_matches_finite_differences(aid):
    state, bg, ba, omega = computed_state()
    computed = aids.InsView(state, bg, ba, omega)
    z, H, R = aid.matrices(computed)
    assert H.shape == (z.size, N_INS) and R.shape == (z.size, z.size)
    np.testing.assert_array_equal(z, aid.predict(computed) - aid.measured)
    np.testing.assert_allclose(aid.predict(true_view(np.zeros(N_INS))), aid.predict(computed), atol=1e-12)
    # Innovation z(dx) = h(computed) - h(truth(dx)); its derivative at 0 is H.
    H_fd = np.empty_like(H)
    for i in range(N_INS):
        e = np.zeros(N_INS)
        e[i] = STEP[i]
        H_fd[:, i] = (aid.predict(true_view(-e)) - aid.predict(true_view(e))) / (2 * STEP[i])
    scale = np.abs(H).max()
    # Relative 1e-6: central differences are exact to O(step^2) and the functions are smooth.
    np.testing.assert_allclose(H, H_fd, rtol=1e-6, atol=1e-6 * scale)


def test_lever_arm_geometry_closed_form():
    """Heading West (yaw +90 deg) with the antenna 1 m forward and 0.5 m up: it is 1 m West and 0.5 m up."""
    C = euler_to_dcm(0.0, 0.0, math.radians(90.0))
    state = NavState.from_dcm(LAT, LON, ALT, [0.0, 0.0, 0.0], C)
    aid = aids.GnssPosition(0.0, LAT, LON, ALT, np.eye(3), [0.0, 1.0, 0.5])
    np.testing.assert_allclose(aid.predict(aids.InsView(state, 0, 0, np.zeros(3))), [-1.0, 0.0, 0.5], atol=1e-12)
    # Turning at 0.5 rad/s about Up with a 2 m forward arm: the antenna moves at 1 m/s to the body's left,
    # i.e. South when facing West.
    vel = aids.GnssVelocity(0.0, [0, 0, 0], np.eye(3), [0.0, 2.0, 0.0])
    np.testing.assert_allclose(vel.predict(aids.InsView(state, 0, 0, np.array([0, 0, 0.5]))), [0.0, -1.0, 0.0],
                               atol=1e-12)


def _settings(**kw):
    base = {"gyro_arw_rad_per_rt_s": math.radians(0.2) / 60, "accel_vrw_mps_per_rt_s": 1e-3,
            "gyro_bias_rw_rad_per_s_per_rt_s": 1e-6, "accel_bias_rw_mps2_per_rt_s": 1e-5}
    return engine.EngineSettings(**{**base, **kw})


def _P0(pos_m, vel_mps, att_rad, bg, ba):
    P = np.zeros((N_INS, N_INS))
    P[PHI, PHI] = np.diag(np.square(att_rad))
    P[DV, DV] = np.eye(3) * vel_mps**2
    J_inv = np.linalg.inv(pos_jacobian(LAT, ALT))
    P[DPOS, DPOS] = J_inv @ (np.eye(3) * pos_m**2) @ J_inv.T
    P[EPS, EPS] = np.eye(3) * bg**2
    P[NABLA, NABLA] = np.eye(3) * ba**2
    return P


def test_static_imu_with_zupt_keeps_velocity_zero_and_attitude_bounded():
    """A static IMU with biases and noise, ZUPT and zero-rate at 2 Hz for 120 s.

    Closed form: with velocity pinned to zero, the tilt settles where the
    levelled accelerometer bias is cancelled (``phi_E = nabla_N / g``, ...)
    and the filter cannot tell the two apart, so the *apparent* levelling is
    what the ZUPT bounds; velocity stays at the ZUPT noise level and the
    position drift at the integral of it.
    """
    truth = static(40.1, -105.15, 1600.0, 1.0, -2.0, 30.0, 120.0)
    rng = np.random.default_rng(7)
    bg, ba = np.radians([0.05, -0.04, 0.03]), np.array([0.02, -0.03, 0.01])
    n = truth.dtheta_b_rad.shape[0]
    dt = truth.dt_s
    dth = truth.dtheta_b_rad + bg * dt + rng.normal(0, math.radians(0.2) / 60 * math.sqrt(dt), (n, 3))
    dvl = truth.dvel_b_mps + ba * dt + rng.normal(0, 1e-3 * math.sqrt(dt), (n, 3))
    t = truth.t_s[1:]
    state0 = NavState.from_dcm(truth.lat_rad[0], truth.lon_rad[0], truth.alt_m[0], [0, 0, 0], truth.C_n_b[0])
    w_mean = dth.mean(axis=0) / dt
    aid_list = []
    for ts in np.arange(0.5, 120.0, 0.5):
        aid_list += [aids.ZeroVelocity(ts, 0.01), aids.ZeroRate(ts, w_mean, math.radians(0.01))]
    res = engine.run(state0, _P0(0.1, 0.1, np.radians([1, 1, 5]), math.radians(0.1), 0.05), t,
                     np.full(n, dt), dth, dvl, aid_list, _settings())
    assert res.aids["zupt"][0] == len(aid_list) // 2
    # Velocity at the ZUPT noise: 3 x 0.01 m/s (the sigma given).
    assert np.abs(res.vel_enu_mps[-100:]).max() < 0.03
    # Tilt bounded by the accelerometer bias it absorbs (<= 0.03 / g rad = 0.18 deg) plus margin for noise.
    C_err = res_C(res)[-1] @ truth.C_n_b[-1].T
    tilt_deg = math.degrees(math.hypot(C_err[2, 0], C_err[2, 1]))
    assert tilt_deg < 0.3
    # Zero-rate updates see every gyro bias (the mean rate less the Earth rate in the body):
    # 0.002 deg/s is 6x the noise of the 120 s mean rate (0.2 deg/sqrt(h) ARW).
    np.testing.assert_allclose(res.gyro_bias_rad_per_s[-1], bg, atol=math.radians(0.002))
    pos_err = frames.ecef_to_enu(frames.geodetic_to_ecef(res.lat_rad[-1], res.lon_rad[-1], res.alt_m[-1])
                                 - truth.pos_ecef_m[-1], truth.lat_rad[-1], truth.lon_rad[-1])
    assert np.linalg.norm(pos_err) < 0.2  # 120 s of velocity errors at 0.01 m/s: 1.2 m worst case, ~0.1 m random


def test_nhc_and_gnss_velocity_noise_grow_with_the_motion():
    """Heading North at 10 m/s, turning left at 0.3 rad/s and braking at 2 m/s^2 (lateral acceleration 3 m/s^2)."""
    state = NavState.from_dcm(LAT, LON, ALT, [0.0, 10.0, 0.0], np.eye(3))
    ins = aids.InsView(state, np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 0.3]), np.array([-3.0, -2.0, 0.0]))
    nhc = aids.NonHolonomic(0.0, 0.1, slip_s=0.12, offset_m=0.5)
    # Lateral: 0.1^2 + (0.12 s x 3 m/s^2)^2 + (0.5 m x 0.3 rad/s)^2; vertical unchanged.
    np.testing.assert_allclose(nhc.matrices(ins)[2], np.diag([0.01 + 0.36**2 + 0.15**2, 0.01]), rtol=1e-12)
    np.testing.assert_allclose(aids.NonHolonomic(0.0, 0.1).matrices(ins)[2], np.eye(2) * 0.01, rtol=1e-12)
    vel = aids.GnssVelocity(0.0, [0.0, 10.0, 0.0], np.eye(3) * 0.04, np.zeros(3), accel_sigma_s=0.1)
    # |a| = sqrt(13) m/s^2: 0.04 + 0.01 x 13 per axis.
    np.testing.assert_allclose(vel.matrices(ins)[2], np.eye(3) * 0.17, rtol=1e-12)


def test_gyro_cross_axis_states_tilt_a_turning_imu_as_the_closed_form():
    """Level, still, turning about Up at w for half a turn, only the six cross-axis terms uncertain (sigma s).

    The rate error ``(M_xz w, M_yz w, 0)`` in the turning body tilts the
    level frame by ``-int C_n_b dt``: summed over both level axes its variance
    is ``2 s^2 (sin^2 wT + (1 - cos wT)^2) = 4 s^2 (1 - cos wT)``, 8 s^2 at half
    a turn; the Up terms (``M_zx``, ``M_zy``) see no rate and the yaw none.
    """
    w, T, s, rate = 0.5, math.pi / 0.5, 0.01, 100.0
    n, dt = round(T * rate), 1.0 / rate
    g = 9.80
    dth = np.tile([0.0, 0.0, w * dt], (n, 1))
    dvl = np.tile([0.0, 0.0, g * dt], (n, 1))
    state0 = NavState.from_dcm(LAT, LON, ALT, [0.0, 0.0, 0.0], np.eye(3))
    settings = dataclasses.replace(_settings(gyro_cross_sigma=s, step_s=0.02), gyro_arw_rad_per_rt_s=0.0,
                                   accel_vrw_mps_per_rt_s=0.0, gyro_bias_rw_rad_per_s_per_rt_s=0.0,
                                   accel_bias_rw_mps2_per_rt_s=0.0)
    res = engine.run(state0, np.zeros((N_INS, N_INS)), dt * np.arange(1, n + 1), np.full(n, dt), dth, dvl, [],
                     settings)
    tilt_var = res.sigma[-1, PHI.start] ** 2 + res.sigma[-1, PHI.start + 1] ** 2
    # 1 %: the rate of each 20 ms propagation is its mean (the body turns 0.01 rad within it).
    np.testing.assert_allclose(tilt_var, 4 * s**2 * (1 - math.cos(w * T)), rtol=1e-2)
    assert res.sigma[-1, PHI.start + 2] < 1e-3 * s
    np.testing.assert_allclose(res.sigma[-1, engine.cross_slice(settings)], s, rtol=1e-12)


def res_C(res):
    return quat_to_dcm(res.q_n_b)


class _Linear(aids.Aid):
    """An aid linear in the bias errors: ``z = z0 - H b``, ``b`` the bias estimates the filter moved from zero."""

    name = "linear"

    def __init__(self, t_s, z0, H, R, states=()):
        super().__init__(t_s)
        self.z0, self.H, self.R, self.states = z0, H, R, states

    def matrices(self, ins):
        b = np.r_[ins.gyro_bias_rad_per_s, ins.accel_bias_mps2]
        return self.z0 - self.H[:, 9:15] @ b, self.H, self.R


def test_aids_of_one_instant_make_the_sequence_of_their_updates():
    # Reference: the textbook sequence, each aid gated on the innovation left by those before it and
    # applied by kalman.update; the engine carries the correction and gains from aid to aid and makes
    # one update. Same algebra in another order: equal to rounding (1e-9 relative), where gating each
    # aid on the joint prior instead would be off by the updates' size (~10 %).
    rng = np.random.default_rng(3)
    A = rng.standard_normal((N_INS, N_INS))
    P0 = 1e-2 * A @ A.T + 1e-3 * np.eye(N_INS)
    settings = engine.EngineSettings(1e-3, 1e-2, 0.0, 0.0)
    group = []
    for m in (1, 2, 1, 3, 1):
        H = np.zeros((m, N_INS))
        H[:, 9:15] = rng.standard_normal((m, 6))  # the biases: the aid sees the filter's corrections
        R = np.diag(rng.uniform(0.01, 0.1, m))
        group.append(_Linear(0.0, H @ rng.multivariate_normal(np.zeros(N_INS), P0)
                             + rng.multivariate_normal(np.zeros(m), R), H, R))
    group[2].z0 = group[2].z0 + 1e3  # an outlier: rejected, the aids after it conditioned without it
    seen = []

    def on_aid(index, aid, z, S, used, reopened):
        seen.append((index, used, z @ np.linalg.solve(S, z)))

    f = engine._Filter(computed_state()[0], P0, settings, 0.0, on_aid)
    f.apply(group, 0.0, 0.0, list(range(len(group))))
    x, P, ref = np.zeros(N_INS), P0, []
    for j, a in enumerate(group):
        y = a.z0 - a.H @ x
        nis = float(y @ np.linalg.solve(a.H @ P @ a.H.T + a.R, y))
        used = nis <= scipy.stats.chi2.ppf(settings.gate_probability, y.size)
        ref.append((j, used, nis))
        if used:
            x, P, _, _ = kalman.update(x, P, a.z0, a.H, a.R)
    assert [r[:2] for r in seen] == [r[:2] for r in ref] and not ref[2][1] and sum(r[1] for r in ref) == 4
    np.testing.assert_allclose([r[2] for r in seen], [r[2] for r in ref], rtol=1e-9)
    np.testing.assert_allclose(f.P, P, rtol=1e-9, atol=1e-9 * np.abs(P).max())
    np.testing.assert_allclose(np.r_[f.bg, f.ba], np.r_[x[EPS], x[NABLA]], rtol=1e-9, atol=1e-15)
    assert f.counts["linear"] == [4, 1]


def test_stale_state_block_is_marginalised_exactly():
    # Dropping a block is Gaussian marginalisation: the other states keep their rows and columns of P,
    # to the bit, and the blocks after it move up.
    settings = engine.EngineSettings(1e-3, 1e-2, 0.0, 0.0)
    f = engine._Filter(computed_state()[0], np.eye(N_INS), settings, 0.0)
    old, kept = (aids.StateBlock(k, (0.0, 0.0), (2.0, 3.0), (0.0, 0.0), drop_after_s=30.0) for k in ("a", "b"))
    f.admit(_Linear(0.0, None, None, None, (old,)))
    f.admit(_Linear(10.0, None, None, None, (kept,)))
    assert f.P.shape == (N_INS + 4,) * 2 and np.array_equal(np.diag(f.P)[N_INS:], [4.0, 9.0, 4.0, 9.0])
    B = np.random.default_rng(4).standard_normal(f.P.shape)
    f.P = B @ B.T
    keep = np.r_[np.arange(N_INS), N_INS + 2, N_INS + 3]
    P_keep = f.P[np.ix_(keep, keep)]
    f.admit(_Linear(30.5, None, None, None, (kept,)))  # "a" last named at 0 s: stale after 30 s
    assert list(f.blocks.entries) == ["b"] and f.blocks.entries["b"][1] == N_INS
    np.testing.assert_array_equal(f.P, P_keep)


def test_course_sigma_is_the_cross_track_velocity_sigma_over_the_speed():
    # Closed form: a velocity along East sees its course move only with its North error, sigma_N / speed;
    # and a Monte Carlo of atan2 on a slanted velocity with a full covariance agrees with the first-order sigma.
    cov = np.diag([0.3**2, 0.1**2, 1.0])
    assert engine.course_sigma_rad([5.0, 0.0, 0.0], cov) == pytest.approx(0.1 / 5.0, rel=1e-12)
    v = np.array([3.0, 4.0, 0.2])
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.25]])
    draws = np.random.default_rng(0).multivariate_normal(v, cov * 1e-2, 200_000)  # small: first order holds
    course = np.arctan2(-draws[:, 0], draws[:, 1])
    # 200 000 draws: the sample sigma is good to 1/sqrt(2 n) = 0.16 %; 1 % allows the second-order terms.
    assert engine.course_sigma_rad(v, cov * 1e-2) == pytest.approx(np.std(course), rel=0.01)
