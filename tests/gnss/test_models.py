"""PPP models against closed forms and published values."""

import numpy as np
import pytest

from leosop.constants import C_MPS, GM_M3_PER_S2, OMEGA_E_RAD_PER_S
from leosop.errors import InputError
from leosop.frames import rotate_to_later_ecef
from leosop.gnss import models

ESBC_ECEF_M = np.array([3582105.2910, 532589.7313, 5232754.8054])  # RINEX header, ~1 m
JD_TT_2020_177 = 2459025.5 + np.arange(0.0, 1.0, 1.0 / 96.0)  # 2020-06-25, 15 min


def test_saastamoinen_standard_atmosphere():
    # ZHD = 0.0022768 * 1013.25 hPa = 2.3070 m at sea level, 45 deg [Davis 1985]; 0.1 mm tolerance.
    assert models.saastamoinen_zhd_m(np.radians(45.0), 0.0) == pytest.approx(2.3070, abs=1e-4)
    # US Standard Atmosphere 1976 gives 505.0 hPa at 5.5 km: ZHD = 0.0022768 * 505.0 / (1 - 0.00154); 2 mm.
    assert models.saastamoinen_zhd_m(np.radians(45.0), 5500.0) == pytest.approx(1.1515, abs=2e-3)


def test_niell_mapping_limits():
    m_dry, m_wet = models.niell_mapping(np.radians([90.0, 30.0, 5.0]), np.radians(55.0), 0.0, 177.0)
    assert m_dry[0] == pytest.approx(1.0, abs=1e-12) and m_wet[0] == pytest.approx(1.0, abs=1e-12)
    # Flat-Earth 1/sin(e) = 2 at 30 deg; curvature lowers it by < 0.5 %.
    assert 1.99 < m_dry[1] < 2.0 and 1.99 < m_wet[1] < 2.0
    # Published NMF values at 5 deg are ~10.1 (dry) and ~10.7 (wet) [Niell 1996, fig. 3]; 2 %.
    assert m_dry[2] == pytest.approx(10.15, rel=0.02)
    assert m_wet[2] == pytest.approx(10.7, rel=0.02)


def test_gmf_iers_test_vector_and_niell_at_high_elevation():
    # The IERS Conventions (2010) software's GMF test case (Green Bank, MJD 55055, 16.7 deg elevation):
    # GMFH = 3.425245519339138678, GMFW = 3.449589116182419257; same formulas and coefficients, so only
    # rounding separates them (1e-12).
    m_dry, m_wet = models.gmf_mapping(np.pi / 2 - 1.278564131, 0.6708665767, -1.393397187, 844.715, 55055.0)
    assert m_dry == pytest.approx(3.425245519339138678, abs=1e-12)
    assert m_wet == pytest.approx(3.449589116182419257, abs=1e-12)
    # Both fit the same ray traces' shape: at ESBC00DNK (55.5 N, 8.5 E) on day 177 they agree within 1e-4
    # relative above 30 deg, where the continued fraction is all but 1/sin(e), and [Boehm 2006] fig. 2's
    # NMF-GMF differences (a few mm of 2.3 m hydrostatic delay, i.e. ~1e-3) at 5 deg.
    el = np.radians([90.0, 60.0, 30.0, 5.0])
    lat, lon, h = np.radians(55.47), np.radians(8.45), 60.0
    gmf = models.gmf_mapping(el, lat, lon, h, 59025.5)
    nmf = models.niell_mapping(el, lat, h, 177.5)
    for g, n in zip(gmf, nmf):
        assert g[0] == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(g[1:3], n[1:3], rtol=1e-4)
        assert g[3] == pytest.approx(n[3], rel=3e-3)
        assert g[3] != n[3]  # a second model, not the first under another name


def test_gpt_iers_test_vector_and_esbjerg_sea_level():
    # The IERS Conventions (2010) software's GPT test case as revised on 2011-10-18 (Green Bank, MJD 55055,
    # 812.546 m ellipsoidal): 918.0710638757363995 hPa, undulation -42.19185643717770517 m; rounding only.
    p_hpa, undulation_m = models.gpt_pressure_hpa(0.6708665767, -1.393397187, 812.546, 55055.0)
    assert p_hpa == pytest.approx(918.0710638757363995, abs=1e-9)
    assert undulation_m == pytest.approx(-42.19185643717770517, abs=1e-9)
    # ESBC00DNK (55.49 N, 8.46 E, 59.5 m ellipsoidal): the geoid over Denmark is about 40 m (a degree-9 model
    # keeps it within a few metres), and a North Sea June climatology is 1010-1020 hPa at sea level, the
    # station ~20 m above it (1 hPa per 8.3 m).
    p_hpa, undulation_m = models.gpt_pressure_hpa(np.radians(55.4936), np.radians(8.4568), 59.5, 59025.5)
    assert undulation_m == pytest.approx(40.0, abs=5.0)
    assert 1007.0 < p_hpa < 1018.0


