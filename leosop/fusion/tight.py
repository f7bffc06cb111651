"""Tightly coupled INS / LEO-Doppler EKF: the filter updates with each satellite's Doppler.

Seed 004 names tight coupling as future work; this is ours. The state is
the 15 INS errors of :mod:`leosop.ins.error_model`, the receiver frequency
offset ``T_u`` [Hz], and for every tracked satellite its constant clock-
induced Doppler offset [Hz] and its constant orbit error (ECEF, m) — the two
systematic errors of seed 004 Table 1 that a snapshot fix cannot separate
from the receiver state, and that make a loosely coupled filter fed with
1 Hz fixes overconfident (their errors persist from fix to fix). A
satellite's states are added with their prior when it rises and dropped
:data:`DROP_AFTER_S` after it was last seen.

Measurement of satellite j (the toolkit's Doppler sign)::

    doppler_j = -(f0/c) (v_s - v_r).(r_s - r_r)/|r_s - r_r| + T_u + o_j + noise,

predicted at the INS state with the satellite position corrected by the
estimated orbit error. Every state is an error state fed back after each
update, as in :mod:`leosop.fusion.loose`. No minimum number of satellites:
each Doppler is used as it comes.
"""

import dataclasses

import numpy as np
from scipy import stats

from .. import frames
from ..ins import error_model, strapdown
from ..ins.error_model import DPOS, DV, EPS, NABLA, PHI
from ..positioning.dop import doppler_jacobian
from . import kalman
from .loose import FusionResult, _pos_jacobian, initial_covariance

__all__ = ["DopplerPriors", "DopplerMeasurements", "run", "DROP_AFTER_S"]

#: A satellite's states are dropped this long after its last measurement.
DROP_AFTER_S = 30.0
#: Single Doppler innovations beyond this chi-square(1) quantile are not used
#: (a wrong comb hypothesis is off by tens of Hz); 1 - 1e-6 is 4.9 sigma.
GATE_PROBABILITY = 1.0 - 1e-6
_N_INS = 15
_T = 15  # index of the receiver offset


@dataclasses.dataclass(frozen=True)
class DopplerPriors:
    """What the receiver knows about the Doppler errors.

    ``sat_offset_mean_hz``/``sat_offset_sigma_hz``: prior of each satellite's
    offset (uniform in [0, max]: mean max/2, sigma max/sqrt(12));
    ``orbit_sigma_m``: orbit error per ECEF axis; ``rx_offset_sigma_hz``:
    prior of the receiver offset; ``rx_offset_psd_hz2_per_s``: its random walk.
    """

    sat_offset_mean_hz: float
    sat_offset_sigma_hz: float
    orbit_sigma_m: float
    rx_offset_sigma_hz: float = 10.0
    rx_offset_psd_hz2_per_s: float = 1e-6
    carrier_hz: float = 11.325e9


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
    """

    epoch_index: np.ndarray
    sat_index: np.ndarray
    doppler_hz: np.ndarray
    sigma_hz: np.ndarray
    pos_sv_ecef_m: np.ndarray
    vel_sv_ecef_mps: np.ndarray


class _Satellites:
    """Bookkeeping of the per-satellite states: 4 per satellite after the 16 common ones."""

    def __init__(self):
        self.ids = []
        self.last_seen = []

    def column(self, j):
        return _N_INS + 1 + 4 * self.ids.index(j)

    def add(self, x_hat, P, j, t_s, priors):
        """Append satellite j's states with their prior; returns the grown (x_hat, P)."""
        self.ids.append(j)
        self.last_seen.append(t_s)
        n = P.shape[0]
        P_new = np.zeros((n + 4, n + 4))
        P_new[:n, :n] = P
        P_new[n, n] = priors.sat_offset_sigma_hz**2
        P_new[n + 1:, n + 1:] = np.eye(3) * max(priors.orbit_sigma_m, 1e-3) ** 2
        return np.concatenate([x_hat, [priors.sat_offset_mean_hz, 0.0, 0.0, 0.0]]), P_new

    def drop_stale(self, x_hat, P, t_s):
        """Remove satellites not seen for DROP_AFTER_S; returns (x_hat, P)."""
        keep_sat = [t_s - seen <= DROP_AFTER_S for seen in self.last_seen]
        if all(keep_sat):
            return x_hat, P
        keep = np.ones(P.shape[0], dtype=bool)
        for i, k in enumerate(keep_sat):
            if not k:
                keep[_N_INS + 1 + 4 * i: _N_INS + 5 + 4 * i] = False
        self.ids = [j for j, k in zip(self.ids, keep_sat) if k]
        self.last_seen = [s for s, k in zip(self.last_seen, keep_sat) if k]
        return x_hat[keep], P[np.ix_(keep, keep)]


