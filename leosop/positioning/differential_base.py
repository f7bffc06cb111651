"""The base's side of a differential fix: its corrections at the rover's rows and the noise they share.

The base's correction of a row is its measurement minus the Doppler its
known position predicts; :func:`base_corrections` interpolates it linearly
in time to the rover's rows (:mod:`~leosop.positioning.differential` uses it
to form single differences). Rover rows that interpolate the same base row
share its noise; :func:`whitener` builds the banded Cholesky factor of that
covariance so that a fit sees independent rows.
"""

import numpy as np
from scipy.linalg import cholesky_banded, solve_banded

from ..errors import InputError
from ..geometry.doppler import doppler_jacobian

__all__ = ["MAX_GAP_S", "TIME_TOL_S", "base_corrections", "model_hz", "sv_states", "whitener"]

#: Widest gap between two base rows of a satellite that is interpolated across [s]: a few snapshot periods
#: (1 s); the satellite's frequency terms are smooth over it, the base's noise is what interpolation adds.
MAX_GAP_S = 5.0
#: Tolerance on a rover time outside its satellite's base span [s] (rounding of time tags).
TIME_TOL_S = 1e-6


def sv_states(meas, name):
    """Satellite states and sigmas of a receiver's rows, checked."""
    if meas.pos_sv_ecef_m is None:
        raise InputError(f"{meas.source or name}: no satellite states (give them as columns or from element sets)")
    return np.asarray(meas.pos_sv_ecef_m, float), np.asarray(meas.vel_sv_ecef_mps, float)


def model_hz(pos_sv_ecef_m, vel_sv_ecef_mps, pos_rx_ecef_m, carrier_hz, vel_rx_ecef_mps=0.0):
    """Doppler of satellites (..., m, 3) seen from receivers broadcastable to them (one per row or per set).

    Returns predictions (..., m) and Jacobians (..., m, 7) (:func:`doppler_jacobian`); the receivers at rest
    unless ``vel_rx_ecef_mps`` is given.
    """
    r_s, v_s = np.asarray(pos_sv_ecef_m, float), np.asarray(vel_sv_ecef_mps, float)
    p_rx = np.broadcast_to(np.asarray(pos_rx_ecef_m, float), r_s.shape)
    v_rx = np.broadcast_to(np.asarray(vel_rx_ecef_mps, float), r_s.shape)
    H = doppler_jacobian(r_s[..., None, :], v_s[..., None, :], p_rx, v_rx,
                         np.asarray(carrier_hz, float)[..., None])[..., 0, :]
    return np.einsum("...mi,...mi->...m", H[..., 3:6], v_rx - v_s), H


def base_corrections(base, base_pos_ecef_m, sat_id, t_s, *, t_base_s=None, max_gap_s=MAX_GAP_S):
    """The base's correction (measurement minus predicted Doppler) interpolated to rover rows.

    Parameters
    ----------
    base : Measurements
        Base rows with satellite states and ``sigma_hz``.
    base_pos_ecef_m : array_like, (3,)
    sat_id : array_like of str, (m,)
        Satellite of each rover row.
    t_s : array_like, (m,)
        Rover row times, on the time base of ``t_base_s``.
    t_base_s : array_like, (n,), optional
        Base row times; default ``base.t_s``.
    max_gap_s : float

    Returns
    -------
    corr_hz, var_hz2 : ndarray, (m,)
        Interpolated correction and its variance; NaN where the row has none.
    base_rows : ndarray of int, (m, 2)
        The two base rows each correction interpolates (-1 where none).
    base_weights : ndarray, (m, 2)
        Their weights (sum 1; 0 where none): rover rows that share a base
        row share its noise, ``cov = sum w_i w_j var_base``.
    """
    pos_sv, vel_sv = sv_states(base, "base")
    tb = np.asarray(base.t_s if t_base_s is None else t_base_s, dtype=float)
    pred, _ = model_hz(pos_sv, vel_sv, np.asarray(base_pos_ecef_m, float), base.carrier_hz)
    c_b = base.doppler_hz - pred
    var_b = np.asarray(base.sigma_hz, float) ** 2
    ids = np.asarray(sat_id, dtype=str)
    t = np.asarray(t_s, dtype=float)
    rows_out, w_out = np.full((len(ids), 2), -1), np.zeros((len(ids), 2))
    for sid in np.intersect1d(ids, base.sat_id):
        rows = np.flatnonzero(base.sat_id == sid)
        rows = rows[np.argsort(tb[rows], kind="stable")]
        tr, want = tb[rows], np.flatnonzero(ids == sid)
        j = np.clip(np.searchsorted(tr, t[want] - TIME_TOL_S), 1, max(len(tr) - 1, 1))
        lo, hi = np.maximum(j - 1, 0), np.minimum(j, len(tr) - 1)
        span = tr[hi] - tr[lo]
        a = np.clip(np.divide(t[want] - tr[lo], span, out=np.zeros(len(want)), where=span > 0), 0.0, 1.0)
        inside = (t[want] >= tr[0] - TIME_TOL_S) & (t[want] <= tr[-1] + TIME_TOL_S) & (span <= max_gap_s)
        # A single base row (or a rover time on a base row) takes that row's correction alone.
        near = np.abs(t[want] - tr[lo]) <= TIME_TOL_S
        a = np.where(near, 0.0, a)
        ok = (inside | near)[:, None]
        rows_out[want] = np.where(ok, np.stack([rows[lo], rows[hi]], axis=-1), -1)
        w_out[want] = np.where(ok, np.stack([1.0 - a, a], axis=-1), 0.0)
    has = rows_out[:, 0] >= 0
    take = np.maximum(rows_out, 0)
    corr = np.where(has, np.sum(w_out * c_b[take], axis=-1), np.nan)
    var = np.where(has, np.sum(w_out**2 * var_b[take], axis=-1), np.nan)
    return corr, var, rows_out, w_out