def test_slant_delay_of_each_model_choice():
    # The one troposphere of the PPP, PPP/INS and simulation code against its parts composed by hand: MJD
    # 59025.75 is 2020-06-25 18:00, day of year 177.75 for Niell (2020-01-01 is MJD 58849); the IERS test
    # station's GPT pressure above (918.07 hPa) in Saastamoinen's formula. Exact but for rounding.
    elev = np.radians([5.0, 30.0, 90.0])
    lat, lon, alt = 0.6708665767, -1.393397187, 812.546
    m_dry, m_wet = models.niell_mapping(elev, lat, alt, 177.75)
    dry, wet = models.slant_hydrostatic_and_wet(elev, lat, lon, alt, 59025.75, mapping="niell",
                                                 zhd_pressure="standard")
    np.testing.assert_allclose(dry, models.saastamoinen_zhd_m(lat, alt) * m_dry, rtol=1e-14)
    np.testing.assert_allclose(wet, m_wet, rtol=1e-14)
    g_dry, g_wet = models.gmf_mapping(elev, lat, lon, alt, 55055.0)
    dry, wet = models.slant_hydrostatic_and_wet(elev, lat, lon, alt, 55055.0)
    np.testing.assert_allclose(dry, models.saastamoinen_zhd_m(lat, alt, 918.0710638757364) * g_dry, rtol=1e-12)
    np.testing.assert_allclose(wet, g_wet, rtol=1e-14)
    assert models.mjd(np.datetime64("2020-06-25T18:00")) == 59025.75
    with pytest.raises(InputError, match="mapping 'vmf1': expected one of gmf, niell"):
        models.slant_hydrostatic_and_wet(elev, lat, lon, alt, 55055.0, mapping="vmf1")


def test_sun_moon_distances():
    sun, moon = models.sun_moon_ecef_m(JD_TT_2020_177)
    r_sun = np.linalg.norm(sun, axis=1)
    r_moon = np.linalg.norm(moon, axis=1)
    # Near aphelion (2020-07-04: 1.01669 AU = 152.10e9 m); 0.1 %.
    assert np.all(np.abs(r_sun / 152.08e9 - 1) < 1e-3)
    assert np.all((356e6 < r_moon) & (r_moon < 407e6))
    # Summer solstice + 4 days: the Sun's declination is 23.4 deg within 0.2 deg.
    dec = np.degrees(np.arcsin(sun[:, 2] / r_sun))
    assert np.all(np.abs(dec - 23.38) < 0.2)


def test_solid_tide_amplitude_bounds():
    sun, moon = models.sun_moon_ecef_m(JD_TT_2020_177)
    d = models.solid_tide_ecef_m(ESBC_ECEF_M, sun, moon)
    up = ESBC_ECEF_M / np.linalg.norm(ESBC_ECEF_M)
    radial = d @ up
    horiz = np.linalg.norm(d - radial[:, None] * up, axis=1)
    # Radial body tide is at most ~0.4 m and horizontal ~0.05 m (IERS 2010 ch. 7); a day spans > 0.1 m.
    assert np.all(np.abs(radial) < 0.4) and np.all(horiz < 0.06)
    assert np.ptp(radial) > 0.1


def test_relativistic_clock_closed_form():
    # Keplerian orbit: r.v = sqrt(GM a) e sin(E), so the term is -2 sqrt(GM a) e sin(E) / c^2.
    a, e, E = 26_560e3, 0.01, np.radians(90.0)
    n = np.sqrt(GM_M3_PER_S2 / a**3)
    r = np.array([a * (np.cos(E) - e), a * np.sqrt(1 - e**2) * np.sin(E), 0.0])
    Edot = n / (1 - e * np.cos(E))
    v = np.array([-a * np.sin(E) * Edot, a * np.sqrt(1 - e**2) * np.cos(E) * Edot, 0.0])
    expected = -2 * np.sqrt(GM_M3_PER_S2 * a) * e * np.sin(E) / C_MPS**2
    assert models.relativistic_clock_s(r, v) == pytest.approx(expected, rel=1e-12)
    assert abs(expected) == pytest.approx(22.9e-9, rel=0.01)  # ~23 ns for e = 0.01 (IS-GPS-200)


