"""GNSS measurement models for PPP: troposphere (NMF, GMF), tides, wind-up, relativity, Sagnac.

Every function is vectorised over leading axes; vectors keep three
components in the last axis, ECEF (ITRF) metres. Time arguments ``jd_tt`` are
Julian dates in TT (from GPS time: ``TT = GPST + 51.184 s``); the Sun and
Moon are low-precision analytic ephemerides ([Montenbruck 2000], section
3.3.2: ~0.1 deg Sun, a few arcmin Moon), ample for tides (mm) and the
satellite attitude of the wind-up model.
"""

import numpy as np

from ..constants import C_MPS, DAY_S, GM_M3_PER_S2, JD_J2000, WGS84_A_M
from ..frames import gmst1982

__all__ = [
    "TT_MINUS_GPST_S",
    "gmf_mapping",
    "gradient_mapping",
    "niell_mapping",
    "relativistic_clock_s",
    "saastamoinen_zhd_m",
    "satellite_axes",
    "shapiro_m",
    "solid_tide_ecef_m",
    "sun_moon_ecef_m",
    "windup_cycles",
]

#: TT - GPST [s] (TAI - GPST = 19 s, TT - TAI = 32.184 s).
TT_MINUS_GPST_S = 51.184
#: GM of the Sun and the Moon over GM of the Earth (IERS Conventions 2010, table 1.1).
GM_SUN_OVER_EARTH = 332_946.0482
GM_MOON_OVER_EARTH = 0.0123000371
_ARCSEC = np.pi / (180.0 * 3600.0)


def saastamoinen_zhd_m(lat_rad, alt_m, pressure_hpa=None):
    """Zenith hydrostatic delay [Saastamoinen 1972], formulation of [Davis 1985].

    ``ZHD = 0.0022768 P / (1 - 0.00266 cos 2 lat - 0.28e-6 h)``. Without a
    pressure the standard atmosphere gives it: ``P = 1013.25 (1 - 2.2557e-5
    h)^5.2568`` hPa ([Berg 1948]).

    Returns
    -------
    ndarray
        Zenith hydrostatic delay [m]; 2.31 m at sea level, 45 deg.
    """
    alt_m = np.asarray(alt_m, float)
    if pressure_hpa is None:
        pressure_hpa = 1013.25 * (1.0 - 2.2557e-5 * alt_m) ** 5.2568
    return 0.0022768 * pressure_hpa / (1.0 - 0.00266 * np.cos(2.0 * lat_rad) - 0.28e-6 * alt_m)


# [Niell 1996] mapping function coefficients at latitudes 15, 30, 45, 60, 75 deg.
_NMF_LAT = np.radians([15.0, 30.0, 45.0, 60.0, 75.0])
_NMF_H_AVG = np.array([
    [1.2769934e-3, 1.2683230e-3, 1.2465397e-3, 1.2196049e-3, 1.2045996e-3],
    [2.9153695e-3, 2.9152299e-3, 2.9288445e-3, 2.9022565e-3, 2.9024912e-3],
    [62.610505e-3, 62.837393e-3, 63.721774e-3, 63.824265e-3, 64.258455e-3]])
_NMF_H_AMP = np.array([
    [0.0, 1.2709626e-5, 2.6523662e-5, 3.4000452e-5, 4.1202191e-5],
    [0.0, 2.1414979e-5, 3.0160779e-5, 7.2562722e-5, 11.723375e-5],
    [0.0, 9.0128400e-5, 4.3497037e-5, 84.795348e-5, 170.37206e-5]])
_NMF_W = np.array([
    [5.8021897e-4, 5.6794847e-4, 5.8118019e-4, 5.9727542e-4, 6.1641693e-4],
    [1.4275268e-3, 1.5138625e-3, 1.4572752e-3, 1.5007428e-3, 1.7599082e-3],
    [4.3472961e-2, 4.6729510e-2, 4.3908931e-2, 4.4626982e-2, 5.4736038e-2]])
_NMF_HT = (2.53e-5, 5.49e-3, 1.14e-3)


