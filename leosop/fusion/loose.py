"""Loosely coupled INS / LEO-fix EKF ([Shen 2024] eq. 13-16) with feedback correction.

State: the 15 INS errors of :mod:`leosop.ins.error_model` (``phi``, ``dv``
ENU, ``[dlat, dlon, dalt]``, gyro drift, accelerometer bias). Measurement:
INS minus LEO fix, velocity then position, 6 values in ENU metres (the
position rows of ``H`` carry the radii that turn ``dlat, dlon`` into metres).
``R`` is the covariance of the fix's white errors, rotated into ENU.

Time-correlated fix errors. A snapshot fix is ``x_true + G_k e_k`` to first
order, ``G_k`` the least-squares gain of epoch k and ``e_k`` the Doppler
errors of its satellites: constant clock-induced offsets ([Shen 2024] Table 1),
constant orbit errors and white estimator noise. Its systematic part persists
from fix to fix and jumps when the satellite set changes: not white, and not
stationary, so no decaying random error fits it. Treated as white it makes the
filter badly overconfident; a Schmidt (consider) treatment is consistent but
more than doubles the errors. So, given a :class:`FixErrorModel`, the filter
estimates them: each satellite in a fix adds a constant offset state (and
three orbit-error states, or three shared by all satellites for a common
orbit shift), which enter the measurement through the fix's gain; they are
marginalised ``DROP_AFTER_S`` (:mod:`.common`) after the last fix that
included them.

What a fix hands the filter. The 6 position and velocity values alone
discard what the fix's residuals show of each satellite's constant errors,
and re-estimating the receiver offsets at every fix discards that they are
constant; in a mixed sky (9-17 satellites, 2-4 clocks) that lost all the
gain of the mix. So each update takes the fix with its receiver offsets (one
near-constant state per clock, as the tight filter has) and its residuals
in the space orthogonal to the fix's states (:func:`_fix_measurement`): to
first order what the epoch's Doppler hold. The filter stays loose in what it
needs: fixes from the snapshot solver, which chooses, checks and solves the
Doppler alone; without a fix (fewer than 6 + k usable Doppler) there is no
update, where the tight filter still takes each Doppler. The measurements
behind these choices: docs/notes/loose-fix-errors.md.

After every update the estimated INS errors are fed back: the INS state is
corrected (:meth:`NavState.corrected`), the bias estimates are accumulated
and removed from later IMU increments, and the INS error state returns to
zero (the satellite error estimates are kept). The INS runs at the IMU
rate; the filter predicts every ``step_s`` (1 s) and updates every
``correction_period_s`` when a fix exists. When no fix exists (fewer than the
fix's 6 + k states for k constellations in view) the INS carries the solution
and the filter resumes at the next fix, so every epoch has an output.

Fixes that cannot be checked. The caller hands the filter only fixes with
a spare Doppler or, without one, a well-conditioned geometry
(:func:`checkable_fixes`): a zero-redundancy fix near a singular geometry
is far from linear in its Doppler errors and its linearised covariance lets
it through the innovation gate kilometres off. And a run of
:data:`REOPEN_AFTER` fixes failing the gate re-opens it (:func:`_reopened`),
so a filter misled once is not locked out of every later fix.
leosop/data/studies/README.md has the run that showed both.
"""

import dataclasses

import numpy as np
from scipy import stats

from .. import frames
from ..ins.error_model import DPOS, DV
from . import kalman
from .common import (GATE_PROBABILITY, N_INS, RX_OFFSET_PSD_HZ2_PER_S, RX_OFFSET_SIGMA_HZ, Corrections,
                     FeedbackIns, SatelliteStates, Track, epochs, initial_covariance, pos_jacobian)

__all__ = ["FixErrorModel", "PAIR_FIELDS", "checkable_fixes", "measurement", "run", "MIN_REDUNDANCY",
           "MAX_GDOP_UNCHECKED", "REOPEN_AFTER"]

