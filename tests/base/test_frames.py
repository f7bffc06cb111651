"""Frames against closed forms and against skyfield (an independent implementation)."""

import datetime as dt

import numpy as np
import pytest

from leosop import frames
from leosop.constants import OMEGA_E_RAD_PER_S, WGS84_A_M, WGS84_B_M
from leosop.orbits import read_tle
from leosop.orbits.propagate import state_ecef

from tests.helpers import data_path

ONE_MM = 1e-3  # m
ONE_NRAD = 1e-9  # rad: ~6 mm on the Earth's surface


def test_geodetic_closed_forms():
    pos = frames.geodetic_to_ecef(np.radians([0.0, 90.0, 0.0]), np.radians([0.0, 0.0, 90.0]), [0.0, 0.0, 100.0])
    expected = [[WGS84_A_M, 0, 0], [0, 0, WGS84_B_M], [0, WGS84_A_M + 100.0, 0]]
    np.testing.assert_allclose(pos, expected, atol=ONE_MM)


def test_geodetic_round_trip_from_depth_to_geo():
    rng = np.random.default_rng(1)
    lat = rng.uniform(-np.pi / 2, np.pi / 2, 2000)
    lon = rng.uniform(-np.pi, np.pi, 2000)
    alt = rng.uniform(-5e3, 4.2e7, 2000)
    lat2, lon2, alt2 = frames.ecef_to_geodetic(frames.geodetic_to_ecef(lat, lon, alt))
    np.testing.assert_allclose(lat2, lat, atol=ONE_NRAD)
    np.testing.assert_allclose(np.angle(np.exp(1j * (lon2 - lon))), 0, atol=ONE_NRAD)
    np.testing.assert_allclose(alt2, alt, atol=ONE_MM)


def test_enu_rotation_is_orthonormal_and_round_trips():
    rng = np.random.default_rng(2)
    lat, lon = rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)
    C = frames.C_e_n(lat, lon)
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=1e-15)
    v = rng.normal(size=(50, 3))
    np.testing.assert_allclose(frames.enu_to_ecef(frames.ecef_to_enu(v, lat, lon), lat, lon), v, atol=1e-12)
    np.testing.assert_allclose(frames.ned_to_enu(frames.enu_to_ned(v)), v)