def _marini(sin_el, a, b, c):
    """Continued fraction of [Marini 1972] normalised to 1 at zenith."""
    return (1.0 + a / (1.0 + b / (1.0 + c))) / (sin_el + a / (sin_el + b / (sin_el + c)))


def niell_mapping(elev_rad, lat_rad, alt_m, doy):
    """Hydrostatic and wet mapping functions of [Niell 1996].

    Parameters
    ----------
    elev_rad, lat_rad, alt_m, doy : array_like, broadcastable
        Elevation, geodetic latitude, height, day of year (UTC, fractional).

    Returns
    -------
    m_dry, m_wet : ndarray
        Both 1 at zenith, about 1/sin(elev) above 15 deg.
    """
    elev_rad, lat_rad, alt_m, doy = np.broadcast_arrays(*(np.asarray(v, float) for v in (elev_rad, lat_rad,
                                                                                          alt_m, doy)))
    alat = np.abs(lat_rad)
    phase = 2.0 * np.pi * (doy - 28.0) / 365.25 + np.where(lat_rad < 0, np.pi, 0.0)
    coef_h = [np.interp(alat, _NMF_LAT, _NMF_H_AVG[i]) - np.interp(alat, _NMF_LAT, _NMF_H_AMP[i]) * np.cos(phase)
              for i in range(3)]
    coef_w = [np.interp(alat, _NMF_LAT, _NMF_W[i]) for i in range(3)]
    s = np.sin(elev_rad)
    m_dry = _marini(s, *coef_h) + (1.0 / s - _marini(s, *_NMF_HT)) * alt_m * 1e-3
    m_wet = _marini(s, *coef_w)
    return m_dry, m_wet


