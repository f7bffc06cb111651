"""Visible satellites and Doppler GDOP of every cell of a global latitude/longitude grid at one epoch.

Every grid cell is a static receiver on the WGS84 ellipsoid (height 0). Per
epoch all satellites are propagated once; each satellite's *footprint*, the
cells that see it above the mask, is found from its position alone: on a
sphere of radius ``R`` the footprint of a satellite at geocentric radius ``r``
is a cap of angular radius ``arccos(R cos(mask) / r) - mask`` around the
sub-satellite point. The cap is taken with the polar radius (the largest cap
over the ellipsoid) and widened by :data:`FOOTPRINT_MARGIN_DEG` (geodetic
normal versus geocentric direction, <= 0.19 deg), converted to one longitude
interval per latitude row, and every candidate (satellite, cell) pair then gets
the exact elevation test of :func:`_visible` -- the same test as the brute
force :func:`brute_force_epoch`, so the counts are identical.

The Doppler GDOP per cell (Shen 2024 eq. 10; 7 states, static receiver, see
:mod:`leosop.geometry.dop`) needs ``H^T W H`` per cell: the outer products
of the visible satellites' Jacobian rows are scatter-added to their cells
(``numpy.bincount``), then inverted in one batch. NaN where fewer than 7
satellites are visible or the geometry is singular. The maps over time are
:func:`leosop.orbits.gridmap.gdop_map`'s.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS, WGS84_B_M
from ..errors import InputError
from ..frames import geodetic_to_ecef
from ..geometry.dop import gdop as gdop_of_h
from ..geometry.doppler import N_DOPPLER_STATES, doppler_jacobian

__all__ = [
    "Grid", "make_grid", "check_grid_deg", "footprint_pairs", "epoch_maps", "brute_force_epoch",
    "FOOTPRINT_MARGIN_DEG", "READABLE_GRID_DEG",
]

#: Widening of the spherical footprint cap [deg]: covers the tilt of the
#: geodetic normal from the geocentric direction (<= 0.19 deg; the cap edge
#: moves by at most as much, |d cap / d elevation| <= 1) and geodetic versus
#: geocentric latitude of the rows (<= 0.19 deg).
FOOTPRINT_MARGIN_DEG = 0.5
# Candidate pairs processed at once (memory ~ 250 bytes per pair).
_BATCH_PAIRS = 400_000
# Cells x satellites per brute-force block.
_BRUTE_BLOCK = 2_000_000
_IU, _JU = np.triu_indices(N_DOPPLER_STATES)


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
    """

    step_deg: float
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    pos_ecef_m: np.ndarray
    up_ecef: np.ndarray

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


def check_grid_deg(grid_deg, option="--grid-deg"):
    """``grid_deg`` if it divides 180 (hence 360) into whole steps, else InputError with readable ones near it.

    The grid is lat = -90, -90 + G, ..., 90 and lon = -180, ..., < 180, so
    only steps G with 180 / G whole make it honestly; the message offers the
    nearest of :data:`READABLE_GRID_DEG` below and above.
    """
    if not (math.isfinite(grid_deg) and 0.0 < grid_deg <= 90.0):
        raise InputError(f"{option} {grid_deg:g}: must be in (0, 90] deg")
    n = 180.0 / grid_deg
    if abs(n - round(n)) > 1e-9 * n:
        below = READABLE_GRID_DEG[READABLE_GRID_DEG < grid_deg]
        above = READABLE_GRID_DEG[READABLE_GRID_DEG > grid_deg]
        near = " or ".join(f"{g:g}" for g in (*below[-1:], *above[:1]))
        raise InputError(f"{option} {grid_deg:g}: must divide 180 and 360 into whole steps; nearest valid: {near}")
    if grid_deg < 0.1:
        raise InputError(f"{option} {grid_deg:g}: at least 0.1 deg (a finer grid does not fit in memory)")
    return 180.0 / round(n)


@functools.lru_cache(maxsize=4)
def make_grid(grid_deg):
    """The :class:`Grid` of step ``grid_deg`` (checked with :func:`check_grid_deg`)."""
    step = check_grid_deg(grid_deg)
    n_lat = round(180.0 / step) + 1
    n_lon = round(360.0 / step)
    lat_deg = -90.0 + step * np.arange(n_lat)
    lon_deg = -180.0 + step * np.arange(n_lon)
    lat = np.radians(np.repeat(lat_deg, n_lon))
    lon = np.radians(np.tile(lon_deg, n_lat))
    pos = geodetic_to_ecef(lat, lon, 0.0)
    up = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    return Grid(step, lat_deg, lon_deg, pos, up)


def _visible(pos_sv_ecef_m, pos_cell_ecef_m, up_cell, sin_mask):
    """Elevation test ``los.up >= sin(mask) |los|`` of pairs; returns (visible, los, range)."""
    los = pos_sv_ecef_m - pos_cell_ecef_m
    rng = np.sqrt(np.einsum("...i,...i->...", los, los))
    return np.einsum("...i,...i->...", los, up_cell) >= sin_mask * rng, los, rng


