"""Loosely coupled INS / LEO-fix EKF (seed 004 eq. 13-16) with feedback correction.

State: the 15 INS errors of :mod:`leosop.ins.error_model` (``phi``, ``dv``
ENU, ``[dlat, dlon, dalt]``, gyro drift, accelerometer bias). Measurement:
INS minus LEO fix, velocity then position, 6 values in ENU metres (the
position rows of ``H`` carry the radii that turn ``dlat, dlon`` into metres).
``R`` is the covariance of the fix's white errors, rotated into ENU.

Time-correlated fix errors. A snapshot fix is ``x_true + G_k e_k`` to first
order, ``G_k`` the least-squares gain of epoch k and ``e_k`` the Doppler
errors of its satellites: constant clock-induced offsets (seed 004 Table 1,
uniform 0-5 Hz), constant orbit errors and white estimator noise. Measured on
10 seeds of the xian-baoji flight (measurement level, 7,468 fixes): the fix
error has NEES/6 = 1.02 against the fix covariance, but its lag-1 correlation
is 0.58 (0.20 at 10 s, ~0 at 30 s), with jumps when the satellite set
changes (every 8 s on average; median 18 m, 90th percentile 95 m, against
12 m between epochs with the same set); its systematic part ``G_k (o + h.dr)``
(median 18 m, 0.38 m/s) exceeds the white part (9 m, 0.19 m/s). The
decomposition is exact: what is left has NEES/6 = 1.00 against
``G_k diag(sigma_noise^2) G_k^T`` (except 5 fixes km off at GDOP > 500). The
error is not stationary, so no decaying random error fits it. Treating
it as white gave NEES/6 = 28; a Schmidt (consider) treatment of the offsets
and orbit errors gives NEES/6 = 0.98 but 5.3 m and 0.057 m/s (5 seeds);
estimating them as states gives NEES/6 = 1.0 with 2.2 m and 0.026 m/s (20 seeds:
2.17 m, 0.026 m/s, NEES/6 0.98, NIS/dof 1.004, lag-1 correlation -0.002), so
that is what this filter does when given a :class:`FixErrorModel`: each
satellite in a fix adds a constant offset state (and three orbit-error
states, or three shared by all satellites for a common orbit shift), which
enter the measurement through the fix's gain; they are marginalised
:data:`DROP_AFTER_S` after the last fix that included them. The filter stays
loose: one 6-value fix difference per update, no Doppler.

After every update the estimated INS errors are fed back: the INS state is
corrected (:meth:`NavState.corrected`), the bias estimates are accumulated
and removed from later IMU increments, and the INS error state returns to
zero (the satellite error estimates are kept). The INS runs at the IMU
rate; the filter predicts every ``step_s`` (1 s) and updates every
``correction_period_s`` when a fix exists. When no fix exists (fewer than 7
satellites) the INS carries the solution and the filter resumes at the next
fix, so every epoch has an output.
"""

import dataclasses

import numpy as np
from scipy import stats

from .. import earth, frames
from ..ins import error_model, strapdown
from ..ins.error_model import DPOS, DV, EPS, NABLA, PHI
from . import kalman

__all__ = ["FilterSettings", "FusionResult", "FixErrorModel", "ORBIT_MODELS", "measurement", "initial_covariance",
           "run", "DROP_AFTER_S"]

#: Innovations whose NIS exceeds this chi-square(6) quantile are rejected
#: (a wrong Doppler peak can give a fix hundreds of metres off); at 1 - 1e-6
#: a consistent filter loses one good fix in a million.
GATE_PROBABILITY = 1.0 - 1e-6
#: A satellite's error states are dropped this long after the last fix that included it.
DROP_AFTER_S = 30.0
#: How the satellites' orbit errors are related: each its own, or one shift of all.
ORBIT_MODELS = ("independent", "common")
_N_INS = 15


@dataclasses.dataclass(frozen=True)
class FilterSettings:
    """Filter tuning, in the units the names carry.

    ``pos_sigma_m``, ``vel_sigma_mps``: initial uncertainty per ENU axis;
    ``att_sigma_rad``: initial attitude uncertainty (E, N, U); ``gyro_bias_*``
    and ``accel_bias_*``: initial bias uncertainty and white-noise densities.
    """

    pos_sigma_m: tuple
    vel_sigma_mps: tuple
    att_sigma_rad: tuple
    gyro_bias_sigma_rad_per_s: float
    accel_bias_sigma_mps2: float
    gyro_arw_rad_per_rt_s: float
    accel_vrw_mps2_per_rt_hz: float
    correction_period_s: float = 1.0
    step_s: float = 1.0
    gate: bool = True


