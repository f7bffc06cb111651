"""Differential Doppler fix against the pair simulator (truth from frames.range_rate and SGP4 states moved by the
drawn element-set offsets, independent of the solver's Jacobian model)."""

from dataclasses import replace

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.orbits.propagate import state_ecef
from leosop.positioning.differential import rtn_frames, solve_differential
from leosop.positioning.differential_base import base_corrections, whitener
from leosop.positioning.differential_sim import (
    draw_satellite_errors,
    simulate_receiver,
    straight_drive,
)

from tests.positioning.helpers import base_rover_scene

#: Noise-free fixes: the single differences cancel satellite offsets and drifts to round-off; 1e-6 Hz noise
#: on ~1e5 Hz Doppler leaves micrometres, 1 mm bounds it with margin.
ONE_MM = 1e-3
#: The clock difference is recovered to its round-off too (1e-6 Hz noise, 1,000 rows).
CLOCK_TOL_HZ = 1e-4
N_EP = 40


@pytest.fixture(scope="module")
def scene():
    """Seven Walker satellites above 25 deg over the base for N_EP s, base and rover 7.5 km apart."""
    return base_rover_scene(np.arange(N_EP).astype("timedelta64[s]"), 7)


def pair(scene, seed, *, sigma_hz, t_base=None, **error_kw):
    const, base, rover, t, ids = scene
    rng = np.random.default_rng(seed)
    err = draw_satellite_errors(ids, t[0], rng, **error_kw)
    b = simulate_receiver(const, err, base, t if t_base is None else t_base, rng, sigma_hz=sigma_hz,
                          clock_offset_hz=1.2e3, clock_drift_hz_per_s=0.5)
    r = simulate_receiver(const, err, rover, t, rng, sigma_hz=sigma_hz, clock_offset_hz=-2e3,
                          clock_drift_hz_per_s=-0.2)
    return r, b


def test_satellite_terms_cancel(scene):
    """Satellite offsets of 500 Hz and drifts of 1 Hz/s leave no trace; the clock difference is the truth's."""
    _, base, rover, _, _ = scene
    r, b = pair(scene, 1, sigma_hz=1e-6, orbit_sigma_rtn_m=(0, 0, 0), offset_max_hz=500.0, drift_sigma_hz_per_s=1.0)
    fix = solve_differential(r, b, base, orbit_sigma_rtn_m=None)
    assert np.linalg.norm(fix.pos_ecef_m[0] - rover) < ONE_MM
    # Truth: (-2000 - 1200) Hz at t0, drift -0.7 Hz/s, evaluated at the block's mid-time.
    expect = [-3.2e3 - 0.7 * fix.t_ref_s[0], -0.7]
    np.testing.assert_allclose(fix.clock_poly_hz[0], expect, atol=CLOCK_TOL_HZ)
    assert fix.status.tolist() == ["ok"] and fix.n_sats.tolist() == [7]


def test_interpolated_base(scene):
    """A base sampled half a second off the rover: interpolation carries the drifts (no noise, no orbit error)."""
    _, base, rover, t, _ = scene
    r, b = pair(scene, 2, sigma_hz=1e-6, t_base=t - np.timedelta64(500, "ms"), orbit_sigma_rtn_m=(0, 0, 0),
                offset_max_hz=500.0, drift_sigma_hz_per_s=1.0)
    fix = solve_differential(r, b, base, orbit_sigma_rtn_m=None)
    # The rover's first epoch has a base row on one side only (base span ends 0.5 s before the rover's).
    assert fix.n_unmatched_rows == 7
    # The interpolated correction holds the base clock and satellite terms, linear in time: exact, ONE_MM.
    assert np.linalg.norm(fix.pos_ecef_m[0] - rover) < ONE_MM