def footprint_pairs(pos_sv_ecef_m, grid, mask_deg):
    """Candidate (satellite, cell) pairs: cells inside each satellite's widened footprint cap.

    Parameters
    ----------
    pos_sv_ecef_m : ndarray, (n_sats, 3)
        NaN rows (failed propagation) get no cells.
    grid : Grid
    mask_deg : float

    Returns
    -------
    sat_index, cell_index : ndarray of int, (m,)
        A superset of the visible pairs, each pair once.
    """
    pos = np.asarray(pos_sv_ecef_m, dtype=float)
    step = grid.step_deg
    n_lat, n_lon = grid.shape
    mask = np.radians(mask_deg)
    r = np.linalg.norm(pos, axis=-1)
    ok = np.isfinite(r) & (r > WGS84_B_M * math.cos(mask))
    k = np.flatnonzero(ok)
    r = r[k]
    lat_s = np.degrees(np.arcsin(pos[k, 2] / r))
    lon_s = np.degrees(np.arctan2(pos[k, 1], pos[k, 0]))
    cap = np.degrees(np.arccos(WGS84_B_M * math.cos(mask) / r) - mask) + FOOTPRINT_MARGIN_DEG
    cap = np.minimum(cap, 180.0)
    i0 = np.clip(np.ceil((lat_s - cap + 90.0) / step), 0, n_lat - 1).astype(int)
    i1 = np.clip(np.floor((lat_s + cap + 90.0) / step), 0, n_lat - 1).astype(int)
    n_rows = np.maximum(i1 - i0 + 1, 0)
    # One entry per (satellite, latitude row).
    row_sat = np.repeat(np.arange(len(k)), n_rows)
    row_i = np.repeat(i0, n_rows) + np.arange(n_rows.sum()) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows)
    phi = np.radians(grid.lat_deg[row_i])
    phi_s = np.radians(lat_s[row_sat])
    cap_r = np.radians(cap[row_sat])
    den = np.cos(phi) * np.cos(phi_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_dlon = (np.cos(cap_r) - np.sin(phi) * np.sin(phi_s)) / den
    full = (den < 1e-12) | (cos_dlon <= -1.0)
    dlon = np.degrees(np.arccos(np.clip(np.nan_to_num(cos_dlon, nan=1.0), -1.0, 1.0)))
    centre = lon_s[row_sat] + 180.0
    j0 = np.ceil((centre - dlon) / step).astype(int)
    n_cols = np.floor((centre + dlon) / step).astype(int) - j0 + 1
    n_cols = np.where(full | (n_cols >= n_lon), n_lon, np.maximum(n_cols, 0))
    j0 = np.where(n_cols == n_lon, 0, j0)
    total = int(n_cols.sum())
    offset = np.arange(total) - np.repeat(np.cumsum(n_cols) - n_cols, n_cols)
    cell = np.repeat(row_i * n_lon, n_cols) + np.mod(np.repeat(j0, n_cols) + offset, n_lon)
    return k[np.repeat(row_sat, n_cols)], cell


def _normal_gdop(normal):
    """GDOP from normal matrices ``H^T W H`` (m, 7, 7): ``sqrt(trace(inverse))``, NaN when singular.

    Cholesky factor of the equilibrated matrix (unit diagonal), unrolled over
    the batch: ``trace(A^-1) = sum (D L^-T)^2``. A pivot below 1e-12 marks the
    geometry singular, the threshold of :func:`leosop.geometry.dop.cofactor`
    (its eigenvalue ratio 1e-12 bounds every pivot from below).
    """
    n = normal.shape[-1]
    diag = np.einsum("...ii->...i", normal)
    ok = (diag > 0).all(-1)
    d = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    A = normal * d[:, :, None] * d[:, None, :]
    L = np.zeros_like(A)
    for j in range(n):
        piv = A[:, j, j] - np.einsum("mk,mk->m", L[:, j, :j], L[:, j, :j])
        ok &= piv > 1e-12
        L[:, j, j] = np.sqrt(np.where(ok, piv, 1.0))
        if j + 1 < n:
            L[:, j + 1:, j] = (A[:, j + 1:, j] - np.einsum("mik,mk->mi", L[:, j + 1:, :j], L[:, j, :j])) \
                / L[:, j, j, None]
    # X = L^-1 by forward substitution; A^-1 = X^T X, so trace(D A^-1 D) = sum_ij X_ij^2 d_j^2.
    X = np.zeros_like(A)
    for i in range(n):
        X[:, i, :] = -np.einsum("mk,mkj->mj", L[:, i, :i], X[:, :i, :])
        X[:, i, i] += 1.0
        X[:, i, :] /= L[:, i, i, None]
    trace = np.einsum("mij,mj->m", X**2, d**2)
    return np.where(ok, np.sqrt(trace), np.nan)


def _jacobian_static(los_ecef_m, rng_m, vel_sv_ecef_mps, carrier_hz):
    """Doppler Jacobian rows of a static receiver as columns (7, m), Fortran-friendly.

    Same rows as :func:`leosop.geometry.doppler.doppler_jacobian` with zero
    receiver velocity, from the satellite-minus-receiver vector ``los``.
    """
    u = -los_ecef_m / rng_m[:, None]
    k = -carrier_hz / C_MPS
    udv = np.einsum("mi,mi->m", u, vel_sv_ecef_mps)
    H = np.empty((N_DOPPLER_STATES, len(rng_m)))
    H[0:3] = (k / rng_m) * (u * udv[:, None] - vel_sv_ecef_mps).T
    H[3:6] = k * u.T
    H[6] = 1.0
    return H


def epoch_maps(pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, grid, mask_deg):
    """Visible count and Doppler GDOP of every cell at one epoch, by footprints.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n_sats, 3)
    carrier_hz : ndarray, (n_sats,)
    grid : Grid
    mask_deg : float

    Returns
    -------
    n_visible : ndarray of int, (n_lat, n_lon)
    gdop : ndarray, (n_lat, n_lon)
        NaN below 7 visible satellites or for a singular geometry.
    """
    sat, cell = footprint_pairs(pos_sv_ecef_m, grid, mask_deg)
    sin_mask = math.sin(math.radians(mask_deg))
    n_cells = grid.n_cells
    count = np.zeros(n_cells, dtype=np.int64)
    normal = np.zeros((len(_IU), n_cells))
    last = N_DOPPLER_STATES - 1
    for a in range(0, len(sat), _BATCH_PAIRS):
        s, c = sat[a:a + _BATCH_PAIRS], cell[a:a + _BATCH_PAIRS]
        vis, los, rng = _visible(pos_sv_ecef_m[s], grid.pos_ecef_m[c], grid.up_ecef[c], sin_mask)
        s, c, los, rng = s[vis], c[vis], los[vis], rng[vis]
        count += np.bincount(c, minlength=n_cells)
        H = _jacobian_static(los, rng, vel_sv_ecef_mps[s], carrier_hz[s])
        for q, (i, j) in enumerate(zip(_IU, _JU)):
            if j < last:
                normal[q] += np.bincount(c, weights=H[i] * H[j], minlength=n_cells)
            elif i < last:  # clock column is 1
                normal[q] += np.bincount(c, weights=H[i], minlength=n_cells)
    normal[len(_IU) - 1] = count
    gdop = np.full(n_cells, np.nan)
    fix = np.flatnonzero(count >= N_DOPPLER_STATES)
    if fix.size:
        full = np.empty((fix.size, N_DOPPLER_STATES, N_DOPPLER_STATES))
        full[:, _IU, _JU] = normal[:, fix].T
        full[:, _JU, _IU] = normal[:, fix].T
        gdop[fix] = _normal_gdop(full)
    return count.reshape(grid.shape), gdop.reshape(grid.shape)


def brute_force_epoch(pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, grid, mask_deg, cells=None):
    """Reference: every satellite against every cell (or the given cells), one epoch.

    Same arguments as :func:`epoch_maps`; ``cells`` (flat indices) restricts
    the evaluation. Returns ``n_visible, gdop`` of shape (n_cells_evaluated,).
    GDOP through :func:`leosop.geometry.dop.gdop` on the zero-weighted rows.
    """
    cells = np.arange(grid.n_cells) if cells is None else np.asarray(cells)
    sin_mask = math.sin(math.radians(mask_deg))
    n_sats = len(pos_sv_ecef_m)
    block = max(1, _BRUTE_BLOCK // max(n_sats, 1))
    counts, gdops = [], []
    for a in range(0, len(cells), block):
        c = cells[a:a + block]
        vis, _, _ = _visible(pos_sv_ecef_m[None], grid.pos_ecef_m[c][:, None], grid.up_ecef[c][:, None], sin_mask)
        vis &= np.isfinite(pos_sv_ecef_m[:, 0])[None]
        counts.append(vis.sum(axis=1))
        width = max(int(vis.sum(axis=1).max(initial=0)), 1)
        # Visible satellites first in each row, then the rest with zero weight.
        order = np.argsort(~vis, axis=1, kind="stable")[:, :width]
        w = np.take_along_axis(vis, order, axis=1).astype(float)
        H = doppler_jacobian(np.nan_to_num(pos_sv_ecef_m)[order], np.nan_to_num(vel_sv_ecef_mps)[order],
                             grid.pos_ecef_m[c], np.zeros((len(c), 3)), carrier_hz[order])
        gdops.append(gdop_of_h(H, weights=w))
    return np.concatenate(counts), np.concatenate(gdops)
