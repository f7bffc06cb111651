"""The global latitude/longitude grid of the maps: its cells, their positions and the steps it accepts.

Cells are static receivers on the WGS84 ellipsoid (height 0), flattened
latitude-major; :func:`make_grid` builds one (cached), :func:`check_grid_deg`
refuses a step that does not divide 180 deg.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..frames import geodetic_to_ecef

__all__ = ["READABLE_GRID_DEG", "Grid", "check_grid_deg", "make_grid"]


@dataclass(frozen=True)
class Grid:
    """Cells of a global grid, flattened latitude-major (``cell = i_lat * n_lon + i_lon``).

    Attributes
    ----------
    step_deg : float
    lat_deg : ndarray, (n_lat,)
        -90, -90 + step, ..., 90.
    lon_deg : ndarray, (n_lon,)
        -180, -180 + step, ... < 180.
    pos_ecef_m : ndarray, (n_cells, 3)
        Cell positions on the ellipsoid (height 0).
    up_ecef : ndarray, (n_cells, 3)
        Unit geodetic normals.
    rho_row_m, z_row_m : ndarray, (n_lat,)
        Distance of each row from the polar axis and its height above the
        equator plane: ``pos_ecef_m = (rho cos(lon), rho sin(lon), z)``.
    cos_lat, sin_lat : ndarray, (n_lat,)
    cos_lon, sin_lon : ndarray, (2 n_lon,)
        Of ``lon_deg`` twice over, so that a longitude index up to ``2 n_lon - 1`` needs no modulo.
    """

    step_deg: float
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    pos_ecef_m: np.ndarray
    up_ecef: np.ndarray
    rho_row_m: np.ndarray
    z_row_m: np.ndarray
    cos_lat: np.ndarray
    sin_lat: np.ndarray
    cos_lon: np.ndarray
    sin_lon: np.ndarray

    @property
    def shape(self):
        """(n_lat, n_lon)."""
        return len(self.lat_deg), len(self.lon_deg)

    @property
    def n_cells(self):
        return len(self.lat_deg) * len(self.lon_deg)


#: Grid steps offered when a step does not divide 180 [deg]: those in [0.1, 90]
#: with at most two decimals (1/100 deg times a divisor of 18000), e.g. 0.25, 2.5, 6, 7.2.
READABLE_GRID_DEG = np.arange(10, 9_001)[18_000 % np.arange(10, 9_001) == 0] / 100.0


def check_grid_deg(grid_deg):
    """``grid_deg`` if it divides 180 (hence 360) into whole steps, else InputError with readable ones near it.

    The grid is lat = -90, -90 + G, ..., 90 and lon = -180, ..., < 180, so
    only steps G with 180 / G whole make it honestly; the message offers the
    nearest of :data:`READABLE_GRID_DEG` below and above.
    """
    if not (math.isfinite(grid_deg) and 0.0 < grid_deg <= 90.0):
        raise InputError(f"grid_deg {grid_deg:g}: must be in (0, 90] deg", param="grid_deg")
    n = 180.0 / grid_deg
    if abs(n - round(n)) > 1e-9 * n:
        below = READABLE_GRID_DEG[READABLE_GRID_DEG < grid_deg]
        above = READABLE_GRID_DEG[READABLE_GRID_DEG > grid_deg]
        near = " or ".join(f"{g:g}" for g in (*below[-1:], *above[:1]))
        raise InputError(f"grid_deg {grid_deg:g}: must divide 180 and 360 into whole steps; nearest valid: {near}",
                         param="grid_deg")
    if grid_deg < 0.1:
        raise InputError(f"grid_deg {grid_deg:g}: at least 0.1 deg (a finer grid does not fit in memory)",
                         param="grid_deg")
    return 180.0 / round(n)


@functools.lru_cache(maxsize=4)
def make_grid(grid_deg):
    """The :class:`Grid` of step ``grid_deg`` (checked with :func:`check_grid_deg`)."""
    step = check_grid_deg(grid_deg)
    n_lat = round(180.0 / step) + 1
    n_lon = round(360.0 / step)
    lat_deg = -90.0 + step * np.arange(n_lat)
    lon_deg = -180.0 + step * np.arange(n_lon)
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    on_axis = geodetic_to_ecef(lat, 0.0, 0.0)  # (rho, 0, z) of each row
    cos_lat, sin_lat = np.cos(lat), np.sin(lat)
    cos_lon, sin_lon = np.tile(np.cos(lon), 2), np.tile(np.sin(lon), 2)
    rho, z = on_axis[:, 0], on_axis[:, 2]
    pos = np.stack([np.outer(rho, cos_lon[:n_lon]), np.outer(rho, sin_lon[:n_lon]),
                    np.repeat(z[:, None], n_lon, axis=1)], axis=-1).reshape(-1, 3)
    up = np.stack([np.outer(cos_lat, cos_lon[:n_lon]), np.outer(cos_lat, sin_lon[:n_lon]),
                   np.repeat(sin_lat[:, None], n_lon, axis=1)], axis=-1).reshape(-1, 3)
    return Grid(step, lat_deg, lon_deg, pos, up, rho, z, cos_lat, sin_lat, cos_lon, sin_lon)
