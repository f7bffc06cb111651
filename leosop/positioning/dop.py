"""Dilution of precision: Doppler positioning ([Shen 2024] eq. 8-10) and range-based.

Doppler model (the toolkit's sign, see :mod:`leosop`)::

    doppler_hz = -(f0 / c) * (v_s - v_r) . (r_s - r_r) / |r_s - r_r| + T_u

State ``[x, y, z, vx, vy, vz, T_u]`` (ECEF m, m/s, Hz). Its Jacobian is seed
004's eq. 8-9 with the position and velocity columns negated (the paper writes
the carrier with the opposite sign of the range-rate term); GDOP
``sqrt(trace((H^T H)^-1))`` (eq. 10) is the same for both signs.
"""

import numpy as np

from ..constants import C_MPS

__all__ = ["doppler_jacobian", "gdop", "cofactor", "range_dops", "N_DOPPLER_STATES"]

#: States of a Doppler snapshot fix: position, velocity, frequency offset.
N_DOPPLER_STATES = 7


def doppler_jacobian(pos_sv_ecef_m, vel_sv_ecef_mps, pos_rx_ecef_m, vel_rx_ecef_mps, carrier_hz):
    """Rows of H: derivative of each satellite's Doppler w.r.t. the receiver state.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (..., n_sv, 3)
    pos_rx_ecef_m, vel_rx_ecef_mps : array_like, (..., 3)
    carrier_hz : float or array_like, broadcastable to (..., n_sv)

    Returns
    -------
    H : ndarray, (..., n_sv, 7)
        Columns d/dr_rx [Hz/m], d/dv_rx [Hz/(m/s)], d/dT_u [1].
    """
    r_s = np.asarray(pos_sv_ecef_m, dtype=float)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float)
    dr = np.asarray(pos_rx_ecef_m, dtype=float)[..., None, :] - r_s
    dv = np.asarray(vel_rx_ecef_mps, dtype=float)[..., None, :] - v_s
    rho = np.linalg.norm(dr, axis=-1, keepdims=True)
    u = dr / rho
    k = -np.asarray(carrier_hz, dtype=float)[..., None] / C_MPS
    d_pos = k * (dv - u * np.sum(u * dv, axis=-1, keepdims=True)) / rho
    d_vel = k * u
    return np.concatenate([d_pos, d_vel, np.ones(d_pos.shape[:-1] + (1,))], axis=-1)


def cofactor(H, weights=None, *, rcond=1e-12):
    """``(H^T W H)^-1`` per batch; NaN where fewer rows than columns or singular.

    Parameters
    ----------
    H : array_like, (..., n_rows, n_states)
    weights : array_like, (..., n_rows), optional
        Row weights (1/sigma^2); 0 drops a row (e.g. a satellite below the mask).
    rcond : float
        Smallest accepted eigenvalue ratio of ``H^T W H`` scaled to unit diagonal.

    Returns
    -------
    Q : ndarray, (..., n_states, n_states)
    """
    H = np.nan_to_num(np.asarray(H, dtype=float))
    w = np.ones(H.shape[:-1]) if weights is None else np.nan_to_num(np.asarray(weights, dtype=float))
    n_states = H.shape[-1]
    HtH = np.einsum("...ki,...k,...kj->...ij", H, w, H)
    # Columns differ by orders of magnitude (Hz/m against Hz/(m/s)): judge the
    # rank on the equilibrated matrix D HtH D with unit diagonal, then unscale.
    diag = np.einsum("...ii->...i", HtH)
    d = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    lam, V = np.linalg.eigh(HtH * d[..., :, None] * d[..., None, :])
    ok = (lam[..., 0] > rcond * np.abs(lam[..., -1])) & (np.count_nonzero(w, axis=-1) >= n_states) & (diag > 0).all(-1)
    inv_lam = np.where(ok[..., None], 1.0 / np.where(ok[..., None], lam, 1.0), np.nan)
    return np.einsum("...ik,...k,...jk->...ij", V, inv_lam, V) * d[..., :, None] * d[..., None, :]


def gdop(H, weights=None):
    """GDOP ``sqrt(trace((H^T W H)^-1))`` ([Shen 2024] eq. 10); NaN when undetermined.

    Parameters
    ----------
    H : array_like, (..., n_rows, n_states)
    weights : array_like, (..., n_rows), optional

    Returns
    -------
    gdop : ndarray, (...)
    """
    return np.sqrt(np.trace(cofactor(H, weights), axis1=-2, axis2=-1))


def range_dops(los_enu, weights=None):
    """Classic pseudorange DOPs from unit lines of sight in ENU.

    Parameters
    ----------
    los_enu : array_like, (..., n_sv, 3)
        Unit vectors from the receiver to the satellites.
    weights : array_like, (..., n_sv), optional
        0 drops a satellite.

    Returns
    -------
    dict of ndarray, (...)
        ``gdop, pdop, hdop, vdop, tdop``; NaN with fewer than 4 satellites.
    """
    u = np.asarray(los_enu, dtype=float)
    G = np.concatenate([-u, np.ones(u.shape[:-1] + (1,))], axis=-1)
    d = np.diagonal(cofactor(G, weights), axis1=-2, axis2=-1)
    return {
        "gdop": np.sqrt(d.sum(-1)),
        "pdop": np.sqrt(d[..., :3].sum(-1)),
        "hdop": np.sqrt(d[..., :2].sum(-1)),
        "vdop": np.sqrt(d[..., 2]),
        "tdop": np.sqrt(d[..., 3]),
    }
