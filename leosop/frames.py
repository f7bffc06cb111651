"""Reference frames: WGS84 geodetic, ECEF, local ENU/NED, TEME, Earth rotation.

Every function is vectorised over any leading shape; vectors keep their
three components in the last axis. Angles are radians. Rotation matrices are
named ``C_to_from``: ``C_n_e @ v_e`` is ``v_n``. The navigation frame ``n``
is East-North-Up (see :mod:`leosop`).
"""

import numpy as np
import numpy.typing as npt

from .constants import DAY_S, OMEGA_E_RAD_PER_S, WGS84_A_M, WGS84_B_M, WGS84_E2
from .shapes import as_vec3, stack_last

__all__ = [
    "geodetic_to_ecef",
    "ecef_to_geodetic",
    "C_e_n",
    "ecef_to_enu",
    "enu_to_ecef",
    "enu_to_ned",
    "ned_to_enu",
    "azimuth_elevation_range",
    "range_rate",
    "rotate_to_later_ecef",
    "gmst1982",
    "teme_to_ecef",
]


def geodetic_to_ecef(lat_rad: npt.ArrayLike, lon_rad: npt.ArrayLike, alt_m: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """WGS84 geodetic coordinates to ECEF position.

    Parameters
    ----------
    lat_rad, lon_rad, alt_m : array_like, broadcastable
        Geodetic latitude and longitude [rad], height above the ellipsoid [m].

    Returns
    -------
    pos_ecef_m : ndarray, shape (..., 3)
    """
    lat, lon, alt = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (lat_rad, lon_rad, alt_m)))
    sin_lat = np.sin(lat)
    n_m = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    r_xy = (n_m + alt) * np.cos(lat)
    return stack_last([r_xy * np.cos(lon), r_xy * np.sin(lon), (n_m * (1.0 - WGS84_E2) + alt) * sin_lat])


