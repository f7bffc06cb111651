"""Loose coupling (the fix aids of fusion/aids_fix.py in the engine).

Measurement model round trip, consistency, bias recovery, gaps, correction period.

The truth is a short straight flight of the [Shen 2024] kind; fixes are the
truth plus white Gaussian errors drawn from the covariance handed to the
filter, the case in which a correct filter must be consistent. The last
tests take the simulated fixes, whose errors come from the satellites'
constant offsets and orbit errors, and the filter that models them.
"""

import dataclasses
import functools

import numpy as np
import pytest

from leosop import earth, frames
from leosop.constants import G0_MPS2
from leosop.fusion import aids_fix, common, kalman
from leosop.fusion.aids import InsView
from leosop.ins import imu, strapdown, trajectory
from leosop.ins.error_model import DPOS, DV, NABLA
from leosop.apps.scenarios import XIAN_BAOJI
from leosop.apps.simulate import run_scenario

from tests.helpers import assert_filter_consistent

ARW = np.radians(0.01) / 60.0  # 0.01 deg/sqrt(h) in rad/sqrt(s)
VRW = 1e-5 * G0_MPS2  # 1e-5 g/sqrt(Hz) in m/s^2/sqrt(Hz)
FIX_SIGMA_M = np.array([15.0, 10.0, 25.0])  # ENU, like a snapshot Doppler fix
FIX_SIGMA_MPS = np.array([0.3, 0.2, 0.5])


@functools.lru_cache(maxsize=2)
def _flight(duration_s):
    return trajectory.flight([[34.342, 108.940], [34.363, 107.239]], alt_m=3000.0, speed_mps=200.0,
                             rate_hz=100.0, duration_s=duration_s)


def _settings(**kw):
    base = dict(pos_sigma_m=(100.0,) * 3, vel_sigma_mps=(1.0,) * 3, att_sigma_rad=tuple(np.radians([0.01, 0.01, 0.05])),
                gyro_bias_sigma_rad_per_s=np.radians(0.03) / 3600, accel_bias_sigma_mps2=1e-4 * G0_MPS2,
                gyro_arw_rad_per_rt_s=ARW, accel_vrw_mps2_per_rt_hz=VRW)
    base.update(kw)
    return common.FilterSettings(**base)


def _case(seed, duration_s=120.0, accel_bias_g=1e-4):
    """Start state, IMU, truth at 1 Hz and white fixes drawn from their covariance, all from one seed."""
    rng = np.random.default_rng(seed)
    truth = _flight(duration_s)
    signs = rng.choice([-1.0, 1.0], size=(2, 3))
    errors = imu.ImuErrors.from_quoted(gyro_bias_deg_per_h=0.03 * signs[0], gyro_arw_deg_per_rt_h=0.01,
                                       accel_bias_g=accel_bias_g * signs[1], accel_vrw_g_per_rt_hz=1e-5)
    dth, dvl = imu.corrupt(truth.dtheta_b_rad, truth.dvel_b_mps, truth.dt_s, errors, rng)
    t1 = truth.resample(1.0)
    C = frames.C_e_n(t1.lat_rad, t1.lon_rad)
    cov_enu = np.zeros((6, 6))
    cov_enu[:3, :3] = np.diag(FIX_SIGMA_M**2)
    cov_enu[3:, 3:] = np.diag(FIX_SIGMA_MPS**2)
    T = np.zeros((t1.t_s.size, 6, 6))  # ENU [pos, vel] -> ECEF [pos, vel]
    T[:, :3, :3] = C
    T[:, 3:, 3:] = C
    cov = T @ cov_enu @ np.swapaxes(T, 1, 2)
    e = rng.standard_normal((t1.t_s.size, 6)) * np.sqrt(np.diag(cov_enu))
    pos_fix = t1.pos_ecef_m + np.einsum("kij,kj->ki", C, e[:, :3])
    vel_fix = np.einsum("kij,kj->ki", C, t1.vel_enu_mps + e[:, 3:])
    # Initial errors drawn from the filter's prior: 100 m and 1 m/s per axis.
    lat, alt = t1.lat_rad[0], t1.alt_m[0]
    R_M, R_N = earth.radii_m(lat)
    dp, dv = 100.0 * rng.standard_normal(3), rng.standard_normal(3)
    state0 = strapdown.NavState.from_dcm(lat + dp[1] / (R_M + alt), t1.lon_rad[0] + dp[0] / ((R_N + alt) * np.cos(lat)),
                                         alt + dp[2], t1.vel_enu_mps[0] + dv, t1.C_n_b[0])
    return state0, dth, dvl, truth.dt_s, (pos_fix, vel_fix, cov), t1, errors


