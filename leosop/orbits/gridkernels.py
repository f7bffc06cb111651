"""Compiled (numba) per-pair work of :func:`leosop.orbits.gridcells.epoch_maps`; optional.

Imported only when numba is installed (``pip install leosop[fast]``); the
numpy code of :mod:`leosop.orbits.gridcells` stays the fallback and the
reference. Each kernel performs the floating-point operations of its numpy
counterpart in the same order (no fast-math, so no fused multiply-adds), so
the results are bit-identical to it:

* :func:`elevation_margins` -- the table elevation test of
  :func:`leosop.orbits.gridcells._visible_segments` (the pairs within
  ``_EXACT_BAND_M`` of the mask are returned for the reference test);
* :func:`accumulate_normals` -- the Jacobian rows of
  :func:`leosop.orbits.gridcells._jacobian_static` and the upper triangle of
  ``H^T H`` per cell: added pair by pair in pair order within a batch and then
  to the running sums, as ``numpy.bincount`` does;
* :func:`normal_gdop` -- the Cholesky GDOP of
  :func:`leosop.orbits.gridcells._normal_gdop`, one cell at a time.

Fusing the per-pair steps removes the gathers and the ~60 pair-length
temporaries of the numpy path and visits each pair's cell once instead of 27
times. ``cache=True``: the machine code is written next to this file
(``leosop/orbits/__pycache__/gridkernels.*.nbi``/``.nbc``) or under
``NUMBA_CACHE_DIR``, so only the first run after an install compiles.
"""

import math

import numba
import numpy as np

from ..constants import C_MPS
from ..geometry.doppler import N_DOPPLER_STATES
from .gridcells import _BATCH_PAIRS, _EXACT_BAND_M, _IU, _exact_visible, _segment_tables, segment_batches