def ecef_to_geodetic(pos_ecef_m: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                                                          npt.NDArray[np.float64]]:
    """ECEF position to WGS84 geodetic coordinates.

    Bowring's parametric-latitude iteration; three passes give better than
    1e-9 m from the Earth's centre region to beyond GEO.

    Parameters
    ----------
    pos_ecef_m : array_like, shape (..., 3)

    Returns
    -------
    lat_rad, lon_rad, alt_m : ndarray, shape (...)
    """
    pos = as_vec3(pos_ecef_m, "pos_ecef_m")
    x, y, z = pos[..., 0], pos[..., 1], pos[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    ep2 = (WGS84_A_M**2 - WGS84_B_M**2) / WGS84_B_M**2
    beta = np.arctan2(z * WGS84_A_M, p * WGS84_B_M)
    for _ in range(3):
        lat = np.arctan2(z + ep2 * WGS84_B_M * np.sin(beta) ** 3, p - WGS84_E2 * WGS84_A_M * np.cos(beta) ** 3)
        beta = np.arctan2(WGS84_B_M * np.sin(lat), WGS84_A_M * np.cos(lat))
    sin_lat = np.sin(lat)
    n_m = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    # Height from the projection that is well conditioned at every latitude.
    alt = p * np.cos(lat) + z * sin_lat - WGS84_A_M**2 / n_m
    return lat, lon, alt


def C_e_n(lat_rad: npt.ArrayLike, lon_rad: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotation from the local ENU frame to ECEF.

    Parameters
    ----------
    lat_rad, lon_rad : array_like, broadcastable, shape (...)

    Returns
    -------
    C_e_n : ndarray, shape (..., 3, 3)
        Columns are the East, North and Up unit vectors in ECEF.
    """
    lat, lon = np.broadcast_arrays(np.asarray(lat_rad, dtype=float), np.asarray(lon_rad, dtype=float))
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    zero = np.zeros_like(lat)
    # Columns East, North, Up.
    return stack_last([[-so, -sl * co, cl * co], [co, -sl * so, cl * so], [zero, cl, sl]], 2)


def ecef_to_enu(vec_ecef: npt.ArrayLike, lat_rad: npt.ArrayLike, lon_rad: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotate ECEF vectors (differences, velocities) into ENU at (lat, lon).

    Parameters
    ----------
    vec_ecef : array_like, shape (..., 3)
    lat_rad, lon_rad : array_like, broadcastable against ``vec_ecef[..., 0]``

    Returns
    -------
    vec_enu : ndarray, shape (..., 3)
    """
    v = as_vec3(vec_ecef, "vec_ecef")
    return np.einsum("...ji,...j->...i", C_e_n(lat_rad, lon_rad), v)


def enu_to_ecef(vec_enu: npt.ArrayLike, lat_rad: npt.ArrayLike, lon_rad: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotate ENU vectors at (lat, lon) into ECEF; inverse of :func:`ecef_to_enu`."""
    v = as_vec3(vec_enu, "vec_enu")
    return np.einsum("...ij,...j->...i", C_e_n(lat_rad, lon_rad), v)


def enu_to_ned(vec_enu: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """ENU components to NED components, shape (..., 3)."""
    v = as_vec3(vec_enu, "vec_enu")
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def ned_to_enu(vec_ned: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """NED components to ENU components, shape (..., 3)."""
    v = as_vec3(vec_ned, "vec_ned")
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def azimuth_elevation_range(pos_sv_ecef_m: npt.ArrayLike, pos_rx_ecef_m: npt.ArrayLike
                            ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Azimuth, elevation and range of satellites seen from a receiver.

    Parameters
    ----------
    pos_sv_ecef_m : array_like, shape (..., 3)
        Satellite positions, e.g. ``(n_sats, n_epochs, 3)``.
    pos_rx_ecef_m : array_like, shape (..., 3)
        Receiver positions broadcastable against the satellites, e.g.
        ``(3,)`` for a site or ``(n_epochs, 3)`` for a trajectory.

    Returns
    -------
    az_rad : ndarray
        Azimuth clockwise from true north in [0, 2 pi).
    elev_rad : ndarray
        Elevation above the ellipsoid's tangent plane.
    range_m : ndarray
    """
    sv = as_vec3(pos_sv_ecef_m, "pos_sv_ecef_m")
    rx = as_vec3(pos_rx_ecef_m, "pos_rx_ecef_m")
    lat, lon, _ = ecef_to_geodetic(rx)
    los_enu = ecef_to_enu(sv - rx, lat, lon)
    range_m = np.linalg.norm(los_enu, axis=-1)
    az = np.mod(np.arctan2(los_enu[..., 0], los_enu[..., 1]), 2.0 * np.pi)
    elev = np.arcsin(np.clip(los_enu[..., 2] / range_m, -1.0, 1.0))
    return az, elev, range_m


def range_rate(pos_sv_ecef_m: npt.ArrayLike, vel_sv_ecef_mps: npt.ArrayLike, pos_rx_ecef_m: npt.ArrayLike,
               vel_rx_ecef_mps: npt.ArrayLike = 0.0) -> npt.NDArray[np.float64]:
    """Rate of change of the satellite-receiver range [m/s].

    Positive when the range grows (satellite receding). The Doppler of a
    carrier ``f0`` is ``-range_rate * f0 / c`` to first order.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, shape (..., 3)
    pos_rx_ecef_m, vel_rx_ecef_mps : array_like, broadcastable, shape (..., 3)

    Returns
    -------
    range_rate_mps : ndarray, shape (...)
    """
    los = as_vec3(pos_sv_ecef_m, "pos_sv_ecef_m") - as_vec3(pos_rx_ecef_m, "pos_rx_ecef_m")
    dv = as_vec3(vel_sv_ecef_mps, "vel_sv_ecef_mps") - np.asarray(vel_rx_ecef_mps, dtype=float)
    return np.sum(los * dv, axis=-1) / np.linalg.norm(los, axis=-1)


def rotate_to_later_ecef(vec_ecef: npt.ArrayLike, dt_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Express ECEF vectors in the ECEF frame ``dt_s`` later.

    The Earth turns by ``theta = OMEGA_E * dt_s`` about z in ``dt_s``, so a
    vector fixed in inertial space has components ``R3(theta) @ vec`` in the
    later frame, with ``R3(theta) = [[cos, sin, 0], [-sin, cos, 0], [0, 0, 1]]``.
    With ``dt_s`` the signal's flight time this is the Sagnac (Earth-rotation)
    correction: the satellite state at transmission in the frame of reception.

    Parameters
    ----------
    vec_ecef : array_like, shape (..., 3)
        Positions [m] or velocities [m/s] in the earlier ECEF frame.
    dt_s : array_like, shape (...), broadcastable
        Time from the earlier frame to the later one [s]; negative goes back.

    Returns
    -------
    vec_ecef : ndarray, shape (..., 3)
        The same vectors in the later ECEF frame.
    """
    v = np.asarray(vec_ecef, dtype=float)
    theta = OMEGA_E_RAD_PER_S * np.asarray(dt_s, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], v[..., 2]], axis=-1)


def gmst1982(jd_ut1: npt.ArrayLike, fr_ut1: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Greenwich mean sidereal angle of the IAU 1982 model and its rate.

    This is the angle that defines the TEME frame of SGP4 (Vallado et al.,
    "Revisiting Spacetrack Report #3", 2006).

    Parameters
    ----------
    jd_ut1, fr_ut1 : array_like
        UT1 Julian date split into a whole part and a day fraction.

    Returns
    -------
    theta_rad : ndarray
        In [0, 2 pi).
    theta_dot_rad_per_s : ndarray
    """
    jd = np.asarray(jd_ut1, dtype=float)
    fr = np.asarray(fr_ut1, dtype=float)
    days = (jd - 2_451_545.0) + fr
    t = days / 36_525.0
    # Whole days contribute whole turns: keep only the fraction for precision.
    day_frac = np.mod(np.mod(jd - 2_451_545.0, 1.0) + fr, 1.0)
    gmst_s = 67_310.54841 + DAY_S * day_frac + (8_640_184.812866 + (0.093104 - 6.2e-6 * t) * t) * t
    theta = np.mod(gmst_s / DAY_S, 1.0) * 2.0 * np.pi
    rate_s_per_s = 1.0 + (8_640_184.812866 + (2 * 0.093104 - 3 * 6.2e-6 * t) * t) / (36_525.0 * DAY_S)
    return theta, rate_s_per_s * 2.0 * np.pi / DAY_S


def teme_to_ecef(pos_teme_m: npt.ArrayLike, vel_teme_mps: npt.ArrayLike, jd_ut1: npt.ArrayLike,
                 fr_ut1: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """TEME position and velocity to ECEF (ITRF without polar motion).

    The velocity includes the Earth-rotation term ``-omega x r``, which is
    worth hundreds of m/s and therefore kHz of Doppler at Ku band. Polar
    motion (at most ~15 m at LEO radius) is neglected, as in skyfield when no
    IERS polar-motion table is installed.

    Parameters
    ----------
    pos_teme_m, vel_teme_mps : array_like, shape (..., n_epochs, 3)
    jd_ut1, fr_ut1 : array_like, shape (n_epochs,)

    Returns
    -------
    pos_ecef_m, vel_ecef_mps : ndarray, shape (..., n_epochs, 3)
    """
    r = as_vec3(pos_teme_m, "pos_teme_m")
    v = as_vec3(vel_teme_mps, "vel_teme_mps")
    theta, theta_dot = gmst1982(jd_ut1, fr_ut1)
    c, s = np.cos(theta), np.sin(theta)
    x = c * r[..., 0] + s * r[..., 1]
    y = -s * r[..., 0] + c * r[..., 1]
    vx = c * v[..., 0] + s * v[..., 1] + theta_dot * y
    vy = -s * v[..., 0] + c * v[..., 1] - theta_dot * x
    pos = np.stack([x, y, r[..., 2]], axis=-1)
    vel = np.stack([vx, vy, v[..., 2]], axis=-1)
    return pos, vel
