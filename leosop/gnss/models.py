"""GNSS measurement models for PPP: tides, wind-up, relativity, Sagnac; the troposphere's from :mod:`.troposphere`.

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
from .troposphere import (gmf_mapping, gpt_pressure_hpa, gradient_mapping, mjd, niell_mapping, saastamoinen_zhd_m,
                          slant_hydrostatic_and_wet)

__all__ = [
    "TT_MINUS_GPST_S",
    "gmf_mapping",
    "gpt_pressure_hpa",
    "gradient_mapping",
    "mjd",
    "niell_mapping",
    "relativistic_clock_s",
    "saastamoinen_zhd_m",
    "satellite_axes",
    "shapiro_m",
    "slant_hydrostatic_and_wet",
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