#: Fewest measurements beyond the fix's states for the filter to use it (see :func:`checkable_fixes`).
MIN_REDUNDANCY = 1
#: Largest Doppler GDOP of a fix without redundancy that the filter uses.
MAX_GDOP_UNCHECKED = 300.0
#: Consecutive fixes failing the gate after which the filter re-opens it (see :func:`run`).
REOPEN_AFTER = 10

#: The :class:`FixErrorModel` fields with one row per satellite-epoch pair.
PAIR_FIELDS = ("epoch_index", "sat_index", "gain_ecef", "jacobian_pv", "clock_index", "weight_sqrt", "residual_hz",
               "sigma_white_hz")


@dataclasses.dataclass(frozen=True)
class FixErrorModel:
    """What each fix is made of: its least-squares gain, its residuals and its receiver clocks.

    A snapshot fix is ``x = x_true + G e`` to first order, with ``G`` the
    weighted least-squares gain of its epoch and ``e`` the Doppler errors of
    the satellites it used: ``e_j = o_j + h_j . dr_j + n_j`` (clock-induced
    offset, orbit error ``dr_j`` seen through the Doppler's sensitivity ``h_j``
    to the satellite's position, white estimator noise of sigma
    ``sigma_white_hz``). Its whitened residuals ``W^(1/2) r`` are
    ``(I - P) W^(1/2) e``, ``P`` the projection on the columns of
    ``W^(1/2) J`` (``J`` the Doppler's Jacobian in the fix's states): the
    part of the satellites' errors that the fix did not absorb. One row per
    satellite-epoch pair used in a fix, sorted by epoch.

    Attributes
    ----------
    epoch_index, sat_index : ndarray of int, (m,)
    gain_ecef : ndarray, (m, 6 + k)
        The pair's column of ``G``: d[pos, vel (ECEF), receiver offsets] / d(Doppler)
        [m/Hz, m/s/Hz, 1]; zero for the clocks absent at its epoch.
    jacobian_pv : ndarray, (m, 6)
        d(Doppler) / d[receiver pos, vel] (ECEF) at the fix [Hz/m, Hz/(m/s)];
        its position part is ``h_j`` (a satellite believed ``dr`` away acts as
        a receiver moved by ``-dr``).
    clock_index : ndarray of int, (m,)
        The pair's receiver clock, 0 .. k - 1.
    weight_sqrt : ndarray, (m,)
        ``W^(1/2)``: one over the sigma the fix weighted the Doppler by [1/Hz].
    residual_hz : ndarray, (m,)
        Measured minus modelled Doppler at the fix.
    sigma_white_hz : ndarray, (m,)
        Sigma of the pair's white estimator noise.
    fix_clock_hz : ndarray, (n_ep, k)
        Each fix's receiver offsets, NaN for a clock absent at the epoch.
    offset_sigma_hz : float or ndarray, (n_sats,)
        Prior of each offset about its constellation's mean (which that
        constellation's receiver offset absorbs): one for all, or satellite
        j's at index j.
    orbit_sigma_m : float
        Prior of the orbit error per axis.
    orbit_model : {"independent", "common"}
        One orbit error per satellite, or one shift shared by all.
    """

    epoch_index: np.ndarray
    sat_index: np.ndarray
    gain_ecef: np.ndarray
    jacobian_pv: np.ndarray
    clock_index: np.ndarray
    weight_sqrt: np.ndarray
    residual_hz: np.ndarray
    sigma_white_hz: np.ndarray
    fix_clock_hz: np.ndarray
    offset_sigma_hz: float | np.ndarray
    orbit_sigma_m: float
    orbit_model: str = "independent"

    @property
    def orbit_hz_per_m(self):
        """``h_j``: d(Doppler error) / d(orbit error, ECEF) [Hz/m], (m, 3)."""
        return self.jacobian_pv[:, :3]

    @property
    def n_clocks(self):
        """Receiver clocks k (constellations)."""
        return self.fix_clock_hz.shape[1]


def _enu_from_ecef_pv(lat_rad, lon_rad):
    """``T`` mapping ECEF ``[pos, vel]`` to ENU ``[vel, pos]``, (6, 6)."""
    C_n_e = frames.C_e_n(lat_rad, lon_rad).T
    T = np.zeros((6, 6))
    T[0:3, 3:6] = C_n_e
    T[3:6, 0:3] = C_n_e
    return T