@dataclasses.dataclass(frozen=True)
class FusionResult:
    """Filter output at every step epoch (n epochs, the first is the initial state).

    Attributes
    ----------
    t_s : ndarray, (n,)
    lat_rad, lon_rad, alt_m : ndarray, (n,)
    vel_enu_mps : ndarray, (n, 3)
    C_n_b : ndarray, (n, 3, 3)
    P : ndarray, (n, 15, 15)
        Covariance of the remaining INS errors (after feedback).
    updated : ndarray of bool, (n,)
        An update was made at this epoch.
    rejected : ndarray of bool, (n,)
        A fix was offered but failed the innovation gate.
    nis : ndarray, (n,)
        Normalised innovation squared of each update, NaN elsewhere.
    nis_dof : ndarray of int, (n,)
        Its degrees of freedom (measurements in the update; 0 without one).
    innovation, innovation_cov : ndarray, (n, 6), (n, 6, 6), or None
        Loose coupling: ``z - H x`` (velocity [m/s], position [m] ENU) and
        ``S`` at updates, NaN elsewhere; None for tight coupling.
    doppler_innovation : structured ndarray or None
        Tight coupling: one row per Doppler used, fields ``epoch``, ``sat``
        and ``normalized`` (innovation over the square root of its variance
        in ``S``); None for loose coupling.
    gyro_bias_rad_per_s, accel_bias_mps2 : ndarray, (n, 3)
        Accumulated bias estimates.
    """

    t_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    alt_m: np.ndarray
    vel_enu_mps: np.ndarray
    C_n_b: np.ndarray
    P: np.ndarray
    updated: np.ndarray
    rejected: np.ndarray
    nis: np.ndarray
    nis_dof: np.ndarray
    gyro_bias_rad_per_s: np.ndarray
    accel_bias_mps2: np.ndarray
    innovation: np.ndarray | None = None
    innovation_cov: np.ndarray | None = None
    doppler_innovation: np.ndarray | None = None

    @property
    def pos_ecef_m(self):
        """ECEF position, (n, 3)."""
        return frames.geodetic_to_ecef(self.lat_rad, self.lon_rad, self.alt_m)

    def pos_vel_cov_enu(self):
        """Covariance of ``[dv_enu, dpos_enu]`` in m/s and m, (n, 6, 6)."""
        D = np.zeros((self.t_s.size, 6, 15))
        D[:, 0:3, DV] = np.eye(3)
        D[:, 3:6, DPOS] = _pos_jacobian(self.lat_rad, self.alt_m)
        return D @ self.P @ np.swapaxes(D, 1, 2)


@dataclasses.dataclass(frozen=True)
class FixErrorModel:
    """The satellites' constant errors behind the fixes and each fix's least-squares gain.

    A snapshot fix is ``x = x_true + G e`` to first order, with ``G`` the
    weighted least-squares gain of its epoch and ``e`` the Doppler errors of
    the satellites it used: ``e_j = o_j + h_j . dr_j + n_j`` (clock-induced
    offset, orbit error ``dr_j`` seen through the Doppler's sensitivity ``h_j``
    to the satellite's position, white estimator noise). One row per
    satellite-epoch pair used in a fix, sorted by epoch.

    Attributes
    ----------
    epoch_index, sat_index : ndarray of int, (m,)
    gain_ecef : ndarray, (m, 6)
        The pair's column of ``G``: d[pos, vel] (ECEF) / d(Doppler) [m/Hz, m/s/Hz].
    orbit_hz_per_m : ndarray, (m, 3)
        ``h_j``: d(Doppler error)/d(orbit error, ECEF) [Hz/m].
    offset_sigma_hz, orbit_sigma_m : float
        Prior of each offset about the common mean (which the fix's receiver
        offset absorbs) and of the orbit error per axis.
    orbit_model : {"independent", "common"}
        One orbit error per satellite, or one shift shared by all.
    """

    epoch_index: np.ndarray
    sat_index: np.ndarray
    gain_ecef: np.ndarray
    orbit_hz_per_m: np.ndarray
    offset_sigma_hz: float
    orbit_sigma_m: float
    orbit_model: str = "independent"


