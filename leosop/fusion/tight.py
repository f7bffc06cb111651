"""Tightly coupled INS / LEO-Doppler EKF: the filter updates with each satellite's Doppler.

[Shen 2024] names tight coupling as future work; this is ours. The state is
the 15 INS errors of :mod:`leosop.ins.error_model`, the receiver frequency
offset ``T_u[g]`` [Hz] of each constellation g (each family is received by its
own chain: one clock state per family, whatever the number of its
satellites in view), and the satellites' error states of
:class:`leosop.fusion.common.SatelliteStates`: every tracked satellite's
constant clock-induced Doppler offset [Hz] and the constant orbit errors
(ECEF, m), three per satellite (``orbit_model="independent"``) or three
shared by all (``"common"``, every satellite shifted by the same vector,
[Shen 2024] Table 6's [E, E, E]) — the two systematic errors of [Shen 2024]
Table 1 that a snapshot fix cannot separate from the receiver state, and
that make a loosely coupled filter fed with 1 Hz fixes overconfident (their
errors persist from fix to fix). A satellite's states are added with their
prior when it rises and dropped ``DROP_AFTER_S`` after it was last seen.

Measurement of satellite j (the toolkit's Doppler sign)::

    doppler_j = -(f0_j/c) (v_s - v_r).(r_s - r_r)/|r_s - r_r| + T_u[g_j] + o_j + noise,

predicted at the INS state with the satellite position corrected by the
estimated orbit error (its own, or the common shift), which enters the row
through the Doppler's sensitivity to the satellite position. Every state is
an error state fed back after each update, as in :mod:`leosop.fusion.loose`.
No minimum number of satellites: each Doppler is used as it comes, one
satellite of one constellation is enough for an update (where tight coupling
beats a snapshot fix, which needs 6 + k).
"""

import dataclasses

import numpy as np
from scipy import stats

from .. import frames
from ..ins.error_model import DPOS, DV
from ..geometry.doppler import doppler_jacobian
from . import kalman
from .common import (GATE_PROBABILITY, N_INS, RX_OFFSET_PSD_HZ2_PER_S, RX_OFFSET_SIGMA_HZ, Corrections,
                     FeedbackIns, SatelliteStates, Track, epochs, initial_covariance, pos_jacobian)

__all__ = ["DopplerPriors", "DopplerMeasurements", "run"]

_T = N_INS  # index of the first receiver offset (constellation 0)


@dataclasses.dataclass(frozen=True)
class DopplerPriors:
    """What the receiver knows about the Doppler errors.

    ``sat_offset_mean_hz``/``sat_offset_sigma_hz``: prior of each satellite's
    offset (uniform in [0, max]: mean max/2, sigma max/sqrt(12)), one float
    for all or an array indexed by satellite; ``orbit_sigma_m``: orbit error
    per ECEF axis; ``rx_offset_sigma_hz``: prior of each receiver offset;
    ``rx_offset_psd_hz2_per_s``: its random walk; ``orbit_model``: one orbit
    error per satellite (``"independent"``) or one shift of all
    (``"common"``); ``n_clocks``: receiver clocks (constellations).
    """

    sat_offset_mean_hz: float | np.ndarray
    sat_offset_sigma_hz: float | np.ndarray
    orbit_sigma_m: float
    rx_offset_sigma_hz: float = RX_OFFSET_SIGMA_HZ
    rx_offset_psd_hz2_per_s: float = RX_OFFSET_PSD_HZ2_PER_S
    orbit_model: str = "independent"
    n_clocks: int = 1


@dataclasses.dataclass(frozen=True)
class DopplerMeasurements:
    """Doppler measurements of all epochs, sorted by epoch (m rows).

    Attributes
    ----------
    epoch_index, sat_index : ndarray of int, (m,)
    doppler_hz, sigma_hz : ndarray, (m,)
        NaN rows are skipped.
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (m, 3)
        Satellite states as the receiver knows them (with orbit errors).
    carrier_hz : ndarray, (m,)
        Carrier of each row (its constellation's).
    clock_index : ndarray of int, (m,)
        Receiver clock of each row (its constellation), 0 .. n_clocks - 1.
    """

    epoch_index: np.ndarray
    sat_index: np.ndarray
    doppler_hz: np.ndarray
    sigma_hz: np.ndarray
    pos_sv_ecef_m: np.ndarray
    vel_sv_ecef_mps: np.ndarray
    carrier_hz: np.ndarray
    clock_index: np.ndarray


