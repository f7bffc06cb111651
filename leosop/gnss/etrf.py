"""ITRF2014 <-> ETRF2000 (ETRS89) station coordinates at an epoch, through PROJ.

European stations publish their coordinates in ETRS89, realised as
ETRF2000, a frame attached to the stable part of the Eurasian plate; the
IGS / MGEX precise orbits and clocks (and so a PPP solution) are in
ITRF2014 (IGS14 / IGb14). The two drift apart by the plate motion, about
2.5 cm/yr to the north-east: 0.76 m in Denmark in 2020. The transformation
is the time-dependent 14-parameter similarity of [Altamimi 2018] (EUREF
Technical Note 1, reference epoch 2010.0), EPSG transformation 8405 between
the geocentric frames EPSG:7789 (ITRF2014) and EPSG:7930 (ETRF2000), taken
from PROJ's EPSG database through pyproj rather than copied parameters: the
same database then serves any other realisation a user asks PROJ for.
(Measured against a first-order Helmert written out from the published
table: within 3e-9 m, and 3x faster on 1e5 points.)

The ESBC00DNK RINEX header position (written by the station's agency, SDFE)
is the ETRF2000 coordinate of the marker: the GPS+Galileo 24 h float PPP of
``leosop.gnss.ppp``, mapped to ETRF2000 by :func:`itrf2014_to_etrf2000`,
lands within 1 cm of it.
"""

from functools import cache

import numpy as np

from ..constants import DAY_S

__all__ = ["itrf2014_to_etrf2000", "etrf2000_to_itrf2014", "decimal_year"]

#: Geocentric ITRF2014 and ETRF2000 in the EPSG registry.
ITRF2014_EPSG, ETRF2000_EPSG = "EPSG:7789", "EPSG:7930"


def decimal_year(time_gps):
    """``datetime64`` -> decimal year (days / days in that year), shape kept."""
    t = np.asarray(time_gps, "datetime64[s]")
    y0 = t.astype("datetime64[Y]")
    days = (t - y0.astype("datetime64[s]")).astype(float) / DAY_S
    n_days = ((y0 + 1).astype("datetime64[D]") - y0.astype("datetime64[D]")).astype(float)
    return y0.astype(int) + 1970 + days / n_days


@cache
def _transformer():
    import pyproj  # deferred: only the PPP reports map frames, and pyproj's import costs ~0.1 s

    return pyproj.Transformer.from_crs(ITRF2014_EPSG, ETRF2000_EPSG, always_xy=True)


def _transform(pos_ecef_m, epoch_yr, direction):
    p = np.asarray(pos_ecef_m, float)
    epoch = np.broadcast_to(np.asarray(epoch_yr, float), p.shape[:-1])
    x, y, z, _ = _transformer().transform(p[..., 0], p[..., 1], p[..., 2], epoch, direction=direction)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1).reshape(p.shape)


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
    return _transform(pos_ecef_m, epoch_yr, "FORWARD")


def etrf2000_to_itrf2014(pos_ecef_m, epoch_yr):
    """Inverse of :func:`itrf2014_to_etrf2000` (PROJ's inverse similarity, a round trip within 1e-9 m)."""
    return _transform(pos_ecef_m, epoch_yr, "INVERSE")