# [Boehm 2006] GMF: spherical-harmonic coefficients (degree and order 9, 1e-5 units; n = 0..9, m = 0..n in
# that order) of the mean and annual amplitude of the hydrostatic (h) and wet (w) continued-fraction ``a``,
# cosine (a) and sine (b) parts, as published with the paper and in [IERS 2010] ch. 9. Rows: ah_mean,
# bh_mean, ah_amp, bh_amp, aw_mean, bw_mean, aw_amp, bw_amp.
_GMF_COEF = np.array("""
125.17 0.8503 0.06936 -6.76 0.1771 0.0113 0.5963 0.01808 0.002801 -0.001414 -1.212 0.093 0.003683 0.001095
4.671e-05 0.3959 -0.03867 0.005413 -0.0005289 0.0003229 2.067e-05 0.3 0.02031 0.0059 0.0004573 -7.619e-05
2.327e-06 3.845e-06 0.1182 0.01158 0.005445 6.219e-05 4.204e-06 -2.093e-06 1.54e-07 -4.28e-08 -0.4751 -0.0349
0.001758 0.0004019 -2.799e-06 -1.287e-06 5.468e-07 7.58e-08 -6.3e-09 -0.116 0.008301 0.0008771 9.955e-05
-1.718e-06 -2.012e-06 1.17e-08 1.79e-08 -1.3e-09 1e-10
0.0 0.0 0.03249 0.0 0.03324 0.0185 0.0 -0.1115 0.02519 0.004923 0.0 0.02737 0.01595 -0.0007332 0.0001933 0.0
-0.04796 0.006381 -0.0001599 -0.0003685 1.815e-05 0.0 0.07033 0.002426 -0.001111 -0.0001357 -7.828e-06 2.547e-06
0.0 0.005779 0.003133 -0.0005312 -2.028e-05 2.323e-07 -9.1e-08 -1.65e-08 0.0 0.03688 -0.0008638 -8.514e-05
-2.828e-05 5.403e-07 4.39e-07 1.35e-08 1.8e-09 0.0 -0.02736 -0.0002977 8.113e-05 2.329e-07 8.451e-07 4.49e-08
-8.1e-09 -1.5e-09 2e-10
-0.2738 -2.837 0.01298 -0.3588 0.02413 0.03427 -0.7624 0.07272 0.0216 -0.003385 0.4424 0.03722 0.02195 -0.001503
0.0002426 0.3013 0.05762 0.01019 -0.0004476 6.79e-05 3.227e-05 0.3123 -0.03535 0.00484 3.025e-06 -4.363e-05
2.854e-07 -1.286e-06 -0.6725 -0.0373 0.0008964 0.0001399 -3.99e-06 7.431e-06 -2.796e-07 -1.601e-07 0.04068
-0.01352 0.0007282 9.594e-05 2.07e-06 -9.62e-08 -2.742e-07 -6.37e-08 -6.3e-09 0.08625 -0.005971 0.0004705
2.335e-05 4.226e-06 2.475e-07 -8.85e-08 -3.6e-08 -2.9e-09 0.0
0.0 0.0 -0.1136 0.0 -0.1868 -0.01399 0.0 -0.1043 0.01175 -0.00224 0.0 -0.03222 0.01333 -0.002647 -2.316e-05 0.0
0.05339 0.01107 -0.003116 -0.0001079 -1.299e-05 0.0 0.004861 0.008891 -0.0006448 -1.279e-05 6.358e-06 -1.417e-07
0.0 0.03041 0.00115 -0.0008743 -2.781e-05 6.367e-07 -1.14e-08 -4.2e-08 0.0 -0.02982 -0.003 1.394e-05 -3.29e-05
-1.705e-07 7.44e-08 2.72e-08 -6.6e-09 0.0 0.01236 -0.0009981 -3.792e-05 -1.355e-05 1.162e-06 -1.789e-07 1.47e-08
-2.4e-09 -4e-10
56.4 1.555 -1.011 -3.975 0.03171 0.1065 0.6175 0.1376 0.04229 0.003028 1.688 -0.1692 0.05478 0.02473 0.0006059
2.278 0.006614 -0.0003505 -0.006697 0.0008402 0.0007033 -3.236 0.2184 -0.04611 -0.01613 -0.001604 5.42e-05
7.922e-05 -0.2711 -0.4406 -0.03376 -0.002801 -0.000409 -2.056e-05 6.894e-06 2.317e-06 1.941 -0.2562 0.01598
0.005449 0.0003544 1.148e-05 7.503e-06 -5.667e-07 -3.66e-08 0.8683 -0.05931 -0.001864 -0.0001277 0.0002029
1.269e-05 1.629e-06 9.66e-08 -1.015e-07 -5e-10
0.0 0.0 0.2592 0.0 0.02974 -0.5471 0.0 -0.5926 -0.103 -0.01567 0.0 0.171 0.09025 0.02689 0.002243 0.0 0.3439
0.02402 0.00541 0.001601 9.669e-05 0.0 0.09502 -0.03063 -0.001055 -0.0001067 -0.000113 2.124e-05 0.0 -0.3129
0.008463 0.0002253 7.413e-05 -9.376e-05 -1.606e-06 2.06e-06 0.0 0.2739 0.001167 -2.246e-05 -0.0001287 -2.438e-05
-7.561e-07 1.158e-06 4.95e-08 0.0 -0.1344 0.005342 0.0003775 -6.756e-05 -1.686e-06 -1.184e-06 2.768e-07 2.73e-08
5.7e-09
0.1023 -2.695 0.3417 -0.1405 0.3175 0.2116 3.536 -0.1505 -0.0166 0.02967 0.3819 -0.1695 -0.07444 0.007409
-0.006262 -1.836 -0.01759 -0.06256 -0.002371 0.0007947 0.0001501 -0.8603 -0.136 -0.03629 -0.003706 -0.0002976
1.857e-05 3.021e-05 2.248 -0.1178 0.01255 0.001134 -0.0002161 -5.817e-06 8.836e-07 -1.769e-07 0.7313 -0.1188
0.01145 0.001011 0.0001083 2.57e-06 -2.14e-06 -5.71e-08 2e-08 -1.632 -0.006948 -0.003893 0.0008592 7.577e-05
4.539e-06 -3.852e-07 -2.213e-07 -1.37e-08 5.8e-09
0.0 0.0 -0.08865 0.0 -0.4309 0.0634 0.0 0.1162 0.06176 -0.004234 0.0 0.253 0.04017 -0.006204 0.004977 0.0 -0.1737
-0.005638 0.0001488 0.0004857 -0.0001809 0.0 -0.1514 -0.01685 0.005333 -7.611e-05 2.394e-05 8.195e-06 0.0 0.09326
-0.01275 -0.0003071 5.374e-05 -3.391e-05 -7.436e-06 6.747e-07 0.0 -0.08637 -0.003807 -0.0006833 -3.861e-05
-2.268e-05 1.454e-06 3.86e-07 -1.068e-07 0.0 -0.02658 -0.001947 0.0007131 -3.506e-05 1.885e-07 5.792e-07 3.99e-08
2e-08 -5.7e-09
""".split(), float).reshape(8, 55) * 1e-5
_GMF_N = np.repeat(np.arange(10), np.arange(1, 11))  # degree of each coefficient
_GMF_M = np.concatenate([np.arange(n + 1) for n in range(10)])  # order
#: MJD of [Niell 1996]'s reference day, 28 January 1980, for the annual term of GMF as of NMF.
_MJD_JAN28_1980 = 44239.0 - 1.0 + 28.0