def whitener(var_rover_hz2, base_rows, base_weights, var_base_hz2, pad):
    """Whitening of each block's single differences: ``v -> L^-1 v`` with ``L L^T`` their covariance.

    Parameters
    ----------
    var_rover_hz2 : ndarray, (n_b, w)
        Rover noise variance of each block's rows.
    base_rows, base_weights : ndarray, (n_b, w, 2)
        The base rows each row interpolates and their weights
        (:func:`base_corrections`).
    var_base_hz2 : ndarray, (n,)
        Noise variance of the base rows.
    pad : ndarray of bool, (n_b, w)
        Padding rows (unit variance, uncorrelated).

    Returns
    -------
    whiten : callable
        ``whiten(v, idx)``: ``L^-1 v`` for the blocks ``idx`` (k,), ``v``
        (k, w) or (k, w, n).

    Notes
    -----
    Rows interpolating the same base row share its noise::

        R_ij = var_rover_i [i == j] + sum_pq [b_ip == b_jq] w_ip w_jq var_base(b_ip)

    so a base off the rover's epochs correlates a satellite's neighbouring
    rows (a base on them leaves ``R`` diagonal and ``L^-1`` the plain
    weights). Those rows lie a few rows apart (one epoch of satellites), so
    ``R`` is banded: its Cholesky factor and the triangular solves are banded
    too (:func:`scipy.linalg.cholesky_banded`).
    """
    n_b, width = pad.shape
    b = np.where(pad[..., None] | (base_weights == 0), -1, base_rows)
    wv = np.where(b >= 0, base_weights, 0.0) * np.sqrt(var_base_hz2[np.maximum(b, 0)])
    # Bandwidth: the widest spread of a base row's users within a block.
    pos = np.broadcast_to(np.arange(width)[None, :, None], b.shape)[b >= 0]
    key = (np.broadcast_to(np.arange(n_b)[:, None, None], b.shape)[b >= 0] * (var_base_hz2.size + 1)
           + b[b >= 0])
    order = np.lexsort((pos, key))
    key, pos = key[order], pos[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if key.size else np.zeros(0, int)
    band = int(np.max(np.maximum.reduceat(pos, starts) - np.minimum.reduceat(pos, starts))) if key.size else 0
    ab = np.zeros((n_b, band + 1, width))  # lower banded form: ab[d, i] = R[i + d, i]
    for d in range(band + 1):
        for p in range(2):
            for q in range(2):
                same = (b[:, d:, p] == b[:, : width - d, q]) & (b[:, d:, p] >= 0)
                ab[:, d, : width - d] += np.where(same, wv[:, d:, p] * wv[:, : width - d, q], 0.0)
    ab[:, 0] += np.where(pad, 1.0, var_rover_hz2)
    chol = [cholesky_banded(ab[k], lower=True) for k in range(n_b)]

    def whiten(v, idx):
        return np.stack([solve_banded((band, 0), chol[k], v[j]) for j, k in enumerate(idx)])

    return whiten
