"""Differential LEO Doppler aids: H against finite differences, the model against the pair simulator's truth.

References: central differences of the aid's own nonlinear model (as
tests/fusion/test_aids_leo.py does for the single-receiver aid); the measurements of
:mod:`leosop.positioning.differential_sim`, whose truth is SGP4 states moved
by drawn element-set offsets and ``frames.range_rate``, independent of the
aid's Jacobians.
"""

import dataclasses

import numpy as np
import pytest

from leosop import frames
from leosop.fusion import aids_differential, engine
from leosop.fusion.aids import InsView, StateBlock
from leosop.fusion.common import N_INS
from leosop.fusion.imu_noise import GRADES
from leosop.ins.strapdown import NavState
from leosop.ins.trajectory import Segment, from_segments
from leosop.orbits import DEFAULT_TLE, read_tle
from leosop.orbits.propagate import state_ecef
from leosop.positioning.differential_sim import draw_satellite_errors, simulate_receiver, straight_drive

from tests.helpers import central_difference_jacobian, leo_geometry
from tests.fusion.helpers import CARRIER_HZ, STEP, computed_state, true_view

CLOCK = StateBlock("diff_clock", (0.0, 0.0), (3e3, 1.5), (1e-6, 1e-6), integrated=True)
ORBIT = StateBlock("diff_orbit:44713", (0.0,) * 3, (30.0, 300.0, 100.0), (0.0,) * 3, drop_after_s=30.0)
X_BLOCKS = {CLOCK.key: np.array([-812.3, 0.4]), ORBIT.key: np.array([12.0, -250.0, 40.0])}
#: Noise-free pair: the aid's model and the simulator's truth differ by what the differences leave of the light
#: time (the satellite moves ~0.2 m in the 25 us of a 7.5 km baseline: ~3 mHz) and the second-order orbit terms
#: (300 m offsets over ~1000 km ranges); 10 mHz (0.3 mm/s) bounds them.
TEN_MHZ = 1e-2
#: Rover and base noise of the drive: the comb's CRLB for 20 ms at 45 dB-Hz (tools/bench_differential.py).
SIGMA_HZ = 0.26


def _aid(lever=(0.3, -0.8, 1.2)):
    """A satellite 550 km up and ~900 km away from the test's INS, a base 7.5 km from it."""
    r_rx, r_sv, v_sv, east, north = leo_geometry(computed_state()[0])
    base = r_rx - 6e3 * east - 4.5e3 * north
    return aids_differential.DifferentialDoppler(0.0, 310.0, 0.3, CARRIER_HZ, r_sv, v_sv, base, lever, CLOCK, ORBIT)


def _with_blocks(view, d):
    """``view`` with the block estimates less the errors ``d`` (5,) (error = estimate minus truth)."""
    return dataclasses.replace(view, states={CLOCK.key: X_BLOCKS[CLOCK.key] - d[:2],
                                             ORBIT.key: X_BLOCKS[ORBIT.key] - d[2:]})


def test_design_matrix_matches_finite_differences():
    aid = _aid()
    _, H, R = aid.matrices(_with_blocks(true_view(np.zeros(N_INS)), np.zeros(5)))
    assert H.shape == (1, N_INS + 5) and R.shape == (1, 1)
    # As test_fuse_leo: 100x the engine tests' INS steps (Doppler round-off), 1 m steps of the orbit offsets
    # (their second-order terms: 1 m over ~1e6 m ranges, 1e-6 relative).
    step = np.r_[100 * STEP, 1e-3, 1e-4, 1.0, 1.0, 1.0]
    H_fd = central_difference_jacobian(lambda e: -aid.predict(_with_blocks(true_view(e[:N_INS]), e[N_INS:])), step)
    assert H[0, N_INS + 1] == 0.0 == H_fd[0, N_INS + 1]  # the drift reaches z through the transition only
    # The orbit columns are the small difference of two receivers' sensitivities (~1e-3 Hz/m at 7.5 km):
    # they must not vanish, or the test would check nothing there.
    assert np.all(np.abs(H[0, N_INS + 2:]) > 1e-5)
    scale = np.maximum(np.abs(H_fd), 1e-3)
    np.testing.assert_array_less(np.abs(H - H_fd), 1e-6 * scale + 1e-9 * np.abs(H).max())