def _legendre_9(t):
    """Unnormalised associated Legendre functions ``P_nm(t)``, n, m <= 9, no Condon-Shortley phase.

    Shape (..., 55) in the order of ``_GMF_N`` / ``_GMF_M`` (the convention of [Heiskanen 1967] eq. 1-62).
    """
    t = np.asarray(t, float)
    u = np.sqrt(np.clip(1.0 - t * t, 0.0, None))
    p = {}
    for m in range(10):
        p[m, m] = (np.prod(np.arange(1, 2 * m, 2)) if m else 1.0) * u**m  # (2m-1)!! u^m
        if m < 9:
            p[m + 1, m] = (2 * m + 1) * t * p[m, m]
        for n in range(m + 2, 10):
            p[n, m] = ((2 * n - 1) * t * p[n - 1, m] - (n + m - 1) * p[n - 2, m]) / (n - m)
    return np.stack([p[n, m] * np.ones_like(t) for n, m in zip(_GMF_N, _GMF_M)], axis=-1)


def gmf_mapping(elev_rad, lat_rad, lon_rad, height_m, mjd):
    """Hydrostatic and wet Global Mapping Functions of [Boehm 2006].

    The continued fraction of [Marini 1972] with ``b, c`` as [Boehm 2006]
    (hydrostatic ``b = 0.0029``, ``c`` from latitude and season; wet ``b =
    0.00146, c = 0.04391``) and ``a`` from spherical harmonics of degree 9
    fit to three years of ECMWF ray traces (mean plus annual cosine, phase
    at 28 January as in [Niell 1996]); the hydrostatic height correction is
    Niell's. Where NMF's ``a`` depends on latitude only, GMF's also follows
    longitude (oceans, continents), which is the point of it for a coastal
    station.

    Parameters
    ----------
    elev_rad, lat_rad, lon_rad, height_m, mjd : array_like, broadcastable
        Elevation, geodetic latitude, longitude, height (above sea level;
        the ellipsoidal height changes the result by 1e-6 per 100 m at 10
        deg), modified Julian date (UTC, fractional).

    Returns
    -------
    m_dry, m_wet : ndarray
        Both 1 at zenith.
    """
    # The coefficients depend on the site and day only: evaluated on their broadcast shape, not the elevations'.
    lat_rad, lon_rad, mjd = np.broadcast_arrays(*(np.asarray(v, float) for v in (lat_rad, lon_rad, mjd)))
    p = _legendre_9(np.sin(lat_rad))
    cos_m, sin_m = np.cos(_GMF_M * lon_rad[..., None]), np.sin(_GMF_M * lon_rad[..., None])
    ah_mean, ah_amp, aw_mean, aw_amp = (np.sum(p * (_GMF_COEF[k] * cos_m + _GMF_COEF[k + 1] * sin_m), axis=-1)
                                        for k in (0, 2, 4, 6))
    season = np.cos(2.0 * np.pi * (mjd - _MJD_JAN28_1980) / 365.25)
    south = lat_rad < 0
    c11, c10 = np.where(south, 0.007, 0.005), np.where(south, 0.002, 0.001)
    c_h = 0.062 + ((np.cos(2.0 * np.pi * (mjd - _MJD_JAN28_1980) / 365.25 + np.where(south, np.pi, 0.0)) + 1.0)
                   * c11 / 2.0 + c10) * (1.0 - np.cos(lat_rad))
    s = np.sin(np.asarray(elev_rad, float))
    m_dry = (_marini(s, ah_mean + ah_amp * season, 0.0029, c_h)
             + (1.0 / s - _marini(s, *_NMF_HT)) * np.asarray(height_m, float) * 1e-3)
    m_wet = _marini(s, aw_mean + aw_amp * season, 0.00146, 0.04391)
    return m_dry, m_wet


