"""Differential LEO Doppler and carrier aids: H against finite differences, the models against the pair simulator's
truth.

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
from leosop.apps import fuse_leo
from leosop.errors import InputError
from leosop.fusion import aids_differential, engine
from leosop.fusion.aids import InsView, StateBlock
from leosop.fusion.aids_carrier import DifferentialCarrier
from leosop.fusion.common import N_INS
from leosop.fusion.imu_noise import GRADES
from leosop.ins.strapdown import NavState
from leosop.ins.trajectory import Segment, from_segments
from leosop.orbits import DEFAULT_TLE, read_tle
from leosop.orbits.propagate import state_ecef
from leosop.positioning.differential_sim import draw_satellite_errors, simulate_receiver, straight_drive
from leosop.positioning.measurements import read_measurements, write_measurements

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
#: Noise-free pair, carrier: what the differences leave of the rover's and base's light times over 2 s and the
#: orbit offsets' second-order terms, measured 1e-4 cycles (3 um); 1e-3 cycles (26 um) bounds them, far below a
#: phase's noise (0.1 cycles).
MILLI_CYCLE = 1e-3


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
                          clock_drift_hz_per_s=clocks["base"][1], phase_sigma_cycles=0.0)
    r = simulate_receiver(const, err, p, t, rng, sigma_hz=0.0, vel_rx_ecef_mps=v, clock_offset_hz=clocks["rover"][0],
                          clock_drift_hz_per_s=clocks["rover"][1], phase_sigma_cycles=0.0)
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
    aids = aids_differential.differential_aids(r, b, base, np.zeros(3), aids_differential.DifferentialOptions(
        carrier=False))
    assert len(aids) == r.t_s.size  # base on the rover's epochs: every row has a correction
    sat = [list(err.sat_ids).index(aid.states[1].key.removeprefix("diff_orbit:")) for aid in aids]
    z = [aid.matrices(_truth_view(aid, pair, err.orbit_rtn_m[j]))[0][0] for aid, j in zip(aids, sat)]
    assert np.max(np.abs(z)) < TEN_MHZ
    # The orbit states matter: at zero offsets the innovations are the baseline's share of the orbit errors.
    z0 = [aid.matrices(_truth_view(aid, pair, np.zeros(3)))[0][0] for aid in aids]
    assert np.max(np.abs(z0)) > 10 * TEN_MHZ


def test_engine_converges_on_a_drive():
    """Ideal IMU, 20 m off at the start: the engine with the aids (Doppler and carrier) pulls the car in, inside its
    own covariance.

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
    b = simulate_receiver(const, err, base, t, rng, sigma_hz=SIGMA_HZ, clock_offset_hz=700.0, phase_sigma_cycles=0.1)
    r = simulate_receiver(const, err, track.pos_ecef_m, t, rng, sigma_hz=SIGMA_HZ, vel_rx_ecef_mps=vel,
                          clock_offset_hz=-1.1e3, clock_drift_hz_per_s=0.3, phase_sigma_cycles=0.1)
    aids = aids_differential.differential_aids(r, b, base, np.zeros(3))
    n_carrier = sum(isinstance(a, DifferentialCarrier) for a in aids)
    assert n_carrier == n_ep - 1  # one per interval, and a clone at each epoch before the last
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
    assert res.aids["differential_doppler"][0] > 0.9 * (len(aids) - 2 * n_carrier)
    assert res.aids["differential_carrier"][0] > 0.9 * n_carrier
    # Pulled in from ~18 m, and inside the covariance it reports (chi-square, 3 dof, 0.999: 16.3).
    assert np.linalg.norm(e) < 6.0
    assert e @ np.linalg.solve(P, e) < 16.3