def _rows(state, x_hat, cols, meas, rows, carrier_hz):
    """Innovations and their Jacobian for measurement ``rows`` of one epoch."""
    lat, lon, alt = state.lat_rad, state.lon_rad, state.alt_m
    C = frames.C_e_n(lat, lon)
    r_rx = frames.geodetic_to_ecef(lat, lon, alt)
    v_rx = C @ state.vel_enu_mps
    orbit = np.array([x_hat[c + 1: c + 4] for c in cols])
    r_sv = meas.pos_sv_ecef_m[rows] - orbit
    v_sv = meas.vel_sv_ecef_mps[rows]
    J = doppler_jacobian(r_sv, v_sv, r_rx, v_rx, carrier_hz)
    offsets = np.array([x_hat[c] for c in cols])
    predicted = np.einsum("mi,mi->m", J[:, 3:6], v_rx - v_sv) + x_hat[_T] + offsets
    # The ECEF velocity C_e_n v_enu also moves with the position through the
    # frame's rotation (dv_ecef/dlat, dv_ecef/dlon): 3e-4 m/s per 10 m at 200 m/s.
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    dC_dlat = np.array([[0.0, -cl * co, -sl * co], [0.0, -cl * so, -sl * so], [0.0, -sl, cl]])
    dC_dlon = np.array([[-co, sl * so, -cl * so], [-so, -sl * co, cl * co], [0.0, 0.0, 0.0]])
    dv_dpos = np.column_stack([dC_dlat @ state.vel_enu_mps, dC_dlon @ state.vel_enu_mps, np.zeros(3)])
    H = np.zeros((len(rows), x_hat.size))
    H[:, DV] = -J[:, 3:6] @ C
    H[:, DPOS] = -J[:, 0:3] @ C @ _pos_jacobian(lat, alt) - J[:, 3:6] @ dv_dpos
    H[:, _T] = 1.0
    for i, c in enumerate(cols):
        H[i, c] = 1.0
        H[i, c + 1: c + 4] = J[i, 0:3]
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
    settings : leosop.fusion.loose.FilterSettings
        INS priors and noise, step and correction period (gating always on).
    n_epochs : int
    progress : callable, optional

    Returns
    -------
    leosop.fusion.loose.FusionResult
        ``innovation`` and ``innovation_cov`` are None, ``doppler_innovation``
        holds each Doppler's normalised innovation; ``nis_dof`` is the number
        of Doppler measurements of each update.
    """
    per_step = int(round(settings.step_s / dt_s))
    if per_step < 2 or per_step % 2 or abs(per_step * dt_s - settings.step_s) > 1e-9:
        raise ValueError(f"step_s={settings.step_s} must be an even multiple of dt_s={dt_s}")
    n = min(n_epochs, dtheta_b_rad.shape[0] // per_step + 1)
    Qc = np.concatenate([np.full(3, settings.gyro_arw_rad_per_rt_s**2),
                         np.full(3, settings.accel_vrw_mps2_per_rt_hz**2)])
    gate = stats.chi2.ppf(GATE_PROBABILITY, 1)
    bounds = np.searchsorted(measurements.epoch_index, np.arange(n + 1))

    out = {k: np.full(shape, np.nan) for k, shape in (
        ("lat", (n,)), ("lon", (n,)), ("alt", (n,)), ("vel", (n, 3)), ("C", (n, 3, 3)), ("P", (n, 15, 15)),
        ("nis", (n,)), ("eps", (n, 3)), ("nabla", (n, 3)))}
    dof = np.zeros(n, dtype=int)
    records = []
    updated = np.zeros(n, dtype=bool)
    rejected = np.zeros(n, dtype=bool)
    state = state0
    P = np.zeros((_N_INS + 1, _N_INS + 1))
    P[:_N_INS, :_N_INS] = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    P[_T, _T] = priors.rx_offset_sigma_hz**2
    x_hat = np.zeros(_N_INS + 1)  # only the non-INS entries are used: T_u, then per satellite
    sats = _Satellites()
    eps = np.zeros(3)
    nabla = np.zeros(3)
    last_update_s = 0.0  # corrections at P, 2P, ... (or the first fix after)
    epochs = range(n) if progress is None else progress(range(n))
    for k in epochs:
        t_s = k * settings.step_s
        if k > 0:
            sl = slice((k - 1) * per_step, k * per_step)
            dth = dtheta_b_rad[sl] - eps * dt_s
            dvl = dvel_b_mps[sl] - nabla * dt_s
            C0 = state.C_n_b
            f_n = C0 @ (dvl.sum(axis=0) / settings.step_s)
            F, G = error_model.model15(C0, f_n, state.vel_enu_mps, state.lat_rad, state.alt_m)
            # Second-order series: the modes of F (Schuler, Earth rate, vertical) are
            # below 2e-3 rad/s, so at 1 s the terms left out are ~1e-6 of those kept
            # (and Van Loan's matrix exponential costs 8x more per step).
            Phi, Qd = error_model.discretize(F, G, Qc, settings.step_s, method="series")
            P[:_N_INS, :] = Phi @ P[:_N_INS, :]
            P[:, :_N_INS] = P[:, :_N_INS] @ Phi.T
            P[:_N_INS, :_N_INS] += Qd
            P[_T, _T] += priors.rx_offset_psd_hz2_per_s * settings.step_s
            P = 0.5 * (P + P.T)
            state = strapdown.integrate(state, dth, dvl, dt_s, out_every=per_step // 2).state(-1)
        rows = np.arange(bounds[k], bounds[k + 1])
        rows = rows[np.isfinite(measurements.doppler_hz[rows]) & (measurements.sigma_hz[rows] > 0)]
        x_hat, P = sats.drop_stale(x_hat, P, t_s)
        for j in measurements.sat_index[rows]:
            if j not in sats.ids:
                x_hat, P = sats.add(x_hat, P, int(j), t_s, priors)
            sats.last_seen[sats.ids.index(j)] = t_s
        due = t_s - last_update_s >= settings.correction_period_s - 1e-9
        if k > 0 and due and rows.size:
            cols = [sats.column(j) for j in measurements.sat_index[rows]]
            y, H = _rows(state, x_hat, cols, measurements, rows, priors.carrier_hz)
            R = np.diag(measurements.sigma_hz[rows] ** 2)
            S_diag = np.einsum("ij,jk,ik->i", H, P, H) + np.diag(R)
            ok = y**2 / S_diag <= gate
            rejected[k] = not ok.all()
            if ok.any():
                x, P, y_used, S = kalman.update(np.zeros(P.shape[0]), P, y[ok], H[ok], R[np.ix_(ok, ok)])
                state = state.corrected(x[PHI], x[DV], x[DPOS])
                eps = eps + x[EPS]
                nabla = nabla + x[NABLA]
                x_hat[_N_INS:] += x[_N_INS:]
                updated[k] = True
                last_update_s = t_s
                out["nis"][k] = kalman.nis(y_used, S)
                dof[k] = int(ok.sum())
                for j, v in zip(measurements.sat_index[rows][ok], y_used / np.sqrt(np.diag(S))):
                    records.append((k, j, v))
        out["lat"][k], out["lon"][k], out["alt"][k] = state.lat_rad, state.lon_rad, state.alt_m
        out["vel"][k], out["C"][k], out["P"][k] = state.vel_enu_mps, state.C_n_b, P[:_N_INS, :_N_INS]
        out["eps"][k], out["nabla"][k] = eps, nabla
    innovations = np.array(records, dtype=[("epoch", int), ("sat", int), ("normalized", float)])
    return FusionResult(np.arange(n) * settings.step_s, out["lat"], out["lon"], out["alt"], out["vel"], out["C"],
                        out["P"], updated, rejected, out["nis"], dof, out["eps"], out["nabla"],
                        doppler_innovation=innovations)