#: [Chen 1997]'s gradient mapping constant for the total delay (0.0031 hydrostatic, 0.0007 wet alone).
CHEN_HERRING_C = 0.0032


def gradient_mapping(elev_rad, az_rad):
    """Partials of the slant delay on the north and east troposphere gradients, [Chen 1997].

    The slant delay's asymmetric part is ``m_g(e) (G_N cos a + G_E sin a)``
    with ``m_g(e) = 1 / (sin e tan e + C)``, ``C = 0.0032``: for a
    refractivity varying linearly across the horizon, ``G`` is the
    height-weighted integral of its horizontal gradient (metres; about a
    millimetre at mid-latitudes), ``1 / (sin e tan e)`` is the flat-Earth
    geometry and ``C`` the Earth's curvature, which keeps it finite at the
    horizon (about 29 at 10 deg, 0 at the zenith).

    Parameters
    ----------
    elev_rad, az_rad : array_like, broadcastable
        Elevation and azimuth (clockwise from north).

    Returns
    -------
    ndarray, shape (..., 2)
        ``d slant / d (G_N, G_E)`` (dimensionless).
    """
    elev_rad, az_rad = np.broadcast_arrays(np.asarray(elev_rad, float), np.asarray(az_rad, float))
    m_g = 1.0 / (np.sin(elev_rad) * np.tan(elev_rad) + CHEN_HERRING_C)
    return np.stack([m_g * np.cos(az_rad), m_g * np.sin(az_rad)], axis=-1)


def _rot_ecl_to_eq(lon_rad, lat_rad, r_m, eps_rad):
    cb = np.cos(lat_rad)
    x, y, z = r_m * cb * np.cos(lon_rad), r_m * cb * np.sin(lon_rad), r_m * np.sin(lat_rad)
    ce, se = np.cos(eps_rad), np.sin(eps_rad)
    return np.stack([x, ce * y - se * z, se * y + ce * z], axis=-1)