@pytest.fixture(scope="module")
def pair():
    """A base at rest and a rover driving at 20 m/s 7.5 km away, the same satellite errors, no noise."""
    const = read_tle(DEFAULT_TLE)
    lat, lon = np.radians(34.3), np.radians(108.9)
    base = frames.geodetic_to_ecef(lat, lon, 400.0)
    start = base + frames.C_e_n(lat, lon) @ np.array([6e3, 4.5e3, 30.0])
    t = const.epochs_utc.max() + np.arange(0, 20, 2).astype("timedelta64[s]")
    pos, _, _ = state_ecef(const, t[[0, -1]])
    _, el, _ = frames.azimuth_elevation_range(pos, base)
    ids = const.sat_ids[np.flatnonzero(el.min(-1) > np.radians(25.0))[:5]]
    rng = np.random.default_rng(3)
    err = draw_satellite_errors(ids, t[0], rng)
    t_s = (t - t[0]) / np.timedelta64(1, "s")
    p, v = straight_drive(start, (1.0, 1.0, 0.0), 20.0, t_s)
    clocks = {"base": (1.2e3, 0.5), "rover": (-2e3, -0.2)}
    b = simulate_receiver(const, err, base, t, rng, sigma_hz=0.0, clock_offset_hz=clocks["base"][0],
                          clock_drift_hz_per_s=clocks["base"][1])
    r = simulate_receiver(const, err, p, t, rng, sigma_hz=0.0, vel_rx_ecef_mps=v, clock_offset_hz=clocks["rover"][0],
                          clock_drift_hz_per_s=clocks["rover"][1])
    return base, r, b, err, p, v, t_s, np.subtract(clocks["rover"], clocks["base"])


def _truth_view(aid, pair, orbit_rtn_m):
    """The INS and the rover-minus-base clock at the truth of ``aid``'s epoch, the orbit states ``orbit_rtn_m``."""
    _, _, _, _, p, v, t_s, clock = pair
    k = int(np.searchsorted(t_s, aid.t_s))
    lat, lon, alt = frames.ecef_to_geodetic(p[k])
    state = NavState.from_dcm(lat, lon, alt, frames.C_e_n(lat, lon).T @ v[k], np.eye(3))
    states = {CLOCK.key: np.array([clock[0] + clock[1] * aid.t_s, clock[1]]), aid.states[1].key: orbit_rtn_m}
    return InsView(state, np.zeros(3), np.zeros(3), np.zeros(3), states=states)


def test_innovation_at_the_truth_is_zero(pair):
    """With the INS, clock and orbit states at the truth, each aid predicts the simulated difference."""
    base, r, b, err = pair[:4]
    aids = aids_differential.differential_aids(r, b, base, np.zeros(3))
    assert len(aids) == r.t_s.size  # base on the rover's epochs: every row has a correction
    sat = [list(err.sat_ids).index(aid.states[1].key.removeprefix("diff_orbit:")) for aid in aids]
    z = [aid.matrices(_truth_view(aid, pair, err.orbit_rtn_m[j]))[0][0] for aid, j in zip(aids, sat)]
    assert np.max(np.abs(z)) < TEN_MHZ
    # The orbit states matter: at zero offsets the innovations are the baseline's share of the orbit errors.
    z0 = [aid.matrices(_truth_view(aid, pair, np.zeros(3)))[0][0] for aid in aids]
    assert np.max(np.abs(z0)) > 10 * TEN_MHZ


