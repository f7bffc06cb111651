"""Doppler Jacobian and DOPs against finite differences and direct matrix inverses."""

import numpy as np

from leosop.constants import C_MPS
from leosop.constellations import REGISTRY
from leosop.geometry.dop import cofactor, cofactor_diagonal, gdop, range_dops
from leosop.geometry.doppler import doppler_jacobian

F0 = REGISTRY["starlink"].carrier_hz


def _doppler(x, r_s, v_s):
    d, dv = r_s - x[:3], v_s - x[3:6]
    return -F0 / C_MPS * np.sum(d * dv, -1) / np.linalg.norm(d, axis=-1) + x[6]


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(6)
    r_s, v_s = rng.normal(size=(9, 3)) * 7e6, rng.normal(size=(9, 3)) * 7e3
    x = np.r_[rng.normal(size=3) * 6e6, rng.normal(size=3) * 200, 5.0]
    H = doppler_jacobian(r_s, v_s, x[:3], x[3:6], F0)
    J = np.empty_like(H)
    for i in range(7):
        h = np.eye(7)[i] * (10.0 if i < 3 else 1e-2 if i < 6 else 1.0)
        J[:, i] = (_doppler(x + h, r_s, v_s) - _doppler(x - h, r_s, v_s)) / (2 * h[i])
    # Central differences: truncation ~ (h/range)^2 relative (1e-12 with 10 m
    # steps at 1e4 km), round-off ~ eps * |doppler| / h ~ 1e-11 Hz/m.
    np.testing.assert_allclose(J, H, rtol=1e-7, atol=1e-10)


def test_gdop_equals_direct_inverse_and_masks_drop_rows():
    rng = np.random.default_rng(7)
    H = rng.normal(size=(4, 10, 7))
    direct = [np.sqrt(np.trace(np.linalg.inv(h.T @ h))) for h in H]
    np.testing.assert_allclose(gdop(H), direct, rtol=1e-10)
    w = np.ones((4, 10))
    w[0, 6:] = 0  # 6 rows left: 7 states undetermined
    w[1, 8:] = 0
    g = gdop(H, w)
    assert np.isnan(g[0])
    np.testing.assert_allclose(g[1], np.sqrt(np.trace(np.linalg.inv(H[1, :8].T @ H[1, :8]))), rtol=1e-10)
    # A rank-deficient geometry (two identical rows repeated) is NaN, not noise.
    Hs = np.repeat(H[2:3, :2], 5, axis=1)
    assert np.isnan(gdop(Hs)).all()
    np.testing.assert_allclose(cofactor(H[3]), np.linalg.inv(H[3].T @ H[3]), rtol=1e-9, atol=1e-12)
    # The DOPs' diagonal-only path must give cofactor's diagonal bit for bit: visibility.json prints it in full.
    np.testing.assert_array_equal(cofactor_diagonal(H, w), np.diagonal(cofactor(H, w), axis1=-2, axis2=-1))


def test_range_dops_closed_form():
    # Zenith plus three satellites at elevation 0 spaced 120 deg in azimuth:
    # G^T G = diag(3/2, 3/2, 1, 4) with a -1 coupling of up and clock, so
    # HDOP = sqrt(4/3), and the up/clock block [[1, -1], [-1, 4]] inverts to
    # VDOP = sqrt(4/3), TDOP = sqrt(1/3).
    az = np.radians([0, 120, 240])
    los = np.vstack([[0, 0, 1], np.stack([np.sin(az), np.cos(az), np.zeros(3)], -1)])
    d = range_dops(los)
    np.testing.assert_allclose([d["hdop"], d["vdop"], d["tdop"]], np.sqrt([4 / 3, 4 / 3, 1 / 3]), rtol=1e-12)
    np.testing.assert_allclose(d["pdop"], np.sqrt(4 / 3 + 4 / 3), rtol=1e-12)
