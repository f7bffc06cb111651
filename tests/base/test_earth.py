"""leosop.earth against published WGS84 values and independent constructions."""

import numpy as np
import pytest

from leosop import earth, frames
from leosop.constants import GM_M3_PER_S2, OMEGA_E_RAD_PER_S, WGS84_A_M

# WGS84 (NIMA TR8350.2, Table 3.4): normal gravity at the pole and J2.
GAMMA_POLE_MPS2 = 9.8321849378
J2 = 1.08262998905e-3
LATS = np.radians([-80.0, -34.3, 0.0, 12.0, 34.342, 60.0, 89.0])


def _gravity_j2(lat_rad, alt_m):
    """|grad| of the J2 + centrifugal potential, by central differences (an independent model)."""
    pos = frames.geodetic_to_ecef(lat_rad, 0.3, alt_m)

    def potential(x):
        r = np.linalg.norm(x)
        s = x[2] / r
        return (GM_M3_PER_S2 / r * (1.0 - J2 * (WGS84_A_M / r) ** 2 * (1.5 * s * s - 0.5))
                + 0.5 * OMEGA_E_RAD_PER_S**2 * (x[0] ** 2 + x[1] ** 2))

    step = np.eye(3) * 1.0
    return np.linalg.norm([(potential(pos + e) - potential(pos - e)) / 2.0 for e in step])


def test_normal_gravity_pole_value():
    # Somigliana's formula must give the published polar gravity (10 digits quoted).
    assert earth.normal_gravity_mps2(np.pi / 2, 0.0) == pytest.approx(GAMMA_POLE_MPS2, abs=1e-9)


@pytest.mark.parametrize("lat_deg", [0.0, 34.342, 60.0, 90.0])
def test_normal_gravity_matches_j2_field(lat_deg):
    lat = np.radians(lat_deg)
    g0 = earth.normal_gravity_mps2(lat, 0.0)
    # Absolute: the J2 model omits J4 and higher even zonals of the normal field, ~1.2e-4 m/s^2.
    assert g0 == pytest.approx(_gravity_j2(lat, 0.0), abs=2e-4)
    for h in (3000.0, 10000.0):
        # Height dependence: the J4 part barely changes over 10 km and the
        # second-order expansion is good to ~1e-7; central differences with
        # a 1 m step add < 1e-8.
        d_ours = earth.normal_gravity_mps2(lat, h) - g0
        d_ref = _gravity_j2(lat, h) - _gravity_j2(lat, 0.0)
        assert d_ours == pytest.approx(d_ref, abs=1e-6)


def test_radii_are_the_curvature_of_geodetic_to_ecef():
    h = 3000.0
    d = 1e-6  # rad; central differences are accurate to ~(d^2) relative = 1e-12
    R_M, R_N = earth.radii_m(LATS)
    dlat = (frames.geodetic_to_ecef(LATS + d, 0.5, h) - frames.geodetic_to_ecef(LATS - d, 0.5, h)) / (2 * d)
    dlon = (frames.geodetic_to_ecef(LATS, 0.5 + d, h) - frames.geodetic_to_ecef(LATS, 0.5 - d, h)) / (2 * d)
    # 1e-9 relative: float rounding of 6e6 m positions divided by 2e-6 rad gives ~1e-3 m on 6e6 m.
    np.testing.assert_allclose(np.linalg.norm(dlat, axis=-1), R_M + h, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(dlon, axis=-1), (R_N + h) * np.cos(LATS), rtol=1e-9)


def test_earth_rate_is_the_polar_axis_in_enu():
    ref = frames.ecef_to_enu(np.array([0.0, 0.0, OMEGA_E_RAD_PER_S]), LATS, 1.1)
    np.testing.assert_allclose(earth.earth_rate_enu(LATS), ref, rtol=0, atol=1e-19)


def test_transport_rate_is_the_rotation_rate_of_enu():
    # Move at vel_enu for +-dt and differentiate C_e_n: Omega_en^n = C_n_e dC_e_n/dt.
    lat, lon, h = np.radians(34.342), np.radians(108.94), 3000.0
    vel = np.array([150.0, -120.0, 7.0])
    R_M, R_N = earth.radii_m(lat)
    rates = np.array([vel[1] / (R_M + h), vel[0] / ((R_N + h) * np.cos(lat))])
    dt = 0.01
    C_p = frames.C_e_n(lat + rates[0] * dt, lon + rates[1] * dt)
    C_m = frames.C_e_n(lat - rates[0] * dt, lon - rates[1] * dt)
    W = frames.C_e_n(lat, lon).T @ (C_p - C_m) / (2 * dt)
    ref = np.array([W[2, 1], W[0, 2], W[1, 0]])
    # Central-difference error ~ (rate dt)^2 ~ 1e-13 relative to 3e-5 rad/s.
    np.testing.assert_allclose(earth.transport_rate_enu(lat, h, vel), ref, rtol=1e-9, atol=1e-15)


def test_local_terms_match_the_vectorised_functions():
    lat, h, ve, vn = 0.6, 3210.0, -180.0, 95.0
    rm_h, rn_h, c, gamma, wie_n, wie_u, wen_e, wen_n, wen_u = earth.local_terms(lat, h, ve, vn)
    R_M, R_N = earth.radii_m(lat)
    # Same formulas in a different arrangement: agreement to float rounding.
    np.testing.assert_allclose([rm_h, rn_h, c, gamma], [R_M + h, R_N + h, np.cos(lat),
                               earth.normal_gravity_mps2(lat, h)], rtol=1e-14)
    np.testing.assert_allclose([0.0, wie_n, wie_u], earth.earth_rate_enu(lat), rtol=1e-14)
    np.testing.assert_allclose([wen_e, wen_n, wen_u], earth.transport_rate_enu(lat, h, [ve, vn, 0.0]), rtol=1e-13)
    np.testing.assert_allclose(earth.gravity_enu_mps2(lat, h), [0.0, 0.0, -gamma], rtol=1e-14)
