"""Property-based tests (hypothesis) of the core numerics and the parsers (issue 13).

Frames and rotations round trip; the Doppler model's Jacobian and rate match
finite differences; noise-free snapshot least squares recovers the receiver
on random geometries; the TLE, time, SigMF and IMU CSV readers give back
what was written. Examples are kept few (each test well under a few seconds).
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from leosop.constants import C_MPS
from leosop.frames import C_e_n, ecef_to_enu, ecef_to_geodetic, enu_to_ecef, geodetic_to_ecef, range_rate
from leosop.ins.imu_io import read_rtklib_sf_csv
from leosop.orbits.tle import parse_tle_lines, tle_checksum
from leosop.geometry.doppler import doppler_jacobian, doppler_rate
from leosop.positioning.snapshot import solve_snapshots
from leosop.rotations import (dcm_to_euler, dcm_to_quat, euler_to_dcm, quat_multiply, quat_normalize, quat_to_dcm,
                              rotvec_to_dcm)
from leosop.signal.iq import open_sigmf
from leosop.signal.iq_write import write_sigmf
from leosop.timebase import format_utc, parse_utc, round_utc

FAST = settings(max_examples=40, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])
ONE_MM = 1e-3  # [m] round trips of ECEF positions: double precision at 1e7 m is ~2e-9 m
F_KU_HZ = 11.325e9  # Starlink downlink carrier

lat_deg = st.floats(-90.0, 90.0)
lon_deg = st.floats(-180.0, 180.0)
alt_m = st.floats(-1e4, 1e7)
unit_float = st.floats(-1.0, 1.0)
vec3 = st.tuples(unit_float, unit_float, unit_float).map(np.array)


@FAST
@given(lat_deg, lon_deg, alt_m)
def test_geodetic_ecef_round_trip(lat, lon, alt):
    pos = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    back = geodetic_to_ecef(*ecef_to_geodetic(pos))
    assert np.linalg.norm(back - pos) < ONE_MM
    assert ecef_to_geodetic(pos)[2] == pytest.approx(alt, abs=ONE_MM)


@FAST
@given(lat_deg, lon_deg, vec3)
def test_enu_rotation_is_orthonormal_and_inverts(lat, lon, v):
    C = C_e_n(np.radians(lat), np.radians(lon))
    assert np.allclose(C.T @ C, np.eye(3), atol=1e-12) and np.linalg.det(C) == pytest.approx(1.0)
    enu = ecef_to_enu(v, np.radians(lat), np.radians(lon))
    assert np.allclose(enu_to_ecef(enu, np.radians(lat), np.radians(lon)), v, atol=1e-12)
    assert np.linalg.norm(enu) == pytest.approx(np.linalg.norm(v), abs=1e-12)


angle = st.floats(-np.pi, np.pi)


@FAST
@given(st.floats(-1.55, 1.55), angle, angle)
def test_euler_dcm_round_trip(pitch, roll, yaw):
    C = euler_to_dcm(pitch, roll, yaw)
    assert np.allclose(C @ C.T, np.eye(3), atol=1e-12) and np.linalg.det(C) == pytest.approx(1.0)
    assert np.allclose(euler_to_dcm(*dcm_to_euler(C)), C, atol=1e-12)


quat = st.tuples(unit_float, unit_float, unit_float, unit_float).filter(
    lambda q: np.linalg.norm(q) > 0.1).map(lambda q: quat_normalize(np.array(q)))


@FAST
@given(quat, quat)
def test_quaternion_product_is_the_dcm_product(p, q):
    assert np.allclose(quat_to_dcm(quat_multiply(p, q)), quat_to_dcm(p) @ quat_to_dcm(q), atol=1e-12)
    back = dcm_to_quat(quat_to_dcm(p))
    assert np.allclose(back, p, atol=1e-9) or np.allclose(back, -p, atol=1e-9)  # q and -q: one rotation


@FAST
@given(vec3.map(lambda v: 3.0 * v))
def test_rotation_vector_keeps_its_axis_and_inverts(phi):
    R = rotvec_to_dcm(phi)
    assert np.allclose(R @ phi, phi, atol=1e-12)
    assert np.allclose(R @ rotvec_to_dcm(-phi), np.eye(3), atol=1e-12)


def _sky(rng_seed, n_sv, lat, lon):
    """Receiver on the ellipsoid and ``n_sv`` satellites at 550 km above its horizon, in LEO motion."""
    rng = np.random.default_rng(rng_seed)
    rx = geodetic_to_ecef(np.radians(lat), np.radians(lon), 0.0)
    az = rng.uniform(0, 2 * np.pi, n_sv)
    el = np.radians(rng.uniform(20, 90, n_sv))
    los_enu = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)
    los = enu_to_ecef(los_enu, np.radians(lat), np.radians(lon))
    # Range to a 550 km shell along each line of sight.
    r_shell = 6_371e3 + 550e3
    b = los @ rx
    rho = -b + np.sqrt(b**2 - (rx @ rx - r_shell**2))
    pos = rx + rho[:, None] * los
    vel = np.cross(pos, rng.normal(size=(n_sv, 3)))
    vel *= 7_600.0 / np.linalg.norm(vel, axis=-1, keepdims=True)
    return rx, pos, vel


seeds = st.integers(0, 2**32 - 1)


@FAST
@given(seeds, lat_deg.filter(lambda x: abs(x) < 89), lon_deg)
def test_doppler_jacobian_matches_finite_differences(seed, lat, lon):
    rx, pos, vel = _sky(seed, 5, lat, lon)
    vel_rx = np.random.default_rng(seed + 1).normal(scale=50.0, size=3)

    def doppler(x):
        return -F_KU_HZ / C_MPS * range_rate(pos, vel, x[:3], x[3:6]) + x[6]

    x = np.r_[rx, vel_rx, 3.0]
    H = doppler_jacobian(pos, vel, rx, vel_rx, F_KU_HZ)
    steps = np.r_[[1.0] * 3, [1e-3] * 3, 1.0]
    fd = np.stack([(doppler(x + np.eye(7)[j] * h) - doppler(x - np.eye(7)[j] * h)) / (2 * h)
                   for j, h in enumerate(steps)], axis=-1)
    assert np.allclose(H, fd, rtol=1e-5, atol=1e-9)


def _accel(r, v):
    """Two-body gravity plus the centrifugal and Coriolis terms of the Earth-fixed frame."""
    from leosop.constants import GM_M3_PER_S2, OMEGA_E_RAD_PER_S

    w = np.array([0.0, 0.0, OMEGA_E_RAD_PER_S])
    return -GM_M3_PER_S2 * r / np.linalg.norm(r, axis=-1, keepdims=True) ** 3 - 2 * np.cross(w, v) \
        - np.cross(w, np.cross(w, r))


def _propagate(r, v, dt_s):
    """One RK4 step of the Earth-fixed equations of motion."""
    k1r, k1v = v, _accel(r, v)
    k2r, k2v = v + 0.5 * dt_s * k1v, _accel(r + 0.5 * dt_s * k1r, v + 0.5 * dt_s * k1v)
    k3r, k3v = v + 0.5 * dt_s * k2v, _accel(r + 0.5 * dt_s * k2r, v + 0.5 * dt_s * k2v)
    k4r, k4v = v + dt_s * k3v, _accel(r + dt_s * k3r, v + dt_s * k3v)
    return r + dt_s / 6 * (k1r + 2 * k2r + 2 * k3r + k4r), v + dt_s / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)


@FAST
@given(seeds, lat_deg.filter(lambda x: abs(x) < 89), lon_deg)
def test_doppler_rate_matches_finite_differences(seed, lat, lon):
    rx, pos, vel = _sky(seed, 4, lat, lon)
    dt = 0.05
    dop = [-F_KU_HZ / C_MPS * range_rate(*_propagate(pos, vel, s * dt), rx) for s in (-1, 1)]
    rate, grad = doppler_rate(pos, vel, rx, F_KU_HZ)
    assert np.allclose(rate, (dop[1] - dop[0]) / (2 * dt), rtol=1e-5, atol=1e-3)
    h = 10.0
    fd = np.stack([(doppler_rate(pos, vel, rx + np.eye(3)[j] * h, F_KU_HZ)[0]
                    - doppler_rate(pos, vel, rx - np.eye(3)[j] * h, F_KU_HZ)[0]) / (2 * h) for j in range(3)], -1)
    assert np.allclose(grad, fd, rtol=1e-4, atol=1e-9)


@settings(max_examples=25, deadline=None, database=None)
@given(seeds, lat_deg.filter(lambda x: abs(x) < 85), lon_deg, st.integers(8, 14), st.floats(-2e4, 2e4))
def test_noise_free_snapshot_recovers_the_receiver(seed, lat, lon, n_sv, clock_hz):
    rx, pos, vel = _sky(seed, n_sv, lat, lon)
    y = -F_KU_HZ / C_MPS * range_rate(pos, vel, rx) + clock_hz
    start = np.r_[rx + np.random.default_rng(seed).normal(scale=2e3, size=3), np.zeros(4)]
    fix = solve_snapshots(y[None], 1.0, pos[None], vel[None], F_KU_HZ, x0=start, alpha=None)
    assume(np.isfinite(fix.gdop[0]) and fix.gdop[0] < 1e4)  # a degenerate draw says nothing about the solver
    assert np.linalg.norm(fix.pos_ecef_m[0] - rx) < 1.0
    assert np.linalg.norm(fix.vel_ecef_mps[0]) < 1e-2
    assert fix.clock_offset_hz[0] == pytest.approx(clock_hz, abs=1e-3)


def _tle_lines(sat, epoch_day, incl, raan, ecc, argp, ma, mm):
    l1 = f"1 {sat:05d}U 25001A   25{epoch_day:012.8f}  .00000000  00000-0  00000+0 0    0"
    l2 = f"2 {sat:05d} {incl:8.4f} {raan:8.4f} {round(ecc * 1e7):07d} {argp:8.4f} {ma:8.4f} {mm:11.8f}    0"
    return [line + str(tle_checksum(line)) for line in (l1, l2)]


@FAST
@given(st.integers(1, 99999), st.floats(1.0, 365.99), st.floats(0, 180), st.floats(0, 359.9999),
       st.floats(0, 0.01), st.floats(0, 359.9999), st.floats(0, 359.9999), st.floats(11.0, 16.4))
def test_tle_round_trip(sat, day, incl, raan, ecc, argp, ma, mm):
    const = parse_tle_lines(["SAT", *_tle_lines(sat, day, incl, raan, ecc, argp, ma, mm)])
    s = const.satrecs[0]
    assert const.sat_ids[0] == str(sat)
    assert s.epochdays == pytest.approx(day, abs=1e-8)
    assert np.degrees([s.inclo, s.nodeo, s.argpo, s.mo]) == pytest.approx([incl, raan, argp, ma], abs=1e-4)
    assert s.ecco == pytest.approx(round(ecc * 1e7) * 1e-7, abs=1e-12)
    assert s.no_kozai * 1440 / (2 * np.pi) == pytest.approx(mm, abs=1e-8)


@FAST
@given(st.integers(-2_000_000_000_000_000_000, 2_000_000_000_000_000_000))
def test_utc_text_round_trip(ns):
    t = np.datetime64(ns, "ns")
    assert np.datetime64(parse_utc(format_utc(t)), "us") == round_utc(t, "us")
    assert abs(parse_utc(format_utc(t)) - t) <= np.timedelta64(500, "ns")


@FAST
@given(seeds, st.integers(1, 300), st.sampled_from(["cf32_le", "ci16_le"]), st.floats(1e3, 1e8),
       st.floats(1e6, 3e10))
def test_sigmf_round_trip(tmp_path, seed, n, datatype, fs, fc):
    rng = np.random.default_rng(seed)
    x = (rng.uniform(-0.7, 0.7, n) + 1j * rng.uniform(-0.7, 0.7, n)).astype(np.complex64)
    meta = tmp_path / f"r{seed}.sigmf-meta"
    write_sigmf(meta, [x[: n // 2], x[n // 2:]], sample_rate_hz=fs, center_hz=fc, datatype=datatype,
                start_utc="2025-01-01T00:00:00Z")
    rec = open_sigmf(meta)
    assert (rec.n_samples, rec.datatype, rec.sample_rate_hz, rec.center_hz) == (n, datatype, fs, fc)
    tol = 0.0 if datatype == "cf32_le" else 2.0 / 32768  # rounding, and 32767 written for 32768 read
    assert np.allclose(rec.read(0, n), x, atol=tol, rtol=0)


@FAST
@given(seeds, st.integers(3, 60), st.floats(1.0, 1000.0))
def test_imu_sf_csv_round_trip(tmp_path, seed, n, rate_hz):
    rng = np.random.default_rng(seed)
    t = 1.6e9 + np.arange(n) / rate_hz
    acc_g, gyro = rng.normal(size=(n, 3)), rng.normal(scale=0.1, size=(n, 3))
    path = tmp_path / f"imu{seed}_sf.csv"
    path.write_text("".join(",".join(f"{v:.17g}" for v in (tk, *a, *g)) + ",0,0,0,0\n"
                            for tk, a, g in zip(t, acc_g, gyro)))
    log = read_rtklib_sf_csv(path)
    assert np.allclose(log.dt_s, np.diff(t), rtol=1e-12, atol=1e-9)
    assert np.allclose(log.gyro_rad_per_s, gyro[1:], rtol=1e-6, atol=1e-9)
    assert np.allclose(log.accel_mps2 / 9.80665, acc_g[1:], rtol=1e-6, atol=1e-9)


@FAST
@given(st.floats(-90, 90), st.floats(-180, 360), st.floats(-1.2e4, 1e8))
def test_site_option_round_trip(lat, lon, alt):
    from leosop.cli.options import parse_site

    assert parse_site(f"{lat!r},{lon!r},{alt!r}") == (lat, lon, alt)


@FAST
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_float_options_take_every_finite_number_and_nothing_else(value):
    import argparse

    from leosop.cli.options import finite_float

    if np.isfinite(value):
        assert finite_float(repr(value)) == value
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="is not a finite number"):
            finite_float(repr(value))