def sun_moon_ecef_m(jd_tt):
    """Sun and Moon positions, low precision ([Montenbruck 2000], eq. 3.38-3.48).

    Parameters
    ----------
    jd_tt : array_like, shape (n,)
        Julian dates (TT). Earth rotation uses GMST with UT1 ~ TT - 69 s.

    Returns
    -------
    sun_ecef_m, moon_ecef_m : ndarray, shape (n, 3)
    """
    jd_tt = np.atleast_1d(np.asarray(jd_tt, float))
    T = (jd_tt - JD_J2000) / 36525.0
    eps = np.radians(23.43929111)
    M = np.radians(357.5256 + 35999.049 * T)
    lam = np.radians(282.9400 + 1.3972 * T) + M + (6892.0 * np.sin(M) + 72.0 * np.sin(2 * M)) * _ARCSEC
    r_sun = (149.619 - 2.499 * np.cos(M) - 0.021 * np.cos(2 * M)) * 1e9
    sun = _rot_ecl_to_eq(lam, 0.0 * lam, r_sun, eps)
    d = np.radians
    L0 = d(218.31617 + 481267.88088 * T - 1.3972 * T)
    lm = d(134.96292 + 477198.86753 * T)  # Montenbruck's l (Moon's mean anomaly); lp is his l' (the Sun's)
    lp = d(357.52543 + 35999.04944 * T)
    F = d(93.27283 + 483202.01873 * T)
    D = d(297.85027 + 445267.11135 * T)
    dlam = (22640 * np.sin(lm) + 769 * np.sin(2 * lm) - 4586 * np.sin(lm - 2 * D) + 2370 * np.sin(2 * D)
            - 668 * np.sin(lp) - 412 * np.sin(2 * F) - 212 * np.sin(2 * lm - 2 * D) - 206 * np.sin(lm + lp - 2 * D)
            + 192 * np.sin(lm + 2 * D) - 165 * np.sin(lp - 2 * D) + 148 * np.sin(lm - lp) - 125 * np.sin(D)
            - 110 * np.sin(lm + lp) - 55 * np.sin(2 * F - 2 * D)) * _ARCSEC
    lam_m = L0 + dlam
    beta = (18520 * np.sin(F + lam_m - L0 + (412 * np.sin(2 * F) + 541 * np.sin(lp)) * _ARCSEC)
            - 526 * np.sin(F - 2 * D) + 44 * np.sin(lm + F - 2 * D) - 31 * np.sin(-lm + F - 2 * D)
            - 25 * np.sin(-2 * lm + F) - 23 * np.sin(lp + F - 2 * D) + 21 * np.sin(-lm + F)
            + 11 * np.sin(-lp + F - 2 * D)) * _ARCSEC
    r_moon = (385000 - 20905 * np.cos(lm) - 3699 * np.cos(2 * D - lm) - 2956 * np.cos(2 * D)
              - 570 * np.cos(2 * lm) + 246 * np.cos(2 * lm - 2 * D) - 205 * np.cos(lp - 2 * D)
              - 171 * np.cos(lm + 2 * D) - 152 * np.cos(lm + lp - 2 * D)) * 1e3
    moon = _rot_ecl_to_eq(lam_m, beta, r_moon, eps)
    jd_ut1 = jd_tt - 69.184 / DAY_S
    theta = gmst1982(np.floor(jd_ut1), jd_ut1 - np.floor(jd_ut1))[0]
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]

    def to_ecef(v):
        return np.stack([c[:, 0] * v[:, 0] + s[:, 0] * v[:, 1], -s[:, 0] * v[:, 0] + c[:, 0] * v[:, 1], v[:, 2]],
                        axis=-1)

    return to_ecef(sun), to_ecef(moon)


def solid_tide_ecef_m(pos_ecef_m, sun_ecef_m, moon_ecef_m):
    """Solid Earth tide displacement, degree 2 ([IERS 2010] eq. 7.5, step 1).

    Love numbers ``h2 = 0.6078 - 0.0006 P2(sin lat)``, ``l2 = 0.0847 + 0.0002
    P2(sin lat)``; the result is the conventional tide-free displacement
    (permanent tide included, as for ITRF coordinates). Radial amplitude up
    to about 0.4 m.

    Parameters
    ----------
    pos_ecef_m : array_like, shape (3,) or (n, 3)
        Station.
    sun_ecef_m, moon_ecef_m : array_like, shape (n, 3)

    Returns
    -------
    ndarray, shape (n, 3)
    """
    r = np.asarray(pos_ecef_m, float)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    u = r / rn
    p2_lat = 1.5 * u[..., 2:3] ** 2 - 0.5  # P2(sin lat) with geocentric latitude
    h2 = 0.6078 - 0.0006 * p2_lat
    l2 = 0.0847 + 0.0002 * p2_lat
    out = 0.0
    for body, gm in ((np.asarray(sun_ecef_m), GM_SUN_OVER_EARTH), (np.asarray(moon_ecef_m), GM_MOON_OVER_EARTH)):
        R = np.linalg.norm(body, axis=-1, keepdims=True)
        e = body / R
        d = np.sum(e * u, axis=-1, keepdims=True)
        k = gm * WGS84_A_M**4 / R**3
        out = out + k * (h2 * u * (1.5 * d**2 - 0.5) + 3.0 * l2 * d * (e - d * u))
    return out