def checkable_fixes(n_used, cov, gdop):
    """Whether each snapshot fix is fit for the filter: redundant, or of a well-conditioned geometry.

    A fix of ``6 + k`` states (k receiver clocks) from ``6 + k`` Doppler fits
    them exactly: its residuals are zero whatever its errors, so neither the
    fix's chi-square test nor its outlier test can see anything. That is
    harmless while the geometry is good, but near a singular geometry the
    fix is far from linear in the Doppler errors: its linearised covariance
    (and the gain of :class:`FixErrorModel`) understate it, and the filter's
    innovation gate, whose ``S`` is dominated by that huge covariance,
    passes fixes kilometres off. So a fix without redundancy is used only up
    to a Doppler GDOP of :data:`MAX_GDOP_UNCHECKED`; a fix with at least
    :data:`MIN_REDUNDANCY` spare Doppler is always used (its residuals were checked).

    Parameters
    ----------
    n_used : ndarray of int, (n,)
        Doppler in each fix.
    cov : ndarray, (n, 6 + k, 6 + k)
        The fixes' covariance; a state's NaN diagonal means it is absent (a clock not in the sky).
    gdop : ndarray, (n,)
        The fixes' Doppler GDOP ([Shen 2024] eq. 10).

    Returns
    -------
    ndarray of bool, (n,)
    """
    n_states = np.isfinite(np.diagonal(np.asarray(cov), axis1=-2, axis2=-1)).sum(axis=-1)
    redundant = np.asarray(n_used) - n_states >= MIN_REDUNDANCY
    return (n_states > 0) & (redundant | (np.asarray(gdop) <= MAX_GDOP_UNCHECKED))


def measurement(state, pos_fix_ecef_m, vel_fix_ecef_mps, cov_fix_pv_ecef):
    """INS-minus-fix measurement of [Shen 2024] eq. 13.

    Parameters
    ----------
    state : leosop.ins.strapdown.NavState
    pos_fix_ecef_m, vel_fix_ecef_mps : array_like, (3,)
    cov_fix_pv_ecef : array_like, (6, 6)
        Covariance of the fix's ``[x, y, z, vx, vy, vz]`` (ECEF).

    Returns
    -------
    z : ndarray, (6,)
        ``[v_ins - v_fix, p_ins - p_fix]`` in ENU at the INS position [m/s, m].
    H : ndarray, (6, 15)
    R : ndarray, (6, 6)
    """
    z, H, T = _ins_minus_fix(state, pos_fix_ecef_m, vel_fix_ecef_mps)
    return z, H, T @ np.asarray(cov_fix_pv_ecef) @ T.T


def _ins_minus_fix(state, pos_fix_ecef_m, vel_fix_ecef_mps):
    """``z`` and ``H`` of :func:`measurement`, and ``T`` (:func:`_enu_from_ecef_pv`) at the INS position."""
    lat, lon, alt = state.lat_rad, state.lon_rad, state.alt_m
    T = _enu_from_ecef_pv(lat, lon)
    C_n_e = T[0:3, 3:6]
    pos_ins = frames.geodetic_to_ecef(lat, lon, alt)
    z = np.concatenate([state.vel_enu_mps - C_n_e @ vel_fix_ecef_mps, C_n_e @ (pos_ins - pos_fix_ecef_m)])
    H = np.zeros((6, 15))
    H[0:3, DV] = np.eye(3)
    H[3:6, DPOS] = pos_jacobian(lat, alt)
    return z, H, T


