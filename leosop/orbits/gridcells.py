"""Visible satellites and Doppler GDOP of every cell of a global latitude/longitude grid at one epoch.

Every grid cell is a static receiver on the WGS84 ellipsoid (height 0). Per
epoch all satellites are propagated once; each satellite's *footprint*, the
cells that see it above the mask, is found from its position alone: on a
sphere of radius ``R`` the footprint of a satellite at geocentric radius ``r``
is a cap of angular radius ``arccos(R cos(mask) / r) - mask`` around the
sub-satellite point. The cap is taken with the polar radius (the largest cap
over the ellipsoid) and widened by :data:`FOOTPRINT_MARGIN_DEG` (geodetic
normal versus geocentric direction, <= 0.19 deg), converted to one longitude
interval per latitude row (a *segment*), and every candidate (satellite, cell)
pair then gets the elevation test from row and longitude tables
(:func:`_visible_segments`); the pairs within a millimetre of the mask get the
3-vector test :func:`_visible` of the brute force :func:`brute_force_epoch`,
so the counts are identical to it.

The Doppler GDOP per cell (Shen 2024 eq. 10; 7 states, static receiver, see
:mod:`leosop.geometry.dop`) needs ``H^T W H`` per cell: the outer products
of the visible satellites' Jacobian rows are scatter-added to their cells
(``numpy.bincount``, segments in row order so that a batch touches a narrow
band of cells), then inverted in one batch. NaN where fewer than 7
satellites are visible or the geometry is singular. With numba installed
(``leosop[fast]``) the per-pair work runs compiled instead
(:mod:`leosop.orbits.gridkernels`, bit-identical, ~2x faster). The maps over
time are :func:`leosop.orbits.gridmap.gdop_map`'s.
"""

import math

import numpy as np

from ..constants import C_MPS, WGS84_B_M
from ..geometry.dop import gdop as gdop_of_h
from ..geometry.doppler import N_DOPPLER_STATES, doppler_jacobian
from ..kernels import pick
from .grid import READABLE_GRID_DEG, Grid, check_grid_deg, make_grid

__all__ = [
    "FOOTPRINT_MARGIN_DEG",
    "READABLE_GRID_DEG",
    "Grid",
    "brute_force_epoch",
    "check_grid_deg",
    "epoch_maps",
    "footprint_pairs",
    "make_grid",
    "segment_batches",
]

#: The compiled per-pair work (:mod:`leosop.kernels`).
KERNEL_MODULE = "leosop.orbits.gridkernels"
#: Widening of the spherical footprint cap [deg]: covers the tilt of the
#: geodetic normal from the geocentric direction (<= 0.19 deg; the cap edge
#: moves by at most as much, |d cap / d elevation| <= 1) and geodetic versus
#: geocentric latitude of the rows (<= 0.19 deg).
FOOTPRINT_MARGIN_DEG = 0.5
# Candidate pairs processed at once (~250 bytes each): small enough for the
# cache, large enough to keep the Python overhead per pair small.
_BATCH_PAIRS = 100_000
#: Pairs whose elevation margin ``los.up - sin(mask) |los|`` is within this of
#: zero [m] get the reference test :func:`_visible`: the table form of
#: :func:`_visible_segments` differs from it by rounding, ~1e-8 m at LEO ranges.
_EXACT_BAND_M = 1e-3
# Cells whose GDOP is computed at once: ~60 temporaries of this many floats stay in cache (~1.4x faster than all).
_GDOP_CELLS = 16_384
# Cells x satellites per brute-force block.
_BRUTE_BLOCK = 2_000_000
_IU, _JU = np.triu_indices(N_DOPPLER_STATES)
_Q_OF = np.zeros((N_DOPPLER_STATES, N_DOPPLER_STATES), dtype=np.int64)  # row of entry (i, j), i <= j
_Q_OF[_IU, _JU] = np.arange(len(_IU))


def _visible(pos_sv_ecef_m, pos_cell_ecef_m, up_cell, sin_mask):
    """Elevation test ``los.up >= sin(mask) |los|`` of pairs; returns (visible, los, range)."""
    los = pos_sv_ecef_m - pos_cell_ecef_m
    rng = np.sqrt(np.einsum("...i,...i->...", los, los))
    return np.einsum("...i,...i->...", los, up_cell) >= sin_mask * rng, los, rng


