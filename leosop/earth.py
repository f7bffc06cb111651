"""WGS84 Earth model for inertial navigation in the local ENU frame.

Normal gravity with height, the meridian and prime-vertical radii of
curvature, the Earth rate and the transport rate, all in the navigation
frame ``n`` = East-North-Up (see :mod:`leosop`). Functions are vectorised
over leading axes; :func:`local_terms` is the same physics for one epoch in
plain floats, for the sequential strapdown loop where numpy's per-call cost
would dominate.

Gravity is the magnitude of WGS84 normal gravity (NIMA TR8350.2 eq. 4-1 and
the second-order height expansion eq. 4-3) pointing down the ellipsoid
normal; its north component above the ellipsoid (below 1e-6 g at aircraft
heights) is neglected, as is usual in navigation mechanizations.
"""

import math

import numpy as np

from .constants import (
    GAMMA_E_MPS2,
    OMEGA_E_RAD_PER_S,
    SOMIGLIANA_K,
    WGS84_A_M,
    WGS84_E2,
    WGS84_F,
    WGS84_M,
)
from .shapes import as_vec3, stack_last

__all__ = [
    "normal_gravity_mps2",
    "gravity_enu_mps2",
    "radii_m",
    "earth_rate_enu",
    "transport_rate_enu",
    "local_terms",
]


def normal_gravity_mps2(lat_rad, alt_m):
    """Magnitude of WGS84 normal gravity [m/s^2] at geodetic latitude and height.

    Somigliana's closed form on the ellipsoid with the second-order free-air
    expansion in height (TR8350.2 eq. 4-3), good to ~1e-6 m/s^2 up to 20 km.

    Parameters
    ----------
    lat_rad, alt_m : array_like, broadcastable

    Returns
    -------
    gamma_mps2 : ndarray
    """
    s2 = np.sin(np.asarray(lat_rad, dtype=float)) ** 2
    h = np.asarray(alt_m, dtype=float)
    gamma0 = GAMMA_E_MPS2 * (1.0 + SOMIGLIANA_K * s2) / np.sqrt(1.0 - WGS84_E2 * s2)
    return gamma0 * (1.0 - 2.0 / WGS84_A_M * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2) * h
                     + 3.0 * h**2 / WGS84_A_M**2)


def gravity_enu_mps2(lat_rad, alt_m):
    """Normal gravity vector ``[0, 0, -gamma]`` in ENU, shape (..., 3)."""
    gamma = normal_gravity_mps2(lat_rad, alt_m)
    z = np.zeros_like(gamma)
    return np.stack([z, z, -gamma], axis=-1)


def radii_m(lat_rad):
    """Meridian and prime-vertical radii of curvature of the WGS84 ellipsoid.

    Returns
    -------
    R_M, R_N : ndarray
        ``R_M = a (1 - e^2) / (1 - e^2 sin^2 L)^1.5``, ``R_N = a / sqrt(1 - e^2 sin^2 L)`` [m].
    """
    w2 = 1.0 - WGS84_E2 * np.sin(np.asarray(lat_rad, dtype=float)) ** 2
    R_N = WGS84_A_M / np.sqrt(w2)
    return R_N * (1.0 - WGS84_E2) / w2, R_N


def earth_rate_enu(lat_rad):
    """Earth rotation rate in ENU, ``[0, Omega cos L, Omega sin L]`` [rad/s], shape (..., 3)."""
    lat = np.asarray(lat_rad, dtype=float)
    return stack_last([np.zeros_like(lat), OMEGA_E_RAD_PER_S * np.cos(lat), OMEGA_E_RAD_PER_S * np.sin(lat)])


def transport_rate_enu(lat_rad, alt_m, vel_enu_mps):
    """Rate of the ENU frame relative to the Earth, ``omega_en^n`` [rad/s].

    ``[-v_N / (R_M + h), v_E / (R_N + h), v_E tan L / (R_N + h)]``.

    Parameters
    ----------
    lat_rad, alt_m : array_like, shape (...)
    vel_enu_mps : array_like, shape (..., 3)

    Returns
    -------
    omega_en_enu_rad_per_s : ndarray, shape (..., 3)
    """
    vel = as_vec3(vel_enu_mps, "vel_enu_mps")
    lat = np.asarray(lat_rad, dtype=float)
    R_M, R_N = radii_m(lat)
    h = np.asarray(alt_m, dtype=float)
    ve_rn = vel[..., 0] / (R_N + h)
    return stack_last([-vel[..., 1] / (R_M + h), ve_rn, ve_rn * np.tan(lat)])


_K1 = 2.0 / WGS84_A_M * (1.0 + WGS84_F + WGS84_M)
_K2 = 4.0 * WGS84_F / WGS84_A_M
_K3 = 3.0 / WGS84_A_M**2


def local_terms(lat_rad, alt_m, ve_mps, vn_mps):
    """Earth terms at one epoch in plain floats (the strapdown's inner loop).

    Same formulas as the vectorised functions of this module.

    Parameters
    ----------
    lat_rad, alt_m, ve_mps, vn_mps : float

    Returns
    -------
    tuple of float
        ``(rm_h, rn_h, cos_lat, gamma, wie_n, wie_u, wen_e, wen_n, wen_u)``:
        ``R_M + h``, ``R_N + h`` [m], cos L, normal gravity [m/s^2], the North
        and Up Earth rate and the ENU transport rate [rad/s].
    """
    s = math.sin(lat_rad)
    c = math.cos(lat_rad)
    s2 = s * s
    w2 = 1.0 - WGS84_E2 * s2
    sw = math.sqrt(w2)
    rn = WGS84_A_M / sw
    rm_h = rn * (1.0 - WGS84_E2) / w2 + alt_m
    rn_h = rn + alt_m
    gamma = GAMMA_E_MPS2 * (1.0 + SOMIGLIANA_K * s2) / sw * (1.0 - (_K1 - _K2 * s2) * alt_m + _K3 * alt_m * alt_m)
    wen_n = ve_mps / rn_h
    return (rm_h, rn_h, c, gamma, OMEGA_E_RAD_PER_S * c, OMEGA_E_RAD_PER_S * s,
            -vn_mps / rm_h, wen_n, wen_n * s / c)