def satellite_axes(pos_sv_ecef_m, sun_ecef_m):
    """Body axes of satellites in nominal yaw attitude (eclipse manoeuvres not modelled).

    z to the Earth's centre, y = z x (Sun - satellite) normalised, x = y x z.

    Parameters
    ----------
    pos_sv_ecef_m : ndarray, shape (n_epochs, n_sats, 3)
    sun_ecef_m : ndarray, shape (n_epochs, 3)

    Returns
    -------
    x, y, z : ndarray, shape (n_epochs, n_sats, 3)
        Unit vectors in ECEF.
    """
    rs = np.asarray(pos_sv_ecef_m, float)
    z = -rs / np.linalg.norm(rs, axis=-1, keepdims=True)
    y = np.cross(z, sun_ecef_m[:, None, :] - rs)
    y /= np.linalg.norm(y, axis=-1, keepdims=True)
    return np.cross(y, z), y, z


def windup_cycles(pos_sv_ecef_m, pos_rx_ecef_m, sun_ecef_m, lat_rad, lon_rad):
    """Carrier phase wind-up [Wu 1993], satellites in nominal yaw attitude.

    Satellite body frame: z to the Earth's centre, y = z x (Sun - satellite),
    x = y x z; receiver antenna dipoles East, North (boresight Up). Eclipse
    yaw manoeuvres are not modelled.

    Parameters
    ----------
    pos_sv_ecef_m : ndarray, shape (n_epochs, n_sats, 3)
    pos_rx_ecef_m : ndarray, shape (3,)
    sun_ecef_m : ndarray, shape (n_epochs, 3)
    lat_rad, lon_rad : float
        Receiver.

    Returns
    -------
    ndarray, shape (n_epochs, n_sats)
        Wind-up in cycles, continuous in time per satellite (NaN where the
        satellite position is NaN); subtract ``lambda * windup`` from phase.
    """
    rs = np.asarray(pos_sv_ecef_m, float)
    x, y, _ = satellite_axes(rs, sun_ecef_m)
    k = np.asarray(pos_rx_ecef_m) - rs
    k /= np.linalg.norm(k, axis=-1, keepdims=True)
    sl, cl, so, co = np.sin(lat_rad), np.cos(lat_rad), np.sin(lon_rad), np.cos(lon_rad)
    xr = np.array([-so, co, 0.0])            # East
    yr = np.array([-sl * co, -sl * so, cl])  # North

    def dot(a, b):
        return np.sum(a * b, axis=-1, keepdims=True)

    Ds = x - k * dot(k, x) - np.cross(k, y)
    Dr = xr - k * dot(k, xr) + np.cross(k, np.broadcast_to(yr, k.shape))
    cosang = dot(Ds, Dr)[..., 0] / (np.linalg.norm(Ds, axis=-1) * np.linalg.norm(Dr, axis=-1))
    ang = np.arccos(np.clip(cosang, -1.0, 1.0)) / (2 * np.pi)
    sgn = np.sign(dot(k, np.cross(Ds, Dr))[..., 0])
    w = np.where(sgn < 0, -ang, ang)
    # Continuous in time: add the integer that keeps each step within half a cycle.
    out = np.full_like(w, np.nan)
    for j in range(w.shape[1]):
        ok = np.isfinite(w[:, j])
        if ok.any():
            out[ok, j] = np.unwrap(w[ok, j], period=1.0)
    return out


def relativistic_clock_s(pos_sv_ecef_m, vel_sv_ecef_mps):
    """Periodic relativistic satellite clock term ``-2 r.v / c^2`` [s] (IS-GPS-200 20.3.3.3.3.1).

    Added to the precise clock (which excludes it) to get the satellite
    clock offset. Shapes (..., 3) -> (...).
    """
    return -2.0 * np.sum(np.asarray(pos_sv_ecef_m) * np.asarray(vel_sv_ecef_mps), axis=-1) / C_MPS**2


def shapiro_m(pos_sv_ecef_m, pos_rx_ecef_m):
    """Relativistic path delay ``2 GM / c^2 ln((rs + rr + rho) / (rs + rr - rho))`` [m] (IS-GPS-200)."""
    rs = np.linalg.norm(pos_sv_ecef_m, axis=-1)
    rr = np.linalg.norm(pos_rx_ecef_m, axis=-1)
    rho = np.linalg.norm(np.asarray(pos_sv_ecef_m) - np.asarray(pos_rx_ecef_m), axis=-1)
    return 2.0 * GM_M3_PER_S2 / C_MPS**2 * np.log((rs + rr + rho) / (rs + rr - rho))