def _fix_measurement(state, pos_fix_ecef_m, vel_fix_ecef_mps, k, sats, model, rows, n_states):
    """A fix with its receiver offsets and residuals, as one measurement of the filter's states.

    Rows: the INS-minus-fix difference of :func:`measurement` (6); minus the
    fix's receiver offsets (one per clock present at epoch ``k``), measuring
    the filter's offset states; and ``Q^T W^(1/2) r``, the fix's whitened
    residuals in an orthonormal basis ``Q`` of the complement of the columns
    of ``W^(1/2) J``, which measure the satellites' errors alone (the fix's
    states are projected out). To first order all are linear in the INS
    errors, the offsets and the satellites' errors ``e``, plus ``B n`` with
    ``n`` the Doppler's white noise, so ``R = B diag(sigma_white^2) B^T``
    (the rows are correlated through ``n``). Together they hold what the
    epoch's Doppler hold about these states: what the 6 fix values alone
    discard is the residual space, in which each satellite's constant
    errors show directly (docs/notes/loose-fix-errors.md).

    Returns
    -------
    z : ndarray, (6 + c + r,)
        c clocks present, r = used Doppler - (6 + c).
    H : ndarray, (6 + c + r, n_states)
    R : ndarray, (6 + c + r, 6 + c + r)
    """
    z_fix, H_fix, T = _ins_minus_fix(state, pos_fix_ecef_m, vel_fix_ecef_mps)
    clk = np.flatnonzero(np.isfinite(model.fix_clock_hz[k]))
    w = model.weight_sqrt[rows]
    A = w[:, None] * np.hstack([model.jacobian_pv[rows], model.clock_index[rows, None] == clk])
    U, sv, _ = np.linalg.svd(A)
    Q = U[:, int(np.sum(sv > sv[0] * 1e-9)):]
    G = model.gain_ecef[rows]
    B = np.vstack([-T @ G[:, :6].T, -G[:, 6 + clk].T, Q.T * w])
    z = np.concatenate([z_fix, -model.fix_clock_hz[k, clk], Q.T @ (w * model.residual_hz[rows])])
    H = np.zeros((z.size, n_states))
    H[:6, :N_INS] = H_fix
    H[6 + np.arange(clk.size), N_INS + clk] = -1.0
    for i, r in enumerate(rows):
        c_off, c_orbit = sats.columns(int(model.sat_index[r]))
        H[:, c_off] += B[:, i]
        H[:, c_orbit] += np.outer(B[:, i], model.orbit_hz_per_m[r])
    return z, H, (B * model.sigma_white_hz[rows] ** 2) @ B.T


def _reopened(P, z, state):
    """``P`` with each INS position and velocity variance raised by the square of its innovation.

    A consistent filter rejects a good fix one time in a million
    (:data:`~leosop.fusion.common.GATE_PROBABILITY`); a run of rejections
    means the filter is confidently wrong (e.g. misled by fixes worse than
    their covariance), and the gate would otherwise lock it out of every
    later fix while the INS drifts. Adding ``z_i**2`` to the variance of the
    INS error that ``z_i`` measures makes the current INS-minus-fix
    difference a one-sigma event, so the fix can correct the INS; the
    correlations and the other states are kept.
    """
    P = P.copy()
    P[DV, DV] += np.diag(z[0:3] ** 2)
    J_inv = np.linalg.inv(pos_jacobian(state.lat_rad, state.alt_m))
    P[DPOS, DPOS] += J_inv @ np.diag(z[3:6] ** 2) @ J_inv.T
    return P