def test_engine_converges_on_a_drive():
    """Ideal IMU, 20 m off at the start: the engine with the aids pulls the car in, inside its own covariance.

    A short drive (20 s, 20 Hz IMU) on the bundled constellation; the reference is the truth of the trajectory
    the IMU and the pair simulator both follow.
    """
    const = read_tle(DEFAULT_TLE)
    lat, lon = np.radians(34.3), np.radians(108.9)
    base = frames.geodetic_to_ecef(lat, lon, 400.0)
    start = base + frames.C_e_n(lat, lon) @ np.array([6e3, 4.5e3, 30.0])
    lat0, lon0, alt0 = frames.ecef_to_geodetic(start)
    rate_hz, run_up_s, n_ep = 20.0, 5.0, 21
    traj = from_segments(np.degrees(lat0), np.degrees(lon0), alt0, 45.0, [Segment(run_up_s, 20.0),
                                                                         Segment(n_ep, 20.0)], rate_hz=rate_hz)
    k0, per_ep = int(run_up_s * rate_hz), int(rate_hz)
    t = const.epochs_utc.max() + np.arange(n_ep).astype("timedelta64[s]")
    track = traj.at(run_up_s + np.arange(n_ep))
    vel = np.einsum("kij,kj->ki", frames.C_e_n(track.lat_rad, track.lon_rad), track.vel_enu_mps)
    pos, _, _ = state_ecef(const, t[[0, -1]])
    _, el, _ = frames.azimuth_elevation_range(pos, base)
    ids = const.sat_ids[np.flatnonzero(el.min(-1) > np.radians(25.0))[:6]]
    rng = np.random.default_rng(5)
    err = draw_satellite_errors(ids, t[0], rng)
    b = simulate_receiver(const, err, base, t, rng, sigma_hz=SIGMA_HZ, clock_offset_hz=700.0)
    r = simulate_receiver(const, err, track.pos_ecef_m, t, rng, sigma_hz=SIGMA_HZ, vel_rx_ecef_mps=vel,
                          clock_offset_hz=-1.1e3, clock_drift_hz_per_s=0.3)
    aids = aids_differential.differential_aids(r, b, base, np.zeros(3))
    k1 = k0 + (n_ep - 1) * per_ep
    settings = dataclasses.replace(GRADES["consumer"].settings(), record_every=per_ep // 2)
    prior = np.diag(np.r_[np.radians([1.0, 1.0, 5.0]), [0.5] * 3, [20.0 / 6.4e6] * 2, 20.0, [1e-4] * 3,
                          [0.05] * 3]) ** 2
    truth0 = traj.at(run_up_s)
    dpos = np.array([8.0 / 6.4e6, -12.0 / 6.4e6, 10.0])  # 8 m north, 12 m west, 10 m up (computed - true)
    state0 = NavState.from_dcm(truth0.lat_rad[0], truth0.lon_rad[0], truth0.alt_m[0], truth0.vel_enu_mps[0],
                               truth0.C_n_b[0]).corrected(dpos=-dpos)
    res = engine.run(state0, prior, traj.t_s[k0 + 1:k1 + 1] - run_up_s, np.full(k1 - k0, traj.dt_s),
                     traj.dtheta_b_rad[k0:k1], traj.dvel_b_mps[k0:k1], aids, settings)
    truth = traj.at(run_up_s + res.t_s[-1])
    C = frames.C_e_n(truth.lat_rad[0], truth.lon_rad[0])
    e = C.T @ (frames.geodetic_to_ecef(res.lat_rad[-1], res.lon_rad[-1], res.alt_m[-1]) - truth.pos_ecef_m[0])
    P = res.cov_pos_enu_m2[-1]
    assert res.aids["differential_doppler"][0] > 0.9 * len(aids)
    # Pulled in from ~18 m, and inside the covariance it reports (chi-square, 3 dof, 0.999: 16.3).
    assert np.linalg.norm(e) < 6.0
    assert e @ np.linalg.solve(P, e) < 16.3