__all__ = ["accumulate_normals", "elevation_margins", "epoch_normals", "normal_gdop"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


def epoch_normals(pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, grid, sat, row, j0, n_cols, sin_mask):
    """Visible count and ``H^T H`` of every cell, compiled; same arguments and results as
    :func:`leosop.orbits.gridcells._epoch_normals` (bit-identical: same batches, same order of operations)."""
    n_cells, n_lon = grid.n_cells, grid.shape[1]
    count = np.zeros(n_cells, dtype=np.int64)
    normal = np.zeros((len(_IU), n_cells))
    n_max = _BATCH_PAIRS + n_lon  # pairs of a batch (its last segment may overshoot by a row)
    vis, rng_m = np.empty(n_max, dtype=bool), np.empty(n_max)
    near_seg, near_lon = np.empty(n_max, dtype=np.int64), np.empty(n_max, dtype=np.int64)
    part = np.empty((0, len(_IU) - 1))
    k_per_m = carrier_hz / C_MPS
    for a, b in segment_batches(n_cols):
        s, rows = sat[a:b], row[a:b]
        x_sv, y_sv, cos_lat, offset, r2_row, rho = _segment_tables(pos_sv_ecef_m, grid, s, rows)
        n_near = elevation_margins(x_sv, y_sv, cos_lat, offset, r2_row, rho, j0[a:b], n_cols[a:b], grid.cos_lon,
                                   grid.sin_lon, sin_mask, _EXACT_BAND_M, vis, rng_m, near_seg, near_lon)
        if n_near:
            pair = np.cumsum(n_cols[a:b])[near_seg[:n_near]] - n_cols[a:b][near_seg[:n_near]]
            pair += near_lon[:n_near] - j0[a:b][near_seg[:n_near]]
            vis[pair] = _exact_visible(pos_sv_ecef_m, grid, s[near_seg[:n_near]], rows[near_seg[:n_near]],
                                       near_lon[:n_near], sin_mask)
        c0, c1 = rows[0] * n_lon, (rows[-1] + 1) * n_lon
        if len(part) < c1 - c0:
            part = np.empty((c1 - c0, len(_IU) - 1))
        accumulate_normals(vis, rng_m, j0[a:b], n_cols[a:b], x_sv, y_sv, pos_sv_ecef_m[s, 2] - grid.z_row_m[rows],
                           rho, vel_sv_ecef_mps[s], k_per_m[s], rows * n_lon - c0, grid.cos_lon, grid.sin_lon, n_lon,
                           part, normal[:, c0:c1], count[c0:c1])
    normal[-1] = count
    return count, normal


@_jit
def elevation_margins(x_sv, y_sv, cos_lat, offset, r2_row, rho, j0, n_cols, cos_lon, sin_lon, sin_mask, band_m,
                      vis, rng_m, near_seg, near_lon):
    """Table elevation test of the pairs of a batch of footprint segments.

    Parameters
    ----------
    x_sv, y_sv, cos_lat, offset, r2_row, rho : ndarray, (n_segments,)
        Per-segment terms of the test (:func:`leosop.orbits.gridcells._segment_tables`).
    j0, n_cols : ndarray of int, (n_segments,)
        First unwrapped longitude index and number of cells of each segment.
    cos_lon, sin_lon : ndarray, (2 n_lon,)
    sin_mask, band_m : float
        Sine of the mask; pairs with ``|margin| <= band_m`` [m] are listed as near.
    vis : ndarray of bool, (m,)
        Out: ``margin > 0`` per pair (``m = n_cols.sum()``, segments in order).
    rng_m : ndarray, (m,)
        Out: range of each pair [m].
    near_seg, near_lon : ndarray of int, (m,)
        Out: segment and unwrapped longitude index of the near pairs (first ``n_near``).

    Returns
    -------
    n_near : int
    """
    m = 0
    n_near = 0
    for s in range(len(n_cols)):
        for lon in range(j0[s], j0[s] + n_cols[s]):
            w = x_sv[s] * cos_lon[lon] + y_sv[s] * sin_lon[lon]
            r = math.sqrt(r2_row[s] - 2.0 * rho[s] * w)
            margin = cos_lat[s] * w + offset[s] - sin_mask * r
            vis[m] = margin > 0.0
            rng_m[m] = r
            if abs(margin) <= band_m:
                near_seg[n_near] = s
                near_lon[n_near] = lon
                n_near += 1
            m += 1
    return n_near


@_jit
def accumulate_normals(vis, rng_m, j0, n_cols, x_sv, y_sv, dz, rho, vel_sv_ecef_mps, k_per_m, cell0, cos_lon,
                       sin_lon, n_lon, part, normal, count):
    """Add the visible pairs of a batch to the per-cell ``H^T H`` (upper triangle) and counts.

    Parameters
    ----------
    vis : ndarray of bool, (m,)
    rng_m : ndarray, (m,)
        Pairs of the batch in segment order (:func:`elevation_margins`).
    j0, n_cols : ndarray of int, (n_segments,)
    x_sv, y_sv, dz, rho : ndarray, (n_segments,)
        Satellite x and y, satellite z minus the row's z, the row's distance from the polar axis [m].
    vel_sv_ecef_mps : ndarray, (n_segments, 3)
    k_per_m : ndarray, (n_segments,)
        Carrier over the speed of light [1/m].
    cell0 : ndarray of int, (n_segments,)
        Row start of each segment's cells relative to the batch's first cell.
    cos_lon, sin_lon : ndarray, (2 n_lon,)
    n_lon : int
    part : ndarray, (>= n_batch_cells, n_triu - 1)
        Scratch: this batch's sums, cell-major (a pair's sums side by side).
    normal : ndarray, (n_triu, n_batch_cells)
        Running sums of the batch's cells (a view), added to.
    count : ndarray of int, (n_batch_cells,)
        Visible satellites per cell, added to.
    """
    n_cells = normal.shape[1]
    part[:n_cells] = 0.0
    m = 0
    for s in range(len(n_cols)):
        vx, vy, vz, k = vel_sv_ecef_mps[s, 0], vel_sv_ecef_mps[s, 1], vel_sv_ecef_mps[s, 2], k_per_m[s]
        for lon in range(j0[s], j0[s] + n_cols[s]):
            if vis[m]:
                rng = rng_m[m]
                e0 = (x_sv[s] - rho[s] * cos_lon[lon]) / rng
                e1 = (y_sv[s] - rho[s] * sin_lon[lon]) / rng
                e2 = dz[s] / rng
                e_dot_v = e0 * vx + e1 * vy + e2 * vz
                k_over_rng = k / rng
                # One row of H; its clock column is 1 (and h_i * 1 is h_i exactly).
                h = ((vx - e0 * e_dot_v) * k_over_rng, (vy - e1 * e_dot_v) * k_over_rng,
                     (vz - e2 * e_dot_v) * k_over_rng, e0 * k, e1 * k, e2 * k, 1.0)
                c = cell0[s] + (lon - n_lon if lon >= n_lon else lon)
                count[c] += 1
                # Entries (i, j), i <= j, row by row as numpy.triu_indices; (clock, clock) is the count.
                q = 0
                for i in range(N_DOPPLER_STATES - 1):
                    for j in range(i, N_DOPPLER_STATES):
                        part[c, q + j - i] += h[i] * h[j]
                    q += N_DOPPLER_STATES - i
            m += 1
    for c in range(n_cells):
        for q in range(part.shape[1]):
            normal[q, c] += part[c, q]


@_jit
def normal_gdop(normal, cells, q_of, gdop):
    """GDOP ``sqrt(trace((H^T H)^-1))`` of the given cells; NaN when singular (pivot <= 1e-12).

    Parameters
    ----------
    normal : ndarray, (n_triu, n_cells)
        Upper triangles, entry ``(i, j)`` in row ``q_of[i, j]``.
    cells : ndarray of int, (k,)
    q_of : ndarray of int, (N_DOPPLER_STATES, N_DOPPLER_STATES)
    gdop : ndarray, (n_cells,)
        Out, at ``cells``.
    """
    n = N_DOPPLER_STATES
    d = np.empty(n)
    L = np.empty((n, n))
    x = np.empty(n)
    for c in cells:
        ok = True
        for i in range(n):
            g = normal[q_of[i, i], c]
            ok = ok and g > 0
            d[i] = 1.0 / math.sqrt(g if g > 0 else 1.0)
        for j in range(n):
            acc = 0.0
            for k in range(j):
                acc += L[j, k] * L[j, k]
            piv = 1.0 - acc if j else 1.0
            ok = ok and piv > 1e-12
            if not ok:
                break
            L[j, j] = math.sqrt(piv)
            for i in range(j + 1, n):
                acc = 0.0
                for k in range(j):
                    acc += L[i, k] * L[j, k]
                L[i, j] = (normal[q_of[j, i], c] * d[i] * d[j] - acc) / L[j, j]
        if not ok:
            gdop[c] = np.nan
            continue
        trace = 0.0
        for j in range(n):
            x[j] = 1.0 / L[j, j]
            col = x[j] * x[j]
            for i in range(j + 1, n):
                acc = 0.0
                for k in range(j, i):
                    acc += L[i, k] * x[k]
                x[i] = -acc / L[i, i]
                col = col + x[i] * x[i]
            trace = trace + col * (d[j] * d[j])
        gdop[c] = math.sqrt(trace)