class _Satellites:
    """Bookkeeping of the satellite error states after the INS (and common orbit) states."""

    def __init__(self, orbit_model, offset_sigma_hz, orbit_sigma_m):
        self.per_sat = 4 if orbit_model == "independent" else 1
        self.first = _N_INS + (0 if orbit_model == "independent" else 3)
        self.offset_var = offset_sigma_hz**2
        self.orbit_var = max(orbit_sigma_m, 1e-3) ** 2
        self.ids = []
        self.last_seen = []

    def initial(self, P):
        """Grow the INS covariance by the common orbit states, if any."""
        n = self.first
        P_new = np.zeros((n, n))
        P_new[:_N_INS, :_N_INS] = P
        P_new[_N_INS:, _N_INS:] = np.eye(n - _N_INS) * self.orbit_var
        return np.zeros(n), P_new

    def columns(self, j):
        """Offset column and orbit columns of satellite j."""
        c = self.first + self.per_sat * self.ids.index(j)
        return c, (slice(c + 1, c + 4) if self.per_sat == 4 else slice(_N_INS, _N_INS + 3))

    def add(self, x_hat, P, j, t_s):
        self.ids.append(j)
        self.last_seen.append(t_s)
        n = P.shape[0]
        P_new = np.zeros((n + self.per_sat, n + self.per_sat))
        P_new[:n, :n] = P
        P_new[n, n] = self.offset_var
        P_new[n + 1:, n + 1:] = np.eye(self.per_sat - 1) * self.orbit_var
        return np.concatenate([x_hat, np.zeros(self.per_sat)]), P_new

    def drop_stale(self, x_hat, P, t_s):
        """Marginalise satellites in no fix for DROP_AFTER_S (they have set)."""
        keep_sat = [t_s - t <= DROP_AFTER_S for t in self.last_seen]
        if all(keep_sat):
            return x_hat, P
        keep = np.ones(P.shape[0], dtype=bool)
        for i, k in enumerate(keep_sat):
            keep[self.first + self.per_sat * i: self.first + self.per_sat * (i + 1)] = k
        self.ids = [j for j, k in zip(self.ids, keep_sat) if k]
        self.last_seen = [t for t, k in zip(self.last_seen, keep_sat) if k]
        return x_hat[keep], P[np.ix_(keep, keep)]


def _pos_jacobian(lat_rad, alt_m):
    """d(ENU metres)/d[dlat, dlon, dalt], shape (..., 3, 3)."""
    lat = np.asarray(lat_rad, dtype=float)
    R_M, R_N = earth.radii_m(lat)
    J = np.zeros(lat.shape + (3, 3))
    J[..., 0, 1] = (R_N + alt_m) * np.cos(lat)
    J[..., 1, 0] = R_M + alt_m
    J[..., 2, 2] = 1.0
    return J


def initial_covariance(settings, lat_rad, alt_m):
    """Initial 15 x 15 covariance of the INS errors (position in rad, rad, m)."""
    J_inv = np.linalg.inv(_pos_jacobian(lat_rad, alt_m))
    P = np.zeros((15, 15))
    P[PHI, PHI] = np.diag(np.square(settings.att_sigma_rad))
    P[DV, DV] = np.diag(np.square(settings.vel_sigma_mps))
    P[DPOS, DPOS] = J_inv @ np.diag(np.square(settings.pos_sigma_m)) @ J_inv.T
    P[EPS, EPS] = np.eye(3) * settings.gyro_bias_sigma_rad_per_s**2
    P[NABLA, NABLA] = np.eye(3) * settings.accel_bias_sigma_mps2**2
    return P


def _enu_from_ecef_pv(lat_rad, lon_rad):
    """``T`` mapping ECEF ``[pos, vel]`` to ENU ``[vel, pos]``, (6, 6)."""
    C_n_e = frames.C_e_n(lat_rad, lon_rad).T
    T = np.zeros((6, 6))
    T[0:3, 3:6] = C_n_e
    T[3:6, 0:3] = C_n_e
    return T