def test_whitening_against_interpolation_matrix(scene):
    """The banded whitening inverts the single differences' covariance built from np.interp's weights.

    Reference: each base row's weight in every rover row by interpolating the base row's indicator with
    np.interp, ``R = diag(var_rover) + W diag(var_base) W^T`` (dense); ``L^-1 R L^-T`` must be the identity
    to round-off (1e-9 on unit entries of matrices of ~1,000 rows).
    """
    _, base, _, t, _ = scene
    r, b = pair(scene, 6, sigma_hz=0.3, t_base=t - np.timedelta64(500, "ms"))
    b = replace(b, sigma_hz=np.random.default_rng(7).uniform(0.1, 0.5, len(b.t_s)))
    _, var_b, rows, w = base_corrections(b, base, r.sat_id, r.t_s)
    keep = np.isfinite(var_b)
    W = np.zeros((keep.sum(), len(b.t_s)))
    for k in range(len(b.t_s)):
        on = r.sat_id[keep] == b.sat_id[k]
        mine = b.sat_id == b.sat_id[k]
        W[on, k] = np.interp(r.t_s[keep][on], b.t_s[mine], (np.arange(len(b.t_s)) == k)[mine].astype(float))
    R = np.diag(r.sigma_hz[keep] ** 2) + (W * b.sigma_hz**2) @ W.T
    whiten = whitener(r.sigma_hz[keep][None] ** 2, rows[keep][None], w[keep][None], b.sigma_hz**2,
                       np.zeros((1, keep.sum()), bool))
    Li_R = whiten(R[None], [0])[0]
    np.testing.assert_allclose(whiten(Li_R.T[None], [0])[0], np.eye(len(R)), atol=1e-9)
    assert np.abs(R - np.diag(np.diag(R))).max() > 0.01  # the rows are correlated: the test has teeth


def test_one_receiver_only_and_blocks(scene):
    """Satellites seen by one receiver are left out and counted; blocks give one fix each."""
    _, base, rover, _, ids = scene
    r, b = pair(scene, 3, sigma_hz=1e-6, orbit_sigma_rtn_m=(0, 0, 0))
    r = r.take(np.flatnonzero(r.sat_id != ids[0]))
    b = b.take(np.flatnonzero(b.sat_id != ids[1]))
    fix = solve_differential(r, b, base, block_s=20.0, orbit_sigma_rtn_m=None)
    assert fix.rover_only_sats == (ids[1],) and fix.base_only_sats == (ids[0],)
    assert fix.n_sats.tolist() == [5, 5] and fix.pos_ecef_m.shape == (2, 3)
    assert np.all(np.linalg.norm(fix.pos_ecef_m - rover, axis=-1) < ONE_MM)
    assert np.all(fix.block[np.isin(r.sat_id, ids[1])] == -1)


def test_moving_rover_blocks(scene):
    """A car at 20 m/s: per-block position at the block's mid-time and velocity, noise-free, to round-off.

    Truth is straight_drive's line (frames.range_rate with the car's velocity in the simulator); 1e-6 Hz
    noise on a block whose velocity trades against position (1 cm/s ~ 1 m) leaves well under 1 mm.
    """
    const, base, rover, t, ids = scene
    rng = np.random.default_rng(8)
    err = draw_satellite_errors(ids, t[0], rng, orbit_sigma_rtn_m=(0, 0, 0))
    b = simulate_receiver(const, err, base, t, rng, sigma_hz=1e-6)
    pos, vel = straight_drive(rover, (1.0, 1.0, 0.0), 20.0, np.arange(N_EP, dtype=float))
    r = simulate_receiver(const, err, pos, t, rng, sigma_hz=1e-6, vel_rx_ecef_mps=vel, clock_drift_hz_per_s=0.3)
    fix = solve_differential(r, b, base, block_s=20.0, motion="constant_velocity", orbit_sigma_rtn_m=None)
    truth, vel_true = straight_drive(rover, (1.0, 1.0, 0.0), 20.0, fix.t_ref_s)
    assert np.all(np.linalg.norm(fix.pos_ecef_m - truth, axis=-1) < ONE_MM)
    np.testing.assert_allclose(fix.vel_ecef_mps, vel_true, atol=1e-5)
    assert fix.status.tolist() == ["ok", "ok"] and fix.cov.shape == (2, 8, 8)
    # At rest the same rows cannot be fitted: the car's 20 m/s is ~760 Hz of Doppler.
    assert solve_differential(r, b, base, block_s=20.0, orbit_sigma_rtn_m=None).status.tolist() != ["ok", "ok"]


def test_no_common_satellite(scene):
    """Nothing in common: no fix, status too_few (the CLI turns it into an error)."""
    _, base, _, _, ids = scene
    r, b = pair(scene, 4, sigma_hz=0.3)
    fix = solve_differential(r.take(np.flatnonzero(r.sat_id == ids[0])), b.take(np.flatnonzero(b.sat_id != ids[0])),
                             base)
    assert fix.status.tolist() == ["too_few"] and np.isnan(fix.pos_ecef_m).all()


def test_different_bands_rejected(scene):
    _, base, _, _, _ = scene
    r, b = pair(scene, 5, sigma_hz=0.3)
    with pytest.raises(InputError, match="different bands"):
        solve_differential(r, replace(b, carrier_hz=b.carrier_hz * 1.1), base)