def test_sagnac_first_order():
    rs = np.array([15_000e3, 10_000e3, 18_000e3])
    rr = ESBC_ECEF_M
    tau = np.linalg.norm(rs - rr) / C_MPS
    rho_rot = np.linalg.norm(rotate_to_later_ecef(rs, tau) - rr)
    sagnac = OMEGA_E_RAD_PER_S / C_MPS * (rs[0] * rr[1] - rs[1] * rr[0])
    # Range change equals omega/c (xs yr - ys xr) to ~1 mm at this size (second-order terms).
    assert rho_rot - np.linalg.norm(rs - rr) == pytest.approx(sagnac, abs=1e-3)


def test_shapiro_size():
    rs = np.array([0.0, 0.0, 26_560e3])
    # Zenith: rho = rs - rr, so the log argument is rs / rr; about 1.3 cm.
    rr = np.array([0.0, 0.0, 6_371e3])
    expected = 2 * GM_M3_PER_S2 / C_MPS**2 * np.log(26_560e3 / 6_371e3)
    assert models.shapiro_m(rs, rr) == pytest.approx(expected, abs=1e-6)
    assert 0.01 < expected < 0.02


def test_windup_is_continuous_and_symmetric_overhead():
    sun, _ = models.sun_moon_ecef_m(JD_TT_2020_177)
    lat, lon = np.radians(55.49), np.radians(8.46)
    up = ESBC_ECEF_M / np.linalg.norm(ESBC_ECEF_M)
    # A satellite moving through the zenith region over 24 h of 15-min steps.
    ang = np.linspace(-0.3, 0.3, len(sun))
    east = np.array([-np.sin(lon), np.cos(lon), 0.0])
    rs = (np.cos(ang)[:, None] * up + np.sin(ang)[:, None] * east) * 26_560e3
    w = models.windup_cycles(rs[:, None, :], ESBC_ECEF_M, sun, lat, lon)
    assert w.shape == (len(sun), 1)
    assert np.all(np.abs(np.diff(w[:, 0])) < 0.5)  # unwrapped: no cycle jumps between steps


def test_etrf2000_is_the_published_similarity():
    """PROJ's EPSG:8405 against the 14 parameters of [Altamimi 2018] table 5 written out here (first order in
    the rotations; the second-order terms are ~1e-13 of a coordinate): a wrong pair of EPSG codes or a sign
    convention (position vector vs coordinate frame) would differ by centimetres, so 1e-6 m."""
    from leosop.gnss.etrf import itrf2014_to_etrf2000

    mas = np.pi / (180 * 3600e3)
    for epoch in (2010.0, 2020.48, 2031.2):
        dt = epoch - 2010.0
        T = (np.array([54.7, 52.2, -74.1]) + np.array([0.1, 0.1, -1.9]) * dt) * 1e-3
        D = (2.12 + 0.11 * dt) * 1e-9
        R = (np.array([1.701, 10.290, -16.632]) + np.array([0.081, 0.490, -0.792]) * dt) * mas
        expected = ESBC_ECEF_M + T + D * ESBC_ECEF_M + np.cross(R, ESBC_ECEF_M)
        np.testing.assert_allclose(itrf2014_to_etrf2000(ESBC_ECEF_M, epoch), expected, rtol=0, atol=1e-6)
    # Arrays of points and epochs keep their shape.
    pts = ESBC_ECEF_M + np.arange(12.0).reshape(2, 2, 3) * 1e3
    assert itrf2014_to_etrf2000(pts, np.full((2, 2), 2020.5)).shape == (2, 2, 3)


def test_etrf2000_drift_is_eurasian_plate_motion():
    from leosop.gnss.etrf import etrf2000_to_itrf2014, itrf2014_to_etrf2000

    # Round trip to 1e-9 m (two fixed-point steps of a 1e-7 relative correction).
    p = itrf2014_to_etrf2000(ESBC_ECEF_M, 2020.5)
    np.testing.assert_allclose(etrf2000_to_itrf2014(p, 2020.5), ESBC_ECEF_M, atol=1e-9)
    # The yearly change of ETRF2000 - ITRF2014 is the Eurasian plate's rotation, independently published in
    # the ITRF2014 plate motion model [Altamimi 2017]: omega = (-0.085, -0.531, 0.770) mas/yr. ETRF2000 is
    # tied to the plate of the older ITRF2000 model, hence ~1 mm/yr between them: that is the tolerance.
    rate = itrf2014_to_etrf2000(ESBC_ECEF_M, 2021.0) - itrf2014_to_etrf2000(ESBC_ECEF_M, 2020.0)
    omega = np.radians(np.array([-0.085, -0.531, 0.770]) / 3.6e6)
    plate = np.cross(omega, ESBC_ECEF_M)  # station velocity in ITRF2014
    np.testing.assert_allclose(rate, -plate, atol=1.5e-3)
    assert 0.02 < np.linalg.norm(plate) < 0.03  # ~2.5 cm/yr north-east in Denmark