def measurement(state, pos_fix_ecef_m, vel_fix_ecef_mps, cov_fix_pv_ecef):
    """INS-minus-fix measurement of seed 004 eq. 13.

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
    lat, lon, alt = state.lat_rad, state.lon_rad, state.alt_m
    C_n_e = frames.C_e_n(lat, lon).T
    pos_ins = frames.geodetic_to_ecef(lat, lon, alt)
    z = np.concatenate([state.vel_enu_mps - C_n_e @ vel_fix_ecef_mps, C_n_e @ (pos_ins - pos_fix_ecef_m)])
    H = np.zeros((6, 15))
    H[0:3, DV] = np.eye(3)
    H[3:6, DPOS] = _pos_jacobian(lat, alt)
    T = _enu_from_ecef_pv(lat, lon)
    return z, H, T @ np.asarray(cov_fix_pv_ecef) @ T.T


def _satellite_rows(state, sats, model, rows, n_states):
    """Columns of the measurement matrix for the satellite error states, (6, n_states).

    The fix error ``G e`` enters ``z = INS - fix`` with a minus sign.
    """
    T = _enu_from_ecef_pv(state.lat_rad, state.lon_rad)
    M = np.zeros((6, n_states))
    for r in rows:
        g = -T @ model.gain_ecef[r]
        c_off, c_orbit = sats.columns(int(model.sat_index[r]))
        M[:, c_off] += g
        M[:, c_orbit] += np.outer(g, model.orbit_hz_per_m[r])
    return M


def run(state0, dtheta_b_rad, dvel_b_mps, dt_s, fixes, settings, *, fix_errors=None, progress=None):
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
        ``cov_pv`` is the covariance of the fix errors that are white in time
        (all of them when ``fix_errors`` is None).
    settings : FilterSettings
    fix_errors : FixErrorModel, optional
        The satellites' constant errors behind the fixes, estimated as
        states (module docstring); None treats the fix errors as white.
    progress : callable, optional
        Wraps the epoch iterator (e.g. :func:`leosop.progress.progress`).

    Returns
    -------
    FusionResult
    """
    pos_fix, vel_fix, cov_fix = fixes
    per_step = int(round(settings.step_s / dt_s))
    if per_step < 2 or per_step % 2 or abs(per_step * dt_s - settings.step_s) > 1e-9:
        raise ValueError(f"step_s={settings.step_s} must be an even multiple of dt_s={dt_s}")
    n = min(len(pos_fix), dtheta_b_rad.shape[0] // per_step + 1)
    Qc = np.concatenate([np.full(3, settings.gyro_arw_rad_per_rt_s**2),
                         np.full(3, settings.accel_vrw_mps2_per_rt_hz**2)])
    gate = stats.chi2.ppf(GATE_PROBABILITY, 6) if settings.gate else np.inf

    out = {k: np.full(shape, np.nan) for k, shape in (
        ("lat", (n,)), ("lon", (n,)), ("alt", (n,)), ("vel", (n, 3)), ("C", (n, 3, 3)), ("P", (n, 15, 15)),
        ("y", (n, 6)), ("S", (n, 6, 6)), ("nis", (n,)), ("eps", (n, 3)), ("nabla", (n, 3)))}
    updated = np.zeros(n, dtype=bool)
    rejected = np.zeros(n, dtype=bool)
    state = state0
    P = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    x_hat = np.zeros(_N_INS)  # only the satellite error states are kept (the INS errors are fed back)
    if fix_errors is not None:
        sats = _Satellites(fix_errors.orbit_model, fix_errors.offset_sigma_hz, fix_errors.orbit_sigma_m)
        x_hat, P = sats.initial(P)
        bounds = np.searchsorted(fix_errors.epoch_index, np.arange(n + 1))
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
            # The satellite error states are constant: only the INS block moves.
            P[:_N_INS, :] = Phi @ P[:_N_INS, :]
            P[:, :_N_INS] = P[:, :_N_INS] @ Phi.T
            P[:_N_INS, :_N_INS] += Qd
            P = 0.5 * (P + P.T)
            hist = strapdown.integrate(state, dth, dvl, dt_s, out_every=per_step // 2)
            state = hist.state(-1)
        have_fix = k > 0 and np.all(np.isfinite(pos_fix[k]))
        if fix_errors is not None and have_fix:
            # Bookkeeping at every fix, also between corrections, so that a
            # satellite keeps its states while it stays in view.
            rows = range(bounds[k], bounds[k + 1])
            x_hat, P = sats.drop_stale(x_hat, P, t_s)
            for j in fix_errors.sat_index[rows]:
                if int(j) not in sats.ids:
                    x_hat, P = sats.add(x_hat, P, int(j), t_s)
                sats.last_seen[sats.ids.index(int(j))] = t_s
        due = t_s - last_update_s >= settings.correction_period_s - 1e-9
        if have_fix and due:
            z, H, R = measurement(state, pos_fix[k], vel_fix[k], cov_fix[k])
            if fix_errors is not None:
                H = np.hstack([H, _satellite_rows(state, sats, fix_errors, rows, P.shape[0])[:, _N_INS:]])
            x, P_post, y, S = kalman.update(x_hat, P, z, H, R)
            nis = kalman.nis(y, S)
            if nis <= gate:
                P = P_post
                dx = x - x_hat
                state = state.corrected(dx[PHI], dx[DV], dx[DPOS])
                eps = eps + dx[EPS]
                nabla = nabla + dx[NABLA]
                x_hat = np.concatenate([np.zeros(_N_INS), x[_N_INS:]])
                updated[k] = True
                last_update_s = t_s
                out["y"][k], out["S"][k], out["nis"][k] = y, S, nis
            else:
                rejected[k] = True
        out["lat"][k], out["lon"][k], out["alt"][k] = state.lat_rad, state.lon_rad, state.alt_m
        out["vel"][k], out["C"][k], out["P"][k] = state.vel_enu_mps, state.C_n_b, P[:_N_INS, :_N_INS]
        out["eps"][k], out["nabla"][k] = eps, nabla
    return FusionResult(np.arange(n) * settings.step_s, out["lat"], out["lon"], out["alt"], out["vel"], out["C"],
                        out["P"], updated, rejected, out["nis"], np.where(updated, 6, 0), out["eps"], out["nabla"],
                        out["y"], out["S"])