@pytest.mark.parametrize("base_off_ms", [0, 500])
def test_consistent_with_orbit_errors(scene, base_off_ms):
    """With shared element-set errors (30/300/100 m) the fix is sub-metre and its covariance honest.

    Mean position NEES over 12 seeds of a consistent 3-D estimate is chi2(36) / 12: its 99.9 % two-sided
    interval is [1.2, 5.9] (tools/bench_differential.py runs more seeds). With the base 0.5 s off the
    rover's epochs, neighbouring rows share interpolated base noise (whitened; unmodelled it gave 4-5 in
    the bench at 50-200 km).
    """
    _, base, rover, t, _ = scene
    nees, err = [], []
    for seed in range(12):
        r, b = pair(scene, 100 + seed, sigma_hz=0.3, t_base=t - np.timedelta64(base_off_ms, "ms"))
        fix = solve_differential(r, b, base)
        e = fix.pos_ecef_m[0] - rover
        nees.append(e @ np.linalg.solve(fix.cov[0, :3, :3], e))
        err.append(np.linalg.norm(e))
    assert 1.2 < np.mean(nees) < 5.9
    assert np.sqrt(np.mean(np.square(err))) < 3.0


def test_rtn_frame_rate_is_the_frames_time_derivative(scene):
    """W of the orbit-offset states against a central difference of the RTN axes built from SGP4 states.

    The axes are the inertial orbit's: they turn at the orbital rate (~1e-3 rad/s) and the cross-track
    one also at the Earth's rate (~7e-5 rad/s, the inertial orbit plane seen from ECEF), which W once
    missed (2 cm/s on a 300 m along-track offset).
    A 0.5 s central difference is good to (0.5 s)^2 / 6 x (1e-3 rad/s)^3 ~ 4e-11 rad/s; the oblateness
    left out of W turns the plane by at most its acceleration over the speed, 1.5 J2 GM / r^2 ~ 0.012
    m/s^2 over 7.6 km/s = 1.5e-6 rad/s (achieved 8.5e-7): 2e-6 rad/s bounds the difference, against
    the ~7e-5 rad/s turn the old W missed.
    """
    const, _, _, t, ids = scene
    idx = const.index_of(ids)
    h = np.timedelta64(500, "ms")
    (p, v, _), (p1, v1, _), (p0, v0, _) = (state_ecef(const.subset(idx), t[[0, -1]] + dt)
                                            for dt in (np.timedelta64(0, "ms"), h, -h))
    _, W = rtn_frames(p, v)
    W_num = (rtn_frames(p1, v1)[0] - rtn_frames(p0, v0)[0]) / 1.0
    np.testing.assert_allclose(W, W_num, rtol=0, atol=2e-6)
    assert np.abs(W_num[..., 2]).max() > 1e-5  # the cross-track axis does turn: the test has teeth


def test_joint_fit_separates_orbit_offsets(scene):
    """The joint fit (base rows in, each satellite's frequency offset + drift): element-set offsets of
    30/300/100 m, satellite offsets of 500 Hz and drifts of 1 Hz/s, base 0.5 s off the rover and losing a
    satellite after 15 s, two 20 s blocks.

    At 1e-3 Hz the base's rows pin the offsets (their Doppler at the base is tens of Hz): the fix's
    sigma is centimetres while single differences, which see the offsets only through the baseline,
    keep decimetres; the error against the simulator's truth must pass a 3-D NEES test at 99.9 %
    (chi2_3: 16.3) in each block. Redundancy: rows minus position, clock and the satellite polynomials.
    """
    _, base, rover, t, ids = scene
    r, b = pair(scene, 0, sigma_hz=1e-3, t_base=t - np.timedelta64(500, "ms"), offset_max_hz=500.0,
                drift_sigma_hz_per_s=1.0)
    b = b.take(np.flatnonzero((b.sat_id != ids[0]) | (b.t_s < 15.0)))
    joint = solve_differential(r, b, base, block_s=20.0, sat_clock_degree=1)
    single = solve_differential(r, b, base, block_s=20.0)
    e = joint.pos_ecef_m - rover
    assert np.all(np.einsum("bi,bij,bj->b", e, np.linalg.inv(joint.cov[:, :3, :3]), e) < 16.3)
    sig_joint, sig_single = (np.sqrt(np.trace(f.cov[:, :3, :3], axis1=-2, axis2=-1)) for f in (joint, single))
    assert np.all(sig_joint < 0.1) and np.all(sig_single > 3 * sig_joint)
    # 7 satellites per block (ids[0] from the rover's rows alone in the second): 5 + 2 x 7 states.
    np.testing.assert_array_equal(joint.dof, joint.n_used - 5 - 14)
    assert joint.status.tolist() == ["ok", "ok"] and joint.z_hz.shape == r.doppler_hz.shape