def _footprint_segments(pos_sv_ecef_m, grid, mask_deg):
    """Each satellite's widened footprint cap as one longitude interval per latitude row.

    Parameters
    ----------
    pos_sv_ecef_m : ndarray, (n_sats, 3)
        NaN rows (failed propagation) get no segment.
    grid : Grid
    mask_deg : float

    Returns
    -------
    sat, row, j0, n_cols : ndarray of int, (n_segments,)
        In the order of ``row``. Cells ``row * n_lon + (j0 + t) % n_lon`` for ``0 <= t < n_cols``;
        ``0 <= j0 < n_lon`` and ``n_cols <= n_lon``, so ``j0 + t < 2 n_lon``.
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
    # Spherical law of cosines, with the row's trigonometry from the grid's tables and the satellite's per satellite.
    cos_lat_s, sin_lat_s = np.hypot(pos[k, 0], pos[k, 1]) / r, pos[k, 2] / r
    den = grid.cos_lat[row_i] * cos_lat_s[row_sat]
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_dlon = (np.cos(np.radians(cap))[row_sat] - grid.sin_lat[row_i] * sin_lat_s[row_sat]) / den
    full = (den < 1e-12) | (cos_dlon <= -1.0)
    dlon = np.degrees(np.arccos(np.clip(np.nan_to_num(cos_dlon, nan=1.0), -1.0, 1.0)))
    centre = lon_s[row_sat] + 180.0
    j0 = np.ceil((centre - dlon) / step).astype(int)
    n_cols = np.floor((centre + dlon) / step).astype(int) - j0 + 1
    n_cols = np.where(full | (n_cols >= n_lon), n_lon, np.maximum(n_cols, 0))
    j0 = np.where(n_cols == n_lon, 0, np.mod(j0, n_lon))
    # Row by row, so that a batch of segments covers a narrow band of cells
    # and the scatter-adds of :func:`epoch_maps` stay in cache.
    keep = np.flatnonzero(n_cols > 0)
    keep = keep[np.argsort(row_i[keep].astype(np.int16), kind="stable")]  # radix sort
    return k[row_sat[keep]], row_i[keep], j0[keep], n_cols[keep]


def _segment_pairs(j0, n_cols):
    """Segment index and unwrapped longitude index ``j0 + t`` (< 2 n_lon) of every pair, (m,) each."""
    seg = np.repeat(np.arange(len(n_cols)), n_cols)
    lon = np.arange(seg.size) + np.repeat(j0 - (np.cumsum(n_cols) - n_cols), n_cols)
    return seg, lon


def segment_batches(n_cols):
    """Consecutive segments ``[a, b)`` with about :data:`_BATCH_PAIRS` pairs each (at least one segment each)."""
    ends = np.cumsum(n_cols)
    cuts = np.searchsorted(ends, np.arange(_BATCH_PAIRS, ends[-1] if ends.size else 0, _BATCH_PAIRS), side="right")
    return [(int(a), int(b)) for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(n_cols)]) if b > a]


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
    sat, row, j0, n_cols = _footprint_segments(pos_sv_ecef_m, grid, mask_deg)
    seg, lon = _segment_pairs(j0, n_cols)
    n_lon = grid.shape[1]
    return sat[seg], row[seg] * n_lon + np.mod(lon, n_lon)


def _normal_gdop(packed):
    """GDOP from normal matrices ``H^T W H`` given by their upper triangles.

    ``sqrt(trace(inverse))``, NaN when singular.

    Parameters
    ----------
    packed : ndarray, (n_triu, m)
        Row ``q`` holds entry ``(_IU[q], _JU[q])`` of each of the ``m`` matrices (7 x 7).

    Returns
    -------
    gdop : ndarray, (m,)

    Notes
    -----
    Cholesky factor of the equilibrated matrix (unit diagonal) with every
    entry a vector over the batch: ``trace(A^-1) = sum (L^-1 D)^2``. A pivot
    below 1e-12 marks the geometry singular, the threshold of
    :func:`leosop.geometry.dop.cofactor` (its eigenvalue ratio 1e-12 bounds
    every pivot from below).
    """
    n = N_DOPPLER_STATES
    entry = {(i, j): packed[q] for q, (i, j) in enumerate(zip(_IU, _JU))}
    diag = [entry[i, i] for i in range(n)]
    ok = np.logical_and.reduce([g > 0 for g in diag])
    d = [1.0 / np.sqrt(np.where(g > 0, g, 1.0)) for g in diag]
    L = {}
    for j in range(n):
        piv = 1.0 - sum(L[j, k] ** 2 for k in range(j)) if j else np.ones_like(d[0])
        ok &= piv > 1e-12
        L[j, j] = np.sqrt(np.where(ok, piv, 1.0))
        for i in range(j + 1, n):
            L[i, j] = (entry[j, i] * d[i] * d[j] - sum(L[i, k] * L[j, k] for k in range(j))) / L[j, j]
    # X = L^-1 by forward substitution; A^-1 = D X^T X D, so its trace is sum_ij X_ij^2 d_j^2.
    trace = 0.0
    for j in range(n):
        X = {j: 1.0 / L[j, j]}
        col = X[j] ** 2
        for i in range(j + 1, n):
            X[i] = -sum(L[i, k] * X[k] for k in range(j, i)) / L[i, i]
            col = col + X[i] ** 2
        trace = trace + col * d[j] ** 2
    return np.where(ok, np.sqrt(trace), np.nan)


def _jacobian_static(los_ecef_m, rng_m, vel_sv_ecef_mps, carrier_hz, out):
    """Doppler Jacobian rows of a static receiver, component first, into ``out``.

    Same rows as :func:`leosop.geometry.doppler.doppler_jacobian` with zero
    receiver velocity, from the satellite-minus-receiver vector ``los``.

    Parameters
    ----------
    los_ecef_m, vel_sv_ecef_mps : sequence of 3 ndarrays, (m,) each
    rng_m, carrier_hz : ndarray, (m,)
    out : ndarray, (7, m)

    Returns
    -------
    H : ndarray, (7, m)
        ``out``.
    """
    k = carrier_hz / C_MPS  # u = -e and -f/c: both signs of doppler_jacobian cancel
    e = [np.divide(c, rng_m, out=out[3 + i]) for i, c in enumerate(los_ecef_m)]
    e_dot_v = e[0] * vel_sv_ecef_mps[0] + e[1] * vel_sv_ecef_mps[1] + e[2] * vel_sv_ecef_mps[2]
    k_over_rng = k / rng_m
    for i in range(3):
        np.multiply(e[i], e_dot_v, out=out[i])
        np.subtract(vel_sv_ecef_mps[i], out[i], out=out[i])
        out[i] *= k_over_rng
        out[3 + i] *= k
    out[6] = 1.0
    return out


def _visible_segments(pos_sv_ecef_m, grid, sat, row, seg, lon, sin_mask):
    """Elevation test of the pairs of footprint segments, identical to :func:`_visible`'s.

    The test ``los.up >= sin(mask) |los|`` is evaluated through the row and
    longitude tables: with ``w = x_sv cos(lon) + y_sv sin(lon)``,
    ``los.up = cos(lat) w + sin(lat) z_sv - pos.up`` and
    ``|los|^2 = |pos_sv|^2 - 2 z_row z_sv + |pos|^2 - 2 rho_row w`` -- per pair
    two table look-ups and a few products instead of gathering 3-vectors. It
    differs from :func:`_visible` by rounding only (~1e-8 m); the pairs within
    :data:`_EXACT_BAND_M` of the mask get :func:`_visible` itself.

    Parameters
    ----------
    pos_sv_ecef_m : ndarray, (n_sats, 3)
    grid : Grid
    sat, row : ndarray of int, (n_segments,)
    seg, lon : ndarray of int, (m,)
        Segment and unwrapped longitude index of each pair (:func:`_segment_pairs`).
    sin_mask : float

    Returns
    -------
    vis : ndarray of bool, (m,)
    range_m : ndarray, (m,)
    """
    x_sv, y_sv, cos_lat, offset, r2_row, rho = _segment_tables(pos_sv_ecef_m, grid, sat, row)
    take = np.take  # per pair: ~30% faster than fancy indexing
    w = take(x_sv, seg) * take(grid.cos_lon, lon) + take(y_sv, seg) * take(grid.sin_lon, lon)
    rng = np.sqrt(take(r2_row, seg) - 2.0 * take(rho, seg) * w)
    margin = take(cos_lat, seg) * w + take(offset, seg) - sin_mask * rng
    vis = margin > 0.0
    near = np.flatnonzero(np.abs(margin) <= _EXACT_BAND_M)
    if near.size:
        vis[near] = _exact_visible(pos_sv_ecef_m, grid, sat[seg[near]], row[seg[near]], lon[near], sin_mask)
    return vis, rng


def _segment_tables(pos_sv_ecef_m, grid, sat, row):
    """Per-segment terms of the table elevation test of :func:`_visible_segments`.

    Returns
    -------
    x_sv, y_sv, cos_lat, offset, r2_row, rho : ndarray, (n_segments,)
        Satellite x and y; the row's cos(lat); ``sin(lat) z_sv - pos.up``;
        ``|pos_sv|^2 - 2 z_row z_sv + |pos|^2``; the row's distance from the polar axis.
    """
    p = pos_sv_ecef_m[sat]
    cos_lat, sin_lat = grid.cos_lat[row], grid.sin_lat[row]
    rho, z = grid.rho_row_m[row], grid.z_row_m[row]
    offset = sin_lat * p[:, 2] - (rho * cos_lat + z * sin_lat)
    r2_row = np.einsum("si,si->s", p, p) - 2.0 * z * p[:, 2] + (rho * rho + z * z)
    return p[:, 0].copy(), p[:, 1].copy(), cos_lat, offset, r2_row, rho


def _exact_visible(pos_sv_ecef_m, grid, sat, row, lon, sin_mask):
    """The reference test :func:`_visible` of pairs given by satellite, row and unwrapped longitude, (m,) each."""
    n_lon = grid.shape[1]
    cell = row * n_lon + lon % n_lon
    return _visible(pos_sv_ecef_m[sat], grid.pos_ecef_m[cell], grid.up_ecef[cell], sin_mask)[0]


def epoch_maps(pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, grid, mask_deg, *, kernel=None):
    """Visible count and Doppler GDOP of every cell at one epoch, by footprints.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n_sats, 3)
    carrier_hz : ndarray, (n_sats,)
    grid : Grid
    mask_deg : float
    kernel : {None, "numba", "numpy"}
        The per-pair work compiled (:mod:`leosop.orbits.gridkernels`, bit-identical results) or in numpy;
        None: numba when it is installed.

    Returns
    -------
    n_visible : ndarray of int, (n_lat, n_lon)
    gdop : ndarray, (n_lat, n_lon)
        NaN below 7 visible satellites or for a singular geometry.
    """
    kernels = pick(kernel, KERNEL_MODULE)
    sat, row, j0, n_cols = _footprint_segments(pos_sv_ecef_m, grid, mask_deg)
    args = (np.asarray(pos_sv_ecef_m, dtype=float), np.asarray(vel_sv_ecef_mps, dtype=float),
            np.asarray(carrier_hz, dtype=float), grid, sat, row, j0, n_cols, math.sin(math.radians(mask_deg)))
    count, normal = kernels.epoch_normals(*args) if kernels else _epoch_normals(*args)
    gdop = np.full(grid.n_cells, np.nan)
    fix = np.flatnonzero(count >= N_DOPPLER_STATES)
    if kernels:
        kernels.normal_gdop(normal, fix, _Q_OF, gdop)
    else:
        for a in range(0, fix.size, _GDOP_CELLS):
            gdop[fix[a:a + _GDOP_CELLS]] = _normal_gdop(normal[:, fix[a:a + _GDOP_CELLS]])
    return count.reshape(grid.shape), gdop.reshape(grid.shape)


def _epoch_normals(pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, grid, sat, row, j0, n_cols, sin_mask):
    """Visible count (n_cells,) and upper triangle of ``H^T H`` (n_triu, n_cells) of every cell, numpy.

    ``sat, row, j0, n_cols`` are :func:`_footprint_segments`'; row ``q`` of the triangle holds entry
    ``(_IU[q], _JU[q])``, the last (clock, clock) the count. The reference of the compiled
    :func:`leosop.orbits.gridkernels.epoch_normals`.
    """
    n_cells, n_lon = grid.n_cells, grid.shape[1]
    count = np.zeros(n_cells, dtype=np.int64)
    normal = np.zeros((len(_IU), n_cells))
    last = N_DOPPLER_STATES - 1  # the clock column of H is 1
    cell_of_lon = np.tile(np.arange(n_lon), 2)
    prod = np.empty(_BATCH_PAIRS + n_lon)
    h_buf = np.empty((N_DOPPLER_STATES, _BATCH_PAIRS + n_lon))
    pos_x, pos_y, pos_z = pos_sv_ecef_m.T.copy()
    vel_x, vel_y, vel_z = vel_sv_ecef_mps.T.copy()
    take = np.take  # per pair: ~30% faster than fancy indexing
    for a, b in segment_batches(n_cols):
        seg, lon = _segment_pairs(j0[a:b], n_cols[a:b])
        vis, rng = _visible_segments(pos_sv_ecef_m, grid, sat[a:b], row[a:b], seg, lon, sin_mask)
        keep = np.flatnonzero(vis)
        seg, lon, rng = take(seg, keep), take(lon, keep), take(rng, keep)
        s, rows = sat[a:b], row[a:b]
        rho = take(grid.rho_row_m[rows], seg)
        los = (take(pos_x[s], seg) - rho * take(grid.cos_lon, lon),
               take(pos_y[s], seg) - rho * take(grid.sin_lon, lon), take(pos_z[s] - grid.z_row_m[rows], seg))
        H = _jacobian_static(los, rng, (take(vel_x[s], seg), take(vel_y[s], seg), take(vel_z[s], seg)),
                             take(carrier_hz[s], seg), h_buf[:, :len(keep)])
        c0, c1 = row[a] * n_lon, (row[b - 1] + 1) * n_lon
        cell = take(rows * n_lon - c0, seg) + take(cell_of_lon, lon)
        count[c0:c1] += np.bincount(cell, minlength=c1 - c0)
        p = prod[:len(keep)]
        for q, (i, j) in enumerate(zip(_IU[:-1], _JU[:-1])):  # H^T H summed over each cell's pairs
            normal[q, c0:c1] += np.bincount(cell, weights=np.multiply(H[i], H[j], out=p) if j < last else H[i],
                                            minlength=c1 - c0)
    normal[-1] = count
    return count, normal


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
