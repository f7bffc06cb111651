"""Vectorised SGP4 propagation to ECEF position and velocity.

Errors come back as data: a satellite-epoch that SGP4 cannot propagate (decay,
eccentricity out of range, ...) has NaN position and velocity and its SGP4
error code in ``status``; nothing raises in the middle of a batch.
"""

import numpy as np

from ..frames import teme_to_ecef
from ..timebase import jd_ut1, jd_utc

__all__ = ["state_teme", "state_ecef", "state_ecef_pairs"]


def _times(times_utc):
    t = np.atleast_1d(np.asarray(times_utc, dtype="datetime64[ns]"))
    if t.ndim != 1:
        raise ValueError(f"times_utc must be one-dimensional, got shape {t.shape}")
    return t


def state_teme(constellation, times_utc):
    """SGP4 state in TEME.

    Parameters
    ----------
    constellation : Constellation
    times_utc : array_like of datetime64, (n_epochs,)

    Returns
    -------
    pos_teme_m, vel_teme_mps : ndarray, (n_sats, n_epochs, 3)
    status : ndarray of uint8, (n_sats, n_epochs)
        SGP4 error code, 0 when valid.
    """
    t = _times(times_utc)
    jd, fr = jd_utc(t)
    err, r_km, v_kmps = constellation.satrec_array.sgp4(jd, fr)
    bad = err != 0
    r_km[bad] = np.nan
    v_kmps[bad] = np.nan
    return r_km * 1e3, v_kmps * 1e3, err.astype(np.uint8)


def state_ecef(constellation, times_utc):
    """SGP4 state in ECEF (ITRF, polar motion neglected).

    Parameters
    ----------
    constellation : Constellation
    times_utc : array_like of datetime64, (n_epochs,)

    Returns
    -------
    pos_ecef_m, vel_ecef_mps : ndarray, (n_sats, n_epochs, 3)
    status : ndarray of uint8, (n_sats, n_epochs)
    """
    t = _times(times_utc)
    r, v, status = state_teme(constellation, t)
    jd, fr = jd_ut1(t)
    pos, vel = teme_to_ecef(r, v, jd, fr)
    return pos, vel, status


def state_ecef_pairs(constellation, sat_index, times_utc):
    """ECEF state of one satellite per time, e.g. at each measurement's transmit time.

    Parameters
    ----------
    constellation : Constellation
    sat_index : array_like of int, (m,)
    times_utc : array_like of datetime64, (m,)

    Returns
    -------
    pos_ecef_m, vel_ecef_mps : ndarray, (m, 3)
    status : ndarray of uint8, (m,)
    """
    idx = np.asarray(sat_index, dtype=int)
    t = _times(times_utc)
    if idx.shape != t.shape:
        raise ValueError(f"sat_index {idx.shape} and times_utc {t.shape} must have the same shape")
    jd, fr = jd_utc(t)
    r = np.full((len(t), 3), np.nan)
    v = np.full((len(t), 3), np.nan)
    status = np.zeros(len(t), dtype=np.uint8)
    for k in np.unique(idx):
        rows = np.flatnonzero(idx == k)
        e, rk, vk = constellation.satrecs[k].sgp4_array(jd[rows], fr[rows])
        ok = e == 0
        r[rows[ok]] = rk[ok] * 1e3
        v[rows[ok]] = vk[ok] * 1e3
        status[rows] = e
    ujd, ufr = jd_ut1(t)
    pos, vel = teme_to_ecef(r, v, ujd, ufr)
    return pos, vel, status