def test_azimuth_elevation_closed_forms():
    lat, lon = np.radians(30.0), np.radians(40.0)
    rx = frames.geodetic_to_ecef(lat, lon, 0.0)
    up, north = frames.C_e_n(lat, lon)[:, 2], frames.C_e_n(lat, lon)[:, 1]
    east = frames.C_e_n(lat, lon)[:, 0]
    sv = np.stack([rx + 550e3 * up, rx + 1e6 * (east + up) / np.sqrt(2), rx + 1e6 * north])
    az, el, rng = frames.azimuth_elevation_range(sv, rx)
    np.testing.assert_allclose(np.degrees(el), [90.0, 45.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(np.degrees(az[1:]), [90.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(rng, [550e3, 1e6, 1e6], atol=ONE_MM)


def test_range_rate_is_derivative_of_range():
    rng = np.random.default_rng(3)
    r_s, v_s = rng.normal(size=(20, 3)) * 7e6, rng.normal(size=(20, 3)) * 7e3
    r_r, v_r = rng.normal(size=3) * 6e6, rng.normal(size=3) * 200
    h = 1e-3
    fd = (np.linalg.norm(r_s + h * v_s - r_r - h * v_r, axis=-1)
          - np.linalg.norm(r_s - h * v_s - r_r + h * v_r, axis=-1)) / (2 * h)
    # Central difference error ~ h^2 * a / 6 with a ~ v^2/range: well below 1e-6 m/s.
    np.testing.assert_allclose(frames.range_rate(r_s, v_s, r_r, v_r), fd, atol=1e-6)


def test_rotate_to_later_ecef_is_the_z_rotation_matrix():
    # The three former private copies and gnss.models.sagnac_rotate all computed
    # R3(OMEGA_E dt) v with R3(t) = [[cos t, sin t, 0], [-sin t, cos t, 0], [0, 0, 1]]:
    # check against that matrix built element by element, over broadcast shapes.
    rng = np.random.default_rng(7)
    vec = rng.normal(scale=7e6, size=(4, 5, 3))
    dt_s = rng.uniform(-0.1, 0.1, size=(4, 5))  # light times of both signs, as the callers pass
    th = OMEGA_E_RAD_PER_S * dt_s
    c, s, z, o = np.cos(th), np.sin(th), np.zeros_like(th), np.ones_like(th)
    R3 = np.stack([np.stack([c, s, z], -1), np.stack([-s, c, z], -1), np.stack([z, z, o], -1)], -2)
    expected = np.einsum("...ij,...j->...i", R3, vec)
    np.testing.assert_allclose(frames.rotate_to_later_ecef(vec, dt_s), expected, rtol=0, atol=1e-8)  # 1e-15 rel
    one = frames.rotate_to_later_ecef(vec[0, 0], dt_s[0, 0])
    np.testing.assert_allclose(one, expected[0, 0], rtol=0, atol=1e-8)
    back = frames.rotate_to_later_ecef(frames.rotate_to_later_ecef(vec, dt_s), -dt_s)
    np.testing.assert_allclose(back, vec, rtol=0, atol=1e-8)


def test_rotate_to_later_ecef_moves_an_inertial_point_west():
    # A point fixed in inertial space appears OMEGA_E dt further west in the ECEF frame dt later.
    lat, lon, alt, dt_s = np.radians(40.0), np.radians([-170.0, 10.0, 120.0]), 550e3, np.array([0.07, 3.0, -20.0])
    moved = frames.rotate_to_later_ecef(frames.geodetic_to_ecef(lat, lon, alt), dt_s)
    np.testing.assert_allclose(moved, frames.geodetic_to_ecef(lat, lon - OMEGA_E_RAD_PER_S * dt_s, alt), atol=ONE_MM)


def test_teme_to_ecef_matches_skyfield_itrs_for_real_starlink_over_a_day():
    """Issue bound: 1 m in position, 1 mm/s in velocity, against skyfield's ITRS."""
    from skyfield.api import EarthSatellite, load
    from skyfield.framelib import itrs

    const = read_tle(data_path("tle", "starlink_3le_2026-04-08_Bochika.txt"))
    const = const.subset(np.arange(0, len(const), len(const) // 12))
    start = dt.datetime(2026, 4, 8, tzinfo=dt.UTC)
    steps = [start + dt.timedelta(minutes=m) for m in range(0, 24 * 60, 97)]
    times = np.array([np.datetime64(s.replace(tzinfo=None), "ns") for s in steps])
    pos, vel, status = state_ecef(const, times)
    assert (status == 0).all()
    ts = load.timescale(builtin=True)
    t = ts.from_datetimes(steps)
    for k, sat in enumerate(const.satrecs):
        r, v = EarthSatellite.from_satrec(sat, ts).at(t).frame_xyz_and_velocity(itrs)
        np.testing.assert_allclose(pos[k], r.m.T, atol=1.0)
        np.testing.assert_allclose(vel[k], v.m_per_s.T, atol=ONE_MM)


def test_teme_to_ecef_velocity_is_derivative_of_position():
    # Rotating-frame velocity: d/dt of the ECEF position, by central differences
    # of the transform itself (1 ms steps: truncation error ~ 1e-7 m/s).
    from leosop.timebase import jd_ut1

    r = np.array([6.9e6, 1.0e5, 2.0e5])
    v = np.array([10.0, 4.5e3, 6.0e3])
    t0 = np.datetime64("2025-01-01T12:00:00", "ns")
    h = np.timedelta64(1, "ms")
    jd, fr = jd_ut1(np.array([t0 - h, t0, t0 + h]))
    pos, vel = frames.teme_to_ecef(np.stack([r - 1e-3 * v, r, r + 1e-3 * v]), np.tile(v, (3, 1)), jd, fr)
    np.testing.assert_allclose(vel[1], (pos[2] - pos[0]) / 2e-3, atol=1e-4)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="3 components"):
        frames.ecef_to_geodetic(np.zeros((4, 2)))