def _rows(state, x_hat, columns, meas, rows):
    """Innovations and their Jacobian for measurement ``rows`` of one epoch.

    ``columns`` holds each row's satellite offset column and orbit columns
    (:meth:`leosop.fusion.common.SatelliteStates.columns`).
    """
    lat, lon, alt = state.lat_rad, state.lon_rad, state.alt_m
    C = frames.C_e_n(lat, lon)
    r_rx = frames.geodetic_to_ecef(lat, lon, alt)
    v_rx = C @ state.vel_enu_mps
    orbit = np.array([x_hat[o] for _, o in columns])
    r_sv = meas.pos_sv_ecef_m[rows] - orbit
    v_sv = meas.vel_sv_ecef_mps[rows]
    J = doppler_jacobian(r_sv, v_sv, r_rx, v_rx, meas.carrier_hz[rows])
    offsets = np.array([x_hat[c] for c, _ in columns])
    clock = _T + meas.clock_index[rows]
    predicted = np.einsum("mi,mi->m", J[:, 3:6], v_rx - v_sv) + x_hat[clock] + offsets
    # The ECEF velocity C_e_n v_enu also moves with the position through the
    # frame's rotation (dv_ecef/dlat, dv_ecef/dlon): 3e-4 m/s per 10 m at 200 m/s.
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    dC_dlat = np.array([[0.0, -cl * co, -sl * co], [0.0, -cl * so, -sl * so], [0.0, -sl, cl]])
    dC_dlon = np.array([[-co, sl * so, -cl * so], [-so, -sl * co, cl * co], [0.0, 0.0, 0.0]])
    dv_dpos = np.column_stack([dC_dlat @ state.vel_enu_mps, dC_dlon @ state.vel_enu_mps, np.zeros(3)])
    H = np.zeros((len(rows), x_hat.size))
    H[:, DV] = -J[:, 3:6] @ C
    H[:, DPOS] = -J[:, 0:3] @ C @ pos_jacobian(lat, alt) - J[:, 3:6] @ dv_dpos
    H[np.arange(len(rows)), clock] = 1.0
    for i, (c, o) in enumerate(columns):
        H[i, c] = 1.0
        H[i, o] = J[i, 0:3]  # the satellite is believed at pos_sv - orbit
    return meas.doppler_hz[rows] - predicted, H


def run(state0, dtheta_b_rad, dvel_b_mps, dt_s, measurements, priors, settings, n_epochs, *, progress=None):
    """Run the INS with tightly coupled Doppler feedback over a whole flight.

    Parameters
    ----------
    state0 : leosop.ins.strapdown.NavState
    dtheta_b_rad, dvel_b_mps : ndarray, (n_imu, 3)
        Measured IMU increments at interval ``dt_s``.
    dt_s : float
    measurements : DopplerMeasurements
        Epoch k is at ``k * settings.step_s``.
    priors : DopplerPriors
    settings : leosop.fusion.common.FilterSettings
        INS priors and noise, step and correction period (gating always on).
    n_epochs : int
    progress : callable, optional

    Returns
    -------
    leosop.fusion.common.FusionResult
        ``innovation`` and ``innovation_cov`` are None, ``doppler_innovation``
        holds each Doppler's normalised innovation; ``nis_dof`` is the number
        of Doppler measurements of each update.
    """
    ins = FeedbackIns(state0, dtheta_b_rad, dvel_b_mps, dt_s, settings)
    n = min(n_epochs, ins.n_epochs)
    gate = stats.chi2.ppf(GATE_PROBABILITY, 1)
    bounds = np.searchsorted(measurements.epoch_index, np.arange(n + 1))
    track = Track(n)
    records = []
    clocks = slice(_T, _T + priors.n_clocks)
    P = np.zeros((clocks.stop, clocks.stop))
    P[:N_INS, :N_INS] = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    P[clocks, clocks] = np.eye(priors.n_clocks) * priors.rx_offset_sigma_hz**2
    x_hat = np.zeros(clocks.stop)  # only the non-INS entries are used: the T_u, then the satellites'
    sats = SatelliteStates(clocks.stop, priors.orbit_model, priors.sat_offset_mean_hz, priors.sat_offset_sigma_hz,
                           priors.orbit_sigma_m)
    x_hat, P = sats.initial(x_hat, P)
    corrections = Corrections(settings.correction_period_s)
    for k, t_s in epochs(n, settings.step_s, progress):
        if k > 0:
            P = ins.predict(k, P)
            P[clocks, clocks] += np.eye(priors.n_clocks) * priors.rx_offset_psd_hz2_per_s * settings.step_s
        rows = np.arange(bounds[k], bounds[k + 1])
        rows = rows[np.isfinite(measurements.doppler_hz[rows]) & (measurements.sigma_hz[rows] > 0)]
        x_hat, P = sats.see(x_hat, P, measurements.sat_index[rows], t_s)
        if k > 0 and corrections.due(t_s) and rows.size:
            columns = [sats.columns(j) for j in measurements.sat_index[rows]]
            y, H = _rows(ins.state, x_hat, columns, measurements, rows)
            R = np.diag(measurements.sigma_hz[rows] ** 2)
            S_diag = np.einsum("ij,jk,ik->i", H, P, H) + np.diag(R)
            ok = y**2 / S_diag <= gate
            track.rejected[k] = not ok.all()
            if ok.any():
                x, P, y_used, S = kalman.update(np.zeros(P.shape[0]), P, y[ok], H[ok], R[np.ix_(ok, ok)])
                ins.feedback(x)
                x_hat[N_INS:] += x[N_INS:]
                track.updated[k] = True
                corrections.done(t_s)
                track.nis[k] = kalman.nis(y_used, S)
                track.nis_dof[k] = int(ok.sum())
                for j, v in zip(measurements.sat_index[rows][ok], y_used / np.sqrt(np.diag(S))):
                    records.append((k, j, v))
        track.record(k, ins, P)
    innovations = np.array(records, dtype=[("epoch", int), ("sat", int), ("normalized", float)])
    return track.result(settings.step_s, doppler_innovation=innovations)
