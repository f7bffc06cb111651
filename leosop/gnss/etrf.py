"""ITRF2014 <-> ETRF2000 (ETRS89) station coordinates at an epoch.

European stations publish their coordinates in ETRS89, realised as
ETRF2000, a frame attached to the stable part of the Eurasian plate; the
IGS / MGEX precise orbits and clocks (and so a PPP solution) are in
ITRF2014 (IGS14 / IGb14). The two drift apart by the plate motion, about
2.5 cm/yr to the north-east: 0.76 m in Denmark in 2020. The 14-parameter
similarity of [Altamimi 2018] (EUREF Technical Note 1, ITRF2014 -> ETRF2000,
reference epoch 2010.0; the same numbers are EPSG transformation 8405) is applied here to first order in the
small rotations (the second-order terms are below 1e-13 of the coordinate).

The ESBC00DNK RINEX header position (written by the station's agency, SDFE)
is the ETRF2000 coordinate of the marker: the GPS+Galileo 24 h float PPP of
``leosop.gnss.ppp``, mapped to ETRF2000 by :func:`itrf2014_to_etrf2000`,
lands within 1 cm of it.
"""

import numpy as np

from ..constants import DAY_S

__all__ = ["itrf2014_to_etrf2000", "etrf2000_to_itrf2014", "decimal_year"]

_MAS_RAD = np.pi / (180.0 * 3600.0e3)
#: [Altamimi 2018] table 5: translations [mm], scale [ppb], rotations [mas] at 2010.0 and their rates per year.
_T_MM, _T_RATE = np.array([54.7, 52.2, -74.1]), np.array([0.1, 0.1, -1.9])
_D_PPB, _D_RATE = 2.12, 0.11
_R_MAS, _R_RATE = np.array([1.701, 10.290, -16.632]), np.array([0.081, 0.490, -0.792])
_EPOCH0_YR = 2010.0


def decimal_year(time_gps):
    """``datetime64`` -> decimal year (days / days in that year), shape kept."""
    t = np.asarray(time_gps, "datetime64[s]")
    y0 = t.astype("datetime64[Y]")
    days = (t - y0.astype("datetime64[s]")).astype(float) / DAY_S
    n_days = ((y0 + 1).astype("datetime64[D]") - y0.astype("datetime64[D]")).astype(float)
    return y0.astype(int) + 1970 + days / n_days


def _delta(pos_ecef_m, epoch_yr):
    dt = np.asarray(epoch_yr, float) - _EPOCH0_YR
    T = (_T_MM + _T_RATE * dt[..., None]) * 1e-3
    D = (_D_PPB + _D_RATE * dt)[..., None] * 1e-9
    r1, r2, r3 = np.moveaxis((_R_MAS + _R_RATE * dt[..., None]) * _MAS_RAD, -1, 0)
    x, y, z = np.moveaxis(pos_ecef_m, -1, 0)
    rot = np.stack([-r3 * y + r2 * z, r3 * x - r1 * z, -r2 * x + r1 * y], axis=-1)
    return T + D * pos_ecef_m + rot


def itrf2014_to_etrf2000(pos_ecef_m, epoch_yr):
    """ITRF2014 coordinates at ``epoch_yr`` -> ETRF2000 at the same epoch.

    Parameters
    ----------
    pos_ecef_m : array_like, shape (..., 3)
    epoch_yr : float or array_like, shape (...)
        Decimal year of the coordinates (:func:`decimal_year`).

    Returns
    -------
    ndarray, shape (..., 3)
    """
    p = np.asarray(pos_ecef_m, float)
    return p + _delta(p, epoch_yr)


def etrf2000_to_itrf2014(pos_ecef_m, epoch_yr):
    """Inverse of :func:`itrf2014_to_etrf2000` (two fixed-point steps, exact to 1e-12 m)."""
    p = np.asarray(pos_ecef_m, float)
    q = p - _delta(p, epoch_yr)
    return p - _delta(q, epoch_yr)
