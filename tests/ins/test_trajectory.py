"""Truth trajectories: geometry, kinematic consistency and the ideal IMU increments."""

import numpy as np
import pytest

from leosop import earth, frames
from leosop.constants import G0_MPS2
from leosop.errors import InputError
from leosop.ins import trajectory

ONE_DEG = np.radians(1.0)


@pytest.fixture(scope="module")
def xb():
    return trajectory.xian_baoji()


@pytest.fixture(scope="module")
def turns():
    wps = [[34.0, 108.0, 1000.0], [34.1, 108.1, 1500.0], [34.0, 108.3, 1500.0], [34.2, 108.3, 500.0]]
    return wps, trajectory.flight(wps, speed_mps=150.0)


def test_xian_baoji_is_shen2024_section_4_1(xb):
    assert xb.t_s[-1] == pytest.approx(782.0) and xb.dt_s == pytest.approx(0.01)
    assert np.degrees([xb.lat_rad[0], xb.lon_rad[0]]) == pytest.approx([34.342, 108.940], abs=1e-12)
    # 3 km and 200 m/s throughout (integration tolerances are ~1e-8 m).
    np.testing.assert_allclose(xb.alt_m, 3000.0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(xb.vel_enu_mps, axis=1), 200.0, atol=1e-9)
    # Xi'an -> Baoji chord is 156,580 m: 782.9 s at 200 m/s, so after 782 s the
    # aircraft is ~180 m short of Baoji and on the line (cross-track < 1 m).
    baoji = frames.geodetic_to_ecef(*np.radians([34.363, 107.239]), 3000.0)
    to_go = frames.ecef_to_enu(baoji - xb.pos_ecef_m[-1], xb.lat_rad[-1], xb.lon_rad[-1])
    along = to_go[:2] @ xb.vel_enu_mps[-1, :2] / 200.0
    assert 150.0 < along < 210.0
    assert np.hypot(*to_go[:2]) ** 2 - along**2 < 1.0


def test_velocity_is_the_derivative_of_position(turns):
    _, tr = turns
    # Fourth-order central differences of ECEF positions against the stated
    # velocity: checks the dense ODE solution end to end. Truncation
    # dt^4/30 * (5th derivative) < 1e-9 m/s inside pieces, rounding of 6e6 m
    # positions ~1.5e-7 m/s; at the joints of pieces the commanded jerk has a
    # kink and the stencil's error rises to ~2e-6 m/s.
    pos = tr.pos_ecef_m
    v_fd = (pos[:-4] - 8 * pos[1:-3] + 8 * pos[3:-1] - pos[4:]) / (12 * tr.dt_s)
    v_ecef = frames.enu_to_ecef(tr.vel_enu_mps[2:-2], tr.lat_rad[2:-2], tr.lon_rad[2:-2])
    np.testing.assert_allclose(v_fd, v_ecef, rtol=0, atol=5e-6)


def test_static_increments_are_earth_rate_and_gravity():
    tr = trajectory.static(34.246, 108.91, 380.0, 5.0, -3.0, 30.0, 2.0)
    lat = np.radians(34.246)
    C = tr.C_n_b[0]
    # Closed forms: omega_ib^b = C_b_n omega_ie^n, f^b = C_b_n [0, 0, gamma].
    np.testing.assert_allclose(tr.dtheta_b_rad / tr.dt_s, np.tile(C.T @ earth.earth_rate_enu(lat), (200, 1)),
                               rtol=0, atol=1e-18)
    np.testing.assert_allclose(tr.dvel_b_mps / tr.dt_s,
                               np.tile(C.T @ [0, 0, earth.normal_gravity_mps2(lat, 380.0)], (200, 1)), atol=1e-12)
    pitch, roll, _ = tr.euler_rad
    np.testing.assert_allclose(np.degrees([pitch[0], roll[0]]), [5.0, -3.0], atol=1e-12)
    assert tr.heading_deg[0] == pytest.approx(30.0, abs=1e-12)
    np.testing.assert_allclose(tr.vel_enu_mps, 0.0, atol=0)


def test_rolling_flight_is_chu2009_table_2():
    tr = trajectory.rolling_flight(duration_s=2.0)
    roll = np.arctan2(-tr.C_n_b[:, 2, 0], tr.C_n_b[:, 2, 2])
    t_mid = 0.5 * (tr.t_s[1:] + tr.t_s[:-1])
    # [Chu 2009]: body rate [180, 0, 0] deg/s about its forward axis (our y);
    # Earth and transport rates add < 1e-4 rad/s.
    np.testing.assert_allclose(tr.dtheta_b_rad / tr.dt_s, np.tile([0, np.pi, 0], (tr.t_s.size - 1, 1)), atol=1e-4)
    # Specific force [0, cos(180 t), -sin(180 t)] g in forward-up-right is
    # g [-sin, 0, cos] in right-forward-up. Tolerance: Coriolis 2 Omega v ~ 0.03 m/s^2,
    # gamma(3 km, 34 deg) vs g0 (0.03 m/s^2) and the mid-interval average of a
    # rotating vector (1 - sinc(pi dt) ~ 2e-4 relative).
    phase = np.pi * t_mid
    ref = G0_MPS2 * np.column_stack([-np.sin(phase), np.zeros_like(phase), np.cos(phase)])
    np.testing.assert_allclose(tr.dvel_b_mps / tr.dt_s, ref, atol=0.07)
    np.testing.assert_allclose(np.unwrap(roll), np.pi * tr.t_s, atol=1e-9)