def _error_enu(result, t1):
    dpos = frames.ecef_to_enu(result.pos_ecef_m - t1.pos_ecef_m, t1.lat_rad, t1.lon_rad)
    return np.concatenate([result.vel_enu_mps - t1.vel_enu_mps, dpos], axis=1)


def test_measurement_is_the_enu_difference_and_h_maps_the_error_state():
    # A fix 12 m East, -7 m North, 30 m Up of the INS and 0.5 m/s slower East:
    # z is the INS minus the fix in ENU, and H applied to the error state that
    # moves the INS onto the fix gives the same numbers (to linearisation, mm).
    lat, lon, alt = np.radians(34.3), np.radians(108.5), 3000.0
    state = strapdown.NavState.from_dcm(lat, lon, alt, [-200.0, 5.0, 0.0], np.eye(3))
    d_enu = np.array([12.0, -7.0, 30.0])
    pos_fix = frames.geodetic_to_ecef(lat, lon, alt) + frames.enu_to_ecef(d_enu, lat, lon)
    vel_fix = frames.enu_to_ecef(state.vel_enu_mps - [0.5, 0.0, 0.0], lat, lon)
    cov = np.diag([4.0, 9.0, 16.0, 0.01, 0.04, 0.09])
    zeros = np.zeros(3)
    z, H, R = aids_fix.LeoFix(1.0, 1, pos_fix, vel_fix, cov).matrices(InsView(state, zeros, zeros, zeros))
    np.testing.assert_allclose(z[:3], [0.5, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(z[3:], -d_enu, atol=1e-3)
    R_M, R_N = earth.radii_m(lat)
    x = np.zeros(15)
    x[DV] = [0.5, 0.0, 0.0]
    x[DPOS] = [-d_enu[1] / (R_M + alt), -d_enu[0] / ((R_N + alt) * np.cos(lat)), -d_enu[2]]
    np.testing.assert_allclose(H @ x, z, atol=1e-3)
    # R is the fix covariance rotated: its trace (rotation invariant) survives.
    assert np.trace(R) == pytest.approx(np.trace(cov), rel=1e-12)


def test_filter_is_consistent_with_white_fixes_over_20_seeds():
    nees, nis, white = [], [], []
    for seed in range(20):
        state0, dth, dvl, dt, fixes, t1, _ = _case(seed)
        res = aids_fix.fuse(state0, dth, dvl, dt, fixes, _settings())
        nees.append(kalman.nees(_error_enu(res, t1)[1:], res.pos_vel_cov_enu()[1:]))
        u = res.updated
        nis.append(res.nis[u])
        L = np.linalg.cholesky(res.innovation_cov[u])
        white.append(np.linalg.solve(L, res.innovation[u][..., None])[..., 0])
    nis = np.concatenate(nis)  # each update is a chi-square(6) draw
    # Whiteness over n = 20 x 119 x 6 pairs of whitened innovations.
    assert_filter_consistent(np.concatenate(nees), nis.sum(), 6 * nis.size,
                             np.concatenate([w[:-1] for w in white]), np.concatenate([w[1:] for w in white]))


def test_vertical_accelerometer_bias_is_recovered():
    # A 1 mg vertical bias is observable through height (simulate and recover):
    # the estimate must lie within 3 sigma of the truth and sigma must be
    # far below the bias itself.
    state0, dth, dvl, dt, fixes, t1, errors = _case(7, duration_s=300.0, accel_bias_g=1e-3)
    res = aids_fix.fuse(state0, dth, dvl, dt, fixes, _settings(accel_bias_sigma_mps2=1e-3 * G0_MPS2))
    # Level flight: body Up is navigation Up to within the pitch/roll of a straight leg.
    truth_up = errors.accel_bias_mps2[2]
    sigma = np.sqrt(res.P[-1][NABLA, NABLA][2, 2])
    assert abs(res.accel_bias_mps2[-1, 2] - truth_up) < 3 * sigma
    assert sigma < 0.1 * abs(truth_up)


def test_gap_in_fixes_is_bridged_and_the_filter_resumes():
    state0, dth, dvl, dt, (pos, vel, cov), t1, _ = _case(3)
    pos, vel, cov = pos.copy(), vel.copy(), cov.copy()
    pos[40:70] = vel[40:70] = np.nan
    cov[40:70] = np.nan
    res = aids_fix.fuse(state0, dth, dvl, dt, (pos, vel, cov), _settings())
    assert np.all(np.isfinite(res.lat_rad)) and np.all(np.isfinite(res.vel_enu_mps))
    assert not res.updated[40:70].any() and res.updated[70:].all()
    # Without fixes the covariance grows, and the errors stay within it (4 sigma).
    sig = np.sqrt(np.diagonal(res.pos_vel_cov_enu(), axis1=1, axis2=2))
    assert np.all(sig[69, 3:] > sig[39, 3:])
    assert np.all(np.abs(_error_enu(res, t1)[40:70]) < 4 * sig[40:70])


def test_correction_period_spaces_the_updates():
    state0, dth, dvl, dt, fixes, _, _ = _case(4)
    res = aids_fix.fuse(state0, dth, dvl, dt, fixes, _settings(correction_period_s=30.0))
    assert np.flatnonzero(res.updated).tolist() == [30, 60, 90, 120]


def _whitened(result):
    u = result.fused.updated
    L = np.linalg.cholesky(result.fused.innovation_cov[u])
    return np.linalg.solve(L, result.fused.innovation[u][..., None])[..., 0]


def test_filter_is_consistent_with_the_simulated_time_correlated_fixes():
    # Measurement-level fixes over 90 s: their errors persist from fix to fix
    # (constant satellite offsets and orbit errors; lag-1 correlation ~0.6), which
    # the filter models through each fix's gain. Issue 6: mean NEES of position
    # and velocity within [0.5, 2] of its dimension (12 seeds: 0.85 x 6 measured;
    # the 782 s flight gives 0.98 x 6 over 20 seeds), NIS and whiteness as above.
    scenario = dataclasses.replace(XIAN_BAOJI, duration_s=90.0)
    nees, nis, dof, white = [], [], [], []
    for seed in range(12):
        r = run_scenario(scenario, level="measurement", seed=seed)
        nees.append(r.nees()[1:])
        nis.append(r.nis()[0])
        dof.append(r.nis()[1])
        white.append(_whitened(r))
    # Each update holds the fix, its receiver offset and its residuals (one value per Doppler);
    # n = 12 x 89 x 6 whitened pairs of the fix rows below.
    assert_filter_consistent(np.concatenate(nees), np.concatenate(nis).sum(), np.concatenate(dof).sum(),
                             np.concatenate([w[:-1] for w in white]), np.concatenate([w[1:] for w in white]))


def test_common_orbit_shift_moves_the_fixes_and_the_filter_knows_it():
    # Closed form: every satellite believed [E, E, E] away (E = 30 m) acts as a
    # receiver moved by the same vector, so noise-free fixes without offsets are
    # off by exactly [30, 30, 30] m ECEF (median over the fixes; 100 dB-Hz
    # leaves ~0.3 m of noise through GDOPs in the hundreds: 1 m bound).
    leo = dataclasses.replace(XIAN_BAOJI.leo, orbit_error_m=30.0, orbit_error_model="common",
                              sat_doppler_offset_max_hz=0.0, cn0_dbhz=100.0)
    r = run_scenario(dataclasses.replace(XIAN_BAOJI, duration_s=30.0, leo=leo), level="measurement", seed=2)
    d = r.fix_pos_ecef_m - r.truth_pos_ecef_m
    ok = np.isfinite(d[:, 0])
    assert ok.sum() >= 28
    np.testing.assert_allclose(np.median(d[ok], axis=0), [30.0, 30.0, 30.0], atol=1.0)
    # With the Table 1 offsets and noise the snapshot geometry still cannot see
    # the shift, so the fused error stays near sqrt(3) E = 52 m (the offsets
    # add or remove a few metres: 15 m bound), and the filter, given the common
    # model, says so: NEES within [0.5, 2] x 6 over 6 seeds (1.0 x 6 measured;
    # a filter that ignored the shift would be near (52 / 2)^2 per dimension).
    scenario = dataclasses.replace(XIAN_BAOJI, duration_s=60.0,
                                   leo=dataclasses.replace(XIAN_BAOJI.leo, orbit_error_m=30.0,
                                                           orbit_error_model="common"))
    nees, pos = [], []
    for seed in range(6):
        r = run_scenario(scenario, level="measurement", seed=seed)
        nees.append(r.nees()[1:])
        pos.append(r.errors()["fused"][0][30:])
    assert abs(np.mean(pos) - np.sqrt(3) * 30.0) < 15.0
    assert 0.5 * 6 <= np.concatenate(nees).mean() <= 2.0 * 6


def test_checkable_fixes_need_redundancy_or_a_good_geometry():
    # Table of cases: 6 + k states (k clocks, NaN rows for an absent clock), Doppler used, GDOP.
    two_clocks = np.eye(8)
    one_of_two = np.eye(8)
    one_of_two[7, 7] = np.nan  # second family not in the sky: 7 states
    failed = np.full((8, 8), np.nan)
    lim = aids_fix.MAX_GDOP_UNCHECKED
    cases = [  # (cov, n_used, gdop, usable)
        (two_clocks, 9, 5.0 * lim, True),  # one spare Doppler: checked by its residuals, any geometry
        (two_clocks, 8, 0.5 * lim, True),  # no spare Doppler, good geometry
        (two_clocks, 8, 2.0 * lim, False),  # no spare Doppler, near-singular geometry
        (one_of_two, 8, 5.0 * lim, True),  # 7 states: the 8th Doppler is spare
        (one_of_two, 7, 2.0 * lim, False),
        (failed, 0, np.nan, False),
    ]
    cov, n_used, gdop, usable = (np.array(c) for c in zip(*cases))
    assert aids_fix.checkable_fixes(n_used, cov, gdop).tolist() == usable.tolist()


def test_gate_reopens_after_a_run_of_rejected_fixes():
    # A filter confidently wrong: the INS starts 2 km off but the filter claims 1 m, so every
    # fix fails the gate (NIS ~ (2 km / 25 m)^2). Without re-opening it never recovers; with
    # it, the REOPEN_AFTER + 1-th fix is taken and the filter is back within 4 sigma of the
    # truth (and within 3 fix sigmas, 75 m) from then on.
    state0, dth, dvl, dt, fixes, t1, _ = _case(5)
    state0 = dataclasses.replace(state0, alt_m=state0.alt_m + 2000.0)
    settings = _settings(pos_sigma_m=(1.0,) * 3)
    locked = aids_fix.fuse(state0, dth, dvl, dt, fixes, settings, reopen_after=None)
    assert locked.rejected[1:].all() and not locked.updated.any()
    res = aids_fix.fuse(state0, dth, dvl, dt, fixes, settings)
    first = aids_fix.REOPEN_AFTER + 1
    assert np.flatnonzero(res.reopened).tolist() == [first]
    assert res.rejected[1:first].all() and res.updated[first:].all()
    err = _error_enu(res, t1)[first:]
    sig = np.sqrt(np.diagonal(res.pos_vel_cov_enu()[first:], axis1=1, axis2=2))
    assert np.all(np.abs(err) < 4 * sig)
    assert np.all(np.linalg.norm(err[:, 3:], axis=1) < 3 * np.linalg.norm(FIX_SIGMA_M))


def test_engine_port_keeps_the_results_of_the_former_loose_filter():
    # Issue 21: simulate's loose coupling moved from its own loop (fusion/loose.run, deleted) to the fix
    # aids in the engine. Reference: that loop's output on this run (commit 78d7b43): mean 3D position
    # and velocity errors, the last epoch's error, the updates and the sum of the NIS. The engine
    # propagates the covariance with the INS at the end of each 1 s step (the loop: at its start) and
    # integrates the INS pair by pair, which moved these by 1e-8 relative here (3e-7 at most over the
    # bundled scenarios): rel 1e-5 leaves room for rounding, while any change of the model or the
    # cadence moves them by percents.
    r = run_scenario(dataclasses.replace(XIAN_BAOJI, duration_s=40.0), level="measurement", seed=1)
    fused = r.errors()["fused"]
    nis, dof = r.nis()
    assert r.fused.updated[1:].all() and int(dof.sum()) == 378
    np.testing.assert_allclose([fused[0][1:].mean(), fused[1][1:].mean(), fused[0][-1], nis.sum()],
                               [4.236632682155679, 0.0861247800758571, 2.447788001233838, 368.08942367312557],
                               rtol=1e-5)
