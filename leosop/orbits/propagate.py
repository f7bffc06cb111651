"""Vectorised SGP4 propagation to ECEF position and velocity.

Errors come back as data: a satellite-epoch that SGP4 cannot propagate (decay,
eccentricity out of range, ...) has NaN position and velocity and its SGP4
error code in ``status``; nothing raises in the middle of a batch. Before a
run, :func:`drop_failing` leaves out (with a warning) the satellites that
cannot be propagated over it, e.g. those that have re-entered.
"""

import warnings

import numpy as np
from sgp4.api import SGP4_ERRORS

from ..errors import InputError
from ..frames import teme_to_ecef
from ..timebase import jd_ut1, jd_utc

__all__ = ["state_teme", "state_ecef", "state_ecef_pairs", "drop_failing"]

#: Satellites named in :func:`drop_failing`'s message (then "and N more").
_NAMED = 3


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


def drop_failing(constellation, times_utc, *, what):
    """The satellites SGP4 propagates at every one of ``times_utc``; the others left out with one warning.

    A satellite that has re-entered (or whose elements have gone bad) makes
    SGP4 fail from some time on; propagating it would give NaN states that a
    recording or a fix cannot use. Give the first and last instants of a
    run: a decay does not undo itself.

    Parameters
    ----------
    constellation : Constellation
    times_utc : array_like of datetime64, (n_epochs,)
    what : str
        The span, for messages (e.g. ``"the recording"``).

    Returns
    -------
    Constellation
        The satellites without an SGP4 error at any of ``times_utc``.

    Warns
    -----
    UserWarning
        One line naming the satellites left out (the first few) and the SGP4 error.

    Raises
    ------
    InputError
        No satellite is left.
    """
    _, _, status = state_teme(constellation, times_utc)
    bad = (status != 0).any(axis=1)
    if not bad.any():
        return constellation
    idx = np.flatnonzero(bad)
    code = status[idx].max(axis=1)
    named = ", ".join(f"{' '.join([constellation.sat_ids[i], constellation.names[i].strip()]).strip()} (error {c}: "
                      f"{SGP4_ERRORS.get(int(c), 'unknown')})" for i, c in zip(idx[:_NAMED], code[:_NAMED]))
    more = f" and {idx.size - _NAMED} more" if idx.size > _NAMED else ""
    source = constellation.source or "element sets"
    if bad.all():
        raise InputError(f"{source}: no satellite left: SGP4 cannot propagate any over {what} (decayed or bad "
                         f"elements): {named}{more}")
    warnings.warn(f"{source}: left out {idx.size} satellite(s) SGP4 cannot propagate over {what} (decayed or bad "
                  f"elements): {named}{more}", stacklevel=2)
    return constellation.subset(np.flatnonzero(~bad))