def test_waypoints_climbs_and_coordinated_turns(turns):
    wps, tr = turns
    pos = tr.pos_ecef_m
    for lat, lon, alt in wps[1:]:
        d = np.linalg.norm(pos - frames.geodetic_to_ecef(np.radians(lat), np.radians(lon), alt), axis=1)
        # Legs aim along the normal section, which differs from the flown
        # geodesic by ~1e-6 rad: the miss stays below a couple of metres.
        assert d.min() < 2.0
    assert tr.alt_m.max() == pytest.approx(1500.0, abs=1e-6) and tr.alt_m[-1] == pytest.approx(500.0, abs=1e-6)
    np.testing.assert_allclose(np.hypot(tr.vel_enu_mps[:, 0], tr.vel_enu_mps[:, 1]), 150.0, atol=1e-9)
    _, roll, _ = tr.euler_rad
    # Standard-rate turn at 150 m/s: bank atan(150 * 3 deg/s / g0) = 38.7 deg.
    assert np.degrees(np.abs(roll).max()) == pytest.approx(np.degrees(np.arctan(150 * 3 * ONE_DEG / G0_MPS2)),
                                                          abs=1e-6)
    # Coordinated: the side force stays below 0.5 % of g (bank uses g0 and
    # ignores the geodesic and Earth-rate terms).
    assert np.abs(tr.dvel_b_mps[:, 0] / tr.dt_s).max() < 0.05


def test_resample_keeps_exact_integrals(xb):
    one_hz = xb.resample(1.0)
    assert one_hz.t_s.size == 783
    np.testing.assert_array_equal(one_hz.lat_rad, xb.lat_rad[::100])
    # Sums of 100 increments, to float rounding.
    np.testing.assert_allclose(one_hz.dvel_b_mps[5], xb.dvel_b_mps[500:600].sum(axis=0), rtol=1e-12)
    assert one_hz.pos_ecef_m.shape == (783, 3) and one_hz.quat_n_b.shape == (783, 4)
    with pytest.raises(InputError, match="sample grid"):
        xb.at([0.005])
    with pytest.raises(InputError, match="multiple"):
        xb.resample(0.015)


def test_bad_waypoints_are_input_errors():
    with pytest.raises(InputError, match="waypoints_deg"):
        trajectory.flight([[34.0, 108.0]], alt_m=100.0)
    with pytest.raises(InputError, match="alt_m"):
        trajectory.flight([[34.0, 108.0], [34.1, 108.0]])
    with pytest.raises(InputError, match="speed_mps"):
        trajectory.flight([[34.0, 108.0], [34.1, 108.0]], alt_m=100.0, speed_mps=0.0)
    with pytest.raises(InputError, match="too short"):
        trajectory.flight([[34.0, 108.0, 0.0], [34.01, 108.0, 5000.0]], speed_mps=100.0)


def test_blockwise_imu_integration_is_identical_to_one_block(monkeypatch):
    # The IMU increments are integrated a block of intervals at a time to bound memory;
    # the block size must not change a single bit (per-interval arithmetic only).
    from leosop.ins import trajectory as tr

    wps = [[34.342, 108.940, 3000.0], [34.363, 108.5, 3000.0], [34.5, 108.4, 3100.0]]
    one = tr.flight(wps, rate_hz=100.0, duration_s=60.0)
    monkeypatch.setattr(tr, "_BLOCK_INTERVALS", 7)
    blocks = tr.flight(wps, rate_hz=100.0, duration_s=60.0)
    assert np.array_equal(one.dtheta_b_rad, blocks.dtheta_b_rad)
    assert np.array_equal(one.dvel_b_mps, blocks.dvel_b_mps)


def test_flight_sampled_on_demand_matches_the_whole_trajectory(monkeypatch):
    # plan_flight computes every sample and interval on its own, so the 1 Hz truth and any run of
    # increments are the whole trajectory's bit for bit.
    from leosop.ins import trajectory as tr

    wps = [[34.342, 108.940, 3000.0], [34.363, 108.5, 3000.0], [34.5, 108.4, 3100.0]]
    whole = tr.flight(wps, rate_hz=100.0, duration_s=60.5)
    monkeypatch.setattr(tr, "_BLOCK_INTERVALS", 700)
    planned = tr.plan_flight(wps, rate_hz=100.0, duration_s=60.5)
    assert planned.n_samples == whole.t_s.size and planned.dt_s == whole.dt_s
    at_1hz, ref = planned.track(every=100), whole.at(whole.t_s[::100])
    for name in ("t_s", "lat_rad", "lon_rad", "alt_m", "vel_enu_mps", "C_n_b"):
        assert np.array_equal(getattr(at_1hz, name), getattr(ref, name)), name
    th, dv = planned.increments(1234, 5001)
    assert np.array_equal(th, whole.dtheta_b_rad[1234:5001]) and np.array_equal(dv, whole.dvel_b_mps[1234:5001])