def _carrier_aid(lever=(0.3, -0.8, 1.2)):
    """Three satellites seen from the test's INS at ``t2`` and 1 s before, a base 7.5 km away, orbit states."""
    r_rx, r_sv, v_sv, east, north = leo_geometry(computed_state()[0])
    base = r_rx - 6e3 * east - 4.5e3 * north
    sv2 = np.stack([r_sv, r_sv + 4e5 * north - 2e5 * east, r_sv - 5e5 * east + 3e5 * north])
    vel = np.stack([v_sv, v_sv + 3e3 * east, v_sv - 2e3 * north])
    sv = np.stack([sv2 - vel, sv2])
    orbits = tuple(StateBlock(f"diff_orbit:{j}", (0.0,) * 3, (30.0, 300.0, 100.0), (0.0,) * 3) for j in range(3))
    clone = StateBlock("diff_carrier_start:1.0", (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, cloned=True)
    # The epochs' noise blocks: a fourth satellite at t1 only, the three in another order at t2.
    noise = (StateBlock("diff_carrier_noise:1.0", (0.0,) * 4, (0.1,) * 4, (0.0,) * 4),
             StateBlock("diff_carrier_noise:2.0", (0.0,) * 3, (0.1,) * 3, (0.0,) * 3))
    index = [[0, 2, 3], [2, 0, 1]]
    # The antenna 1 s before: ~20 m back along the INS's velocity (its own estimate; any point will do for H).
    start = r_rx - 14.0 * north + 12.0 * east
    x = {**{b.key: np.array([12.0, -250.0, 40.0]) * (j + 1) / 2 for j, b in enumerate(orbits)}, clone.key: start,
         noise[0].key: np.array([0.03, -0.2, 0.11, 0.07]), noise[1].key: np.array([-0.05, 0.09, 0.14])}
    aid = DifferentialCarrier(2.0, [1.5e5, -2e4, 3e4], noise, index, np.full(3, CARRIER_HZ), sv,
                              np.stack([vel, vel]), base, lever, clone, orbits)
    return aid, x


def test_carrier_design_matrix_matches_finite_differences():
    """Every column of the carrier aid's H (INS, the three orbit blocks, the two epochs' noise, the clone) against
    central differences; the noise columns are exact (+-1 where each row's satellites sit, 0 at the unused one)."""
    aid, x = _carrier_aid()
    keys = [b.key for b in aid.states]
    sizes = np.cumsum([b.size for b in aid.states])[:-1]
    n = N_INS + sizes[-1] + 3

    def view(e):
        d = np.split(e[N_INS:], sizes)
        return dataclasses.replace(true_view(e[:N_INS]), states={k: x[k] - dk for k, dk in zip(keys, d)})

    z, H, R = aid.matrices(view(np.zeros(n)))
    assert H.shape == (2, n) and R.shape == (2, 2) and z.shape == (2,)
    np.testing.assert_array_equal(R, 0.0)  # all the noise is in the states
    noise = H[:, N_INS + 9:N_INS + 16]
    np.testing.assert_array_equal(noise, [[1, 0, -1, 0, 1, 0, -1], [1, 0, 0, -1, 0, 1, -1]])
    # The engine tests' INS steps times 10 (cycles of ~1e5 round to 1e-11), 1 mm clone and 1 m orbit steps (the
    # second-order terms: 1 m over ~1e6 m ranges), 0.01 cycle noise steps (linear: any step).
    step = np.r_[10 * STEP, np.full(9, 1.0), np.full(7, 1e-2), np.full(3, 1e-3)]
    H_fd = central_difference_jacobian(lambda e: -aid.predict(view(e)), step)
    # A delta-range does not see the velocity; the orbit columns (what 1 s changes of the baseline's share of an
    # offset, ~1e-3 cycles per metre) must not vanish, or the test would check nothing there.
    assert np.all(H[:, 3:6] == 0.0) and np.all(np.abs(H[:, N_INS:N_INS + 9]).max(axis=0) > 1e-4)
    scale = np.maximum(np.abs(H_fd), 1e-3)
    np.testing.assert_array_less(np.abs(H - H_fd), 1e-6 * scale + 1e-9 * np.abs(H).max())


def test_carrier_innovation_at_the_truth_is_zero_and_a_slip_drops_its_interval(pair):
    """Noise-free phases: with the INS, the clone and the orbit states at the truth each interval's
    differences are the simulated ones; an arc that changes between two epochs leaves that satellite out there."""
    base, r, b, err, p = pair[:5]
    t_s = pair[6]

    def carrier(rover):
        return [a for a in aids_differential.differential_aids(rover, b, base, np.zeros(3))
                if isinstance(a, DifferentialCarrier)]

    def innovation(aid, orbit_scale):
        k = int(np.searchsorted(t_s, aid.t_s))
        states = {o.key: orbit_scale * err.orbit_rtn_m[list(err.sat_ids).index(o.key.split(":")[1])]
                  for o in aid.orbits}
        states[aid.states[-1].key] = p[k - 1]  # the antenna at the previous epoch
        states.update({n.key: np.zeros(n.size) for n in aid.noise})  # noise-free
        view = _truth_view(aid, pair, np.zeros(3))
        return aid.matrices(dataclasses.replace(view, states=states))[0]

    aids = carrier(r)
    assert [a.t_s for a in aids] == list(t_s[1:])  # one aid per interval, every satellite in each
    assert all(a.measured.size == np.unique(r.sat_id).size - 1 for a in aids)
    # Consecutive intervals share their common epoch's noise block, whose prior is the rows' phase sigma.
    assert all(a.noise[1] is n.noise[0] for a, n in zip(aids[:-1], aids[1:]))
    sigma = carrier(dataclasses.replace(r, phase_sigma_cycles=np.full(len(r), 0.3)))[0].noise[0].sigma0
    np.testing.assert_allclose(sigma, 0.3)  # the rover's, the base's being 0
    assert np.max(np.abs(np.concatenate([innovation(a, 1.0) for a in aids]))) < MILLI_CYCLE
    # The orbit states matter: at zero offsets a cycle or so is left over 2 s.
    assert np.max(np.abs(np.concatenate([innovation(a, 0.0) for a in aids]))) > 100 * MILLI_CYCLE
    # A slip on the first satellite at the fourth epoch: a new arc, a new ambiguity.
    slipped = (r.sat_id == r.sat_id[0]) & (r.t_s >= t_s[3])
    r2 = dataclasses.replace(r, arc=np.where(slipped, "1", r.arc), phase_cycles=r.phase_cycles + 1234.0 * slipped)
    aids2 = carrier(r2)
    sizes = {a.t_s: a.measured.size for a in aids2}
    assert sizes[t_s[3]] == aids[0].measured.size - 1 and sizes[t_s[4]] == aids[0].measured.size
    assert np.max(np.abs(np.concatenate([innovation(a, 1.0) for a in aids2]))) < MILLI_CYCLE


def test_simulated_phase_rate_is_the_doppler():
    """The pair simulator's phase against its own Doppler: the phase change over 0.1 s less the mean of the two
    Doppler values (the trapezoid's error there: 0.1^2 / 12 times a Doppler's second derivative of up to ~30
    Hz/s^2, 0.03 mHz); 0.05 Hz bounds what the simulator's light time and central-difference velocity leave
    (measured 0.02-0.03 Hz), a fifth of a Doppler's noise."""
    const = read_tle(DEFAULT_TLE)
    site = frames.geodetic_to_ecef(np.radians(34.3), np.radians(108.9), 400.0)
    t = const.epochs_utc.max() + (np.arange(0, 100) * 100).astype("timedelta64[ms]")
    pos, _, _ = state_ecef(const, t[[0, -1]])
    _, el, _ = frames.azimuth_elevation_range(pos, site)
    ids = const.sat_ids[np.flatnonzero(el.min(-1) > np.radians(25.0))[:3]]
    rng = np.random.default_rng(4)
    m = simulate_receiver(const, draw_satellite_errors(ids, t[0], rng), site, t, rng, sigma_hz=0.0,
                          clock_offset_hz=900.0, clock_drift_hz_per_s=0.7, phase_sigma_cycles=0.0)
    for j in ids:
        k = np.flatnonzero(m.sat_id == j)
        rate = np.diff(m.phase_cycles[k]) / np.diff(m.t_s[k])
        assert np.max(np.abs(rate - 0.5 * (m.doppler_hz[k][1:] + m.doppler_hz[k][:-1]))) < 0.05


def test_tables_round_trip_to_the_same_aids(pair, tmp_path):
    """The pair written as DESIGN 4.3 tables (with phase_cycles, phase_sigma_cycles, arc; on a t_s clock) and read
    back gives ``fuse --leo-base``'s aids: the in-memory pair's, to the tables' repr digits; a base of other
    satellites is one line naming the tables."""
    base = pair[0]
    r, b = (dataclasses.replace(m, time_utc=None, sigma_hz=np.full(len(m), SIGMA_HZ),
                                phase_sigma_cycles=np.full(len(m), 0.1)) for m in pair[1:3])
    paths = []
    for name, m in (("rover", r), ("base", b)):
        paths.append(tmp_path / f"{name}.csv")
        write_measurements(paths[-1], m)
    rover2, base2 = (read_measurements(p_) for p_ in paths)
    np.testing.assert_array_equal(rover2.phase_cycles, r.phase_cycles)
    np.testing.assert_array_equal(rover2.arc, r.arc)
    made = fuse_leo.to_differential_aids(rover2, base2, None, base, np.zeros(3))
    ref = aids_differential.differential_aids(r, b, base, np.zeros(3))
    assert [type(a) for a in made] == [type(a) for a in ref] and [a.t_s for a in made] == [a.t_s for a in ref]
    for a, a_ref in zip(made, ref):
        if not a.clones:
            np.testing.assert_allclose(a.measured, a_ref.measured, rtol=0, atol=1e-9)
    # A bad phase sigma sets its row aside with the reason, as the table's other columns do.
    text = paths[0].read_text().splitlines()
    header = text[0].split(",")
    row = text[1].split(",")
    row[header.index("phase_sigma_cycles")] = "-0.1"
    paths[0].write_text("\n".join([text[0], ",".join(row), *text[2:]]) + "\n")
    assert read_measurements(paths[0]).rejected == ((2, "phase_sigma_cycles is -0.1, expected a positive number or "
                                                        "an empty field"),)
    other = base2.take(np.flatnonzero(base2.sat_id != base2.sat_id[0]))
    other = dataclasses.replace(other, sat_id=np.char.add(other.sat_id, "9"))
    with pytest.raises(InputError, match=f"{paths[1]}: no row of {paths[0]} has a base correction"):
        fuse_leo.to_differential_aids(rover2, other, None, base, np.zeros(3))


def test_carrier_rate_moves_both_ends_of_the_interval():
    """``rate`` (the IMU time offset's column) against a central difference of the prediction with the antenna at
    both ends moved along the INS's velocity (no lever arm: the antenna is the INS)."""
    aid, x = _carrier_aid(lever=(0.0, 0.0, 0.0))
    state = computed_state()[0]
    r0 = frames.geodetic_to_ecef(state.lat_rad, state.lon_rad, state.alt_m)
    v_ecef = frames.C_e_n(state.lat_rad, state.lon_rad) @ state.vel_enu_mps

    def h(dt):
        lat, lon, alt = frames.ecef_to_geodetic(r0 + v_ecef * dt)
        moved = NavState.from_dcm(lat, lon, alt, state.vel_enu_mps, state.C_n_b)
        states = {**x, aid.states[-1].key: x[aid.states[-1].key] + v_ecef * dt}
        return aid.predict(InsView(moved, np.zeros(3), np.zeros(3), np.zeros(3), states=states))

    ins = InsView(state, np.zeros(3), np.zeros(3), np.zeros(3), states=x)
    # 4 m of motion either side: the geodetic round trip's ~1e-8 m then costs ~1e-7 cycles/s, and the central
    # difference's error (the third derivative along a line, ~v^3 / rho^2 per metre) is far below it.
    dt = 0.5
    np.testing.assert_allclose(aid.rate(ins), (h(dt) - h(-dt)) / (2 * dt), rtol=1e-6, atol=1e-6)
    assert np.all(np.abs(aid.rate(ins)) > 1e-3)  # not a vanishing check