def run(state0, dtheta_b_rad, dvel_b_mps, dt_s, fixes, settings, *, fix_errors=None, reopen_after=REOPEN_AFTER,
        progress=None):
    """Run the INS with loose-coupling feedback over a whole flight.

    Parameters
    ----------
    state0 : leosop.ins.strapdown.NavState
        Initial INS state (with its errors).
    dtheta_b_rad, dvel_b_mps : ndarray, (n_imu, 3)
        Measured IMU increments at interval ``dt_s``.
    dt_s : float
    fixes : tuple (pos_ecef_m, vel_ecef_mps, cov_pv)
        LEO fixes at every step epoch ``k * step_s`` (k = 0 .. n-1):
        shapes (n, 3), (n, 3), (n, 6, 6); NaN rows where there is no fix.
        ``cov_pv`` is the fixes' covariance, used when ``fix_errors`` is None
        (which makes their whole error white in time).
    settings : leosop.fusion.common.FilterSettings
    fix_errors : FixErrorModel, optional
        What the fixes are made of: the filter then estimates the receiver
        offsets and the satellites' constant errors as states and takes each
        fix with its offsets and residuals (module docstring).
    reopen_after : int or None
        After this many consecutive fixes failed the innovation gate, the
        next failing fix re-opens it (:func:`_reopened`); None never re-opens.
    progress : callable, optional
        Wraps the epoch iterator (e.g. :func:`leosop.progress.progress`).

    Returns
    -------
    leosop.fusion.common.FusionResult
    """
    pos_fix, vel_fix, cov_fix = fixes
    ins = FeedbackIns(state0, dtheta_b_rad, dvel_b_mps, dt_s, settings)
    n = min(len(pos_fix), ins.n_epochs)
    track = Track(n)
    innovation, innovation_cov = np.full((n, 6), np.nan), np.full((n, 6, 6), np.nan)
    P = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    x_hat = np.zeros(N_INS)  # only the states after the INS errors are kept (the INS errors are fed back)
    if fix_errors is not None:
        # One frequency offset per receiver clock, then the satellites' errors, their offsets about
        # their constellation's mean (which the receiver offset absorbs).
        clocks = slice(N_INS, N_INS + fix_errors.n_clocks)
        P = np.pad(P, (0, fix_errors.n_clocks))
        P[clocks, clocks] = np.eye(fix_errors.n_clocks) * RX_OFFSET_SIGMA_HZ**2
        x_hat = np.zeros(clocks.stop)
        sats = SatelliteStates(clocks.stop, fix_errors.orbit_model, 0.0, fix_errors.offset_sigma_hz,
                               fix_errors.orbit_sigma_m)
        x_hat, P = sats.initial(x_hat, P)
        bounds = np.searchsorted(fix_errors.epoch_index, np.arange(n + 1))
    corrections = Corrections(settings.correction_period_s)
    reopened = np.zeros(n, dtype=bool)
    n_rejected = 0  # consecutive fixes that failed the gate
    for k, t_s in epochs(n, settings.step_s, progress):
        if k > 0:
            P = ins.predict(k, P)
            if fix_errors is not None:
                P[clocks, clocks] += np.eye(fix_errors.n_clocks) * RX_OFFSET_PSD_HZ2_PER_S * settings.step_s
        have_fix = k > 0 and np.all(np.isfinite(pos_fix[k]))
        if fix_errors is not None and have_fix:
            # Bookkeeping at every fix, also between corrections, so that a
            # satellite keeps its states while it stays in view.
            rows = np.arange(bounds[k], bounds[k + 1])
            x_hat, P = sats.see(x_hat, P, fix_errors.sat_index[rows], t_s)
        if have_fix and corrections.due(t_s):
            if fix_errors is None:
                z, H, R = measurement(ins.state, pos_fix[k], vel_fix[k], cov_fix[k])
            else:
                z, H, R = _fix_measurement(ins.state, pos_fix[k], vel_fix[k], k, sats, fix_errors, rows, P.shape[0])
            x, P_post, y, S = kalman.update(x_hat, P, z, H, R)
            nis = kalman.nis(y, S)
            gate = stats.chi2.ppf(GATE_PROBABILITY, z.size) if settings.gate else np.inf
            if nis > gate and reopen_after is not None and n_rejected >= reopen_after:
                P = _reopened(P, z, ins.state)
                x, P_post, y, S = kalman.update(x_hat, P, z, H, R)
                nis = kalman.nis(y, S)
                reopened[k] = True
            if nis <= gate:
                n_rejected = 0
                P = P_post
                ins.feedback(x - x_hat)
                x_hat = np.concatenate([np.zeros(N_INS), x[N_INS:]])
                track.updated[k] = True
                corrections.done(t_s)
                innovation[k], innovation_cov[k] = y[:6], S[:6, :6]
                track.nis[k], track.nis_dof[k] = nis, z.size
            else:
                track.rejected[k] = True
                n_rejected += 1
        track.record(k, ins, P)
    return track.result(settings.step_s, innovation=innovation, innovation_cov=innovation_cov, reopened=reopened)
