"""LEO Doppler aids (tight coupling) for the engine: one aid per satellite measurement.

Measurement of satellite j, constellation g (the toolkit's Doppler sign)::

    doppler_j = -(f0_j / c) (v_s - v_a) . (r_s - r_a) / |r_s - r_a| + T_u[g] + o_j + noise,

with the antenna ``r_a = r + C_e_n C_n_b l`` and ``v_a = C_e_n (v + C_n_b
(omega x l))`` (lever arm ``l`` in the body frame, as the GNSS aids), the
satellite state as given (CSV columns, or propagated from element sets),
``T_u[g]`` the receiver's frequency offset of constellation g (a state
block, with or without its drift, each family received by its own chain) and
``o_j`` the satellite's clock-induced offset (a block per satellite, a slow
random walk that may also take the slowly varying Doppler of an orbit error;
dropped :data:`SAT_DROP_AFTER_S` after the satellite was last seen).
Optionally the satellite position carries an estimated constant orbit error
``dr`` (ECEF, m; [Shen 2024] Table 1): the satellite is believed at
``r_s - dr``, with ``dr`` a block of three states per satellite
(``orbit_model="independent"``) or one shift shared by all
(``"common"``, [Shen 2024] Table 6's [E, E, E]). The rows are those of
:func:`leosop.geometry.doppler.doppler_jacobian` chained to the INS errors;
``tests/fusion/test_aids_leo.py`` checks them against finite differences.

Integration window (``LeoOptions.window_s = T``): a Doppler estimated over
``T`` seconds measures the antenna's mean velocity over them, the chord
``(r_a(t + T/2) - r_a(t - T/2)) / T``, not its velocity at ``t`` (a car
rocking in roll at 2 Hz moves its antenna by 0.1-0.3 m/s about a mean
that a 1 s integration sees steady; docs/fusion-real.md). The aid is then
applied at the window's end ``t + T/2`` with the chord in place of
``v_a`` and the midpoint in place of ``r_a``; the start ``r_a(t - T/2)`` is
a cloned block ([Roumeliotis 2002], stochastic cloning) that
:class:`LeoWindowStart` makes at ``t - T/2``: the antenna position's
estimate and its error's covariance with the whole state, carried
unchanged (no noise) to the window's end and corrected by every update
in between through that covariance. The satellite state stays the one at
``t``.
"""

import dataclasses

import numpy as np

from .. import frames
from ..constants import C_MPS
from ..geometry.doppler import doppler_jacobian
from ..ins.error_model import DPOS, DV, EPS, PHI
from ..rotations import skew
from .aids import Aid, StateBlock
from .common import DROP_AFTER_S, N_INS, ORBIT_MODELS, pos_jacobian

__all__ = ["SAT_DROP_AFTER_S", "LeoDoppler", "LeoOptions", "LeoWindowStart", "leo_aids"]

#: A satellite's offset state is dropped this long after its last Doppler [s] (as the tight filter's).
SAT_DROP_AFTER_S = DROP_AFTER_S


@dataclasses.dataclass(frozen=True)
class LeoOptions:
    """Priors and noise of the LEO Doppler aids.

    ``rx_offset_sigma_hz``: prior of each receiver frequency offset (a real
    receiver's oscillator may be kHz off at 11 GHz; the first Doppler of a
    constellation settles it); ``rx_drift_sigma_hz_per_s`` its drift's prior
    (None: no drift state, the offset is a random walk alone);
    ``rx_offset_psd_hz2_per_s`` and ``rx_drift_psd_hz2_per_s3`` their random
    walks; ``sat_offset_sigma_hz`` each satellite's offset about the
    receiver's (simulate's offsets, uniform in [0, 5 Hz]: 5 / sqrt(12)) and
    ``sat_offset_psd_hz2_per_s`` its random walk (an orbit error of 1 m moves
    a Doppler by ~0.4 Hz over a pass of minutes); ``default_sigma_hz`` the
    noise of a row without ``sigma_hz``; ``orbit_sigma_m`` the prior of the
    orbit error per ECEF axis (None: no orbit states) and ``orbit_model``
    whether each satellite has its own (``"independent"``) or all share one
    (``"common"``); ``window_s`` the Doppler's integration time (the
    module's window model; None: the velocity at the row's time).
    """

    rx_offset_sigma_hz: float = 1000.0
    rx_drift_sigma_hz_per_s: float = 1.0
    rx_offset_psd_hz2_per_s: float = 1e-6
    rx_drift_psd_hz2_per_s3: float = 1e-6
    sat_offset_sigma_hz: float = 5.0 / np.sqrt(12.0)
    sat_offset_psd_hz2_per_s: float = 2e-3
    default_sigma_hz: float = 1.0
    orbit_sigma_m: float | None = None
    orbit_model: str = "independent"
    window_s: float | None = None


def _antenna(ins, lever_arm_b_m):
    """``C_e_n``, ``C_n_b``, lever arm and its rotation velocity (ENU), antenna position and velocity (ECEF), as a
    tuple; the lever terms are None without a lever arm."""
    s = ins.state
    C = frames.C_e_n(s.lat_rad, s.lon_rad)
    r = frames.geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m)
    v_n = s.vel_enu_mps
    C_n_b = l_n = w_n = None
    if lever_arm_b_m.any():
        C_n_b = s.C_n_b
        l_n = C_n_b @ lever_arm_b_m
        w_n = C_n_b @ np.cross(ins.omega_ib_b_rad_per_s, lever_arm_b_m)
        r, v_n = r + C @ l_n, v_n + w_n
    return C, C_n_b, l_n, w_n, r, C @ v_n


def _frame_turn(lat_rad):
    """``M`` (3, 3): a position change [dlat, dlon, dalt] turns the ENU frame by ``M dpos`` = (-dlat, dlon cos
    lat, dlon sin lat), so ``C_e_n x`` moves by ``-C_e_n [x x] M dpos`` for any ENU vector x (velocity, lever arm)."""
    M = np.zeros((3, 3))
    M[0, 0], M[1, 1], M[2, 1] = -1.0, np.cos(lat_rad), np.sin(lat_rad)
    return M


def _antenna_jacobian(ins, C, l_n):
    """``dr_a / dx`` (3, 15): the antenna position (ECEF) over the INS errors; ``l_n`` None without a lever arm."""
    s = ins.state
    G = np.zeros((3, N_INS))
    G[:, DPOS] = C @ pos_jacobian(s.lat_rad, s.alt_m)
    if l_n is not None:
        G[:, DPOS] -= C @ skew(l_n) @ _frame_turn(s.lat_rad)
        G[:, PHI] = C @ skew(l_n)
    return G


class LeoWindowStart(Aid):
    """The start of a LEO Doppler integration window: clones the antenna position (ECEF, m) into ``clone``.

    Parameters
    ----------
    t_s : float
        On the aids' clock.
    lever_arm_b_m : array_like, (3,)
    clone : StateBlock
        3 states, ``cloned``; named by the window's :class:`LeoDoppler` aids.
    """

    name = "leo_window"
    external_clock = True
    gated = False
    clones = True

    def __init__(self, t_s, lever_arm_b_m, clone):
        super().__init__(t_s)
        self.lever_arm_b_m = np.asarray(lever_arm_b_m, dtype=float).reshape(3)
        self.states = (clone,)

    def clone_rows(self, ins):
        C, _, l_n, _, r, _ = _antenna(ins, self.lever_arm_b_m)
        return r, _antenna_jacobian(ins, C, l_n)


class LeoDoppler(Aid):
    """One satellite's Doppler [Hz] at the GNSS antenna (the module's model).

    Parameters
    ----------
    t_s : float
        On the aids' clock.
    doppler_hz, sigma_hz, carrier_hz : float
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (3,)
        Satellite state at ``t_s`` (ECEF).
    lever_arm_b_m : array_like, (3,)
        Antenna minus IMU in the body frame (Right-Forward-Up).
    clock : StateBlock
        The receiver's offset of the satellite's constellation (state 0; a
        drift, if any, reaches the measurement through the block's transition).
    sat : StateBlock
        The satellite's offset (1 state).
    orbit : StateBlock, optional
        The satellite's orbit error (3 states, ECEF m): the satellite is
        believed at ``pos_sv_ecef_m`` less its estimate.
    window : tuple of (float, StateBlock), optional
        Integration time ``T`` [s] and the antenna position cloned at its
        start by a :class:`LeoWindowStart` (the module's window model;
        ``t_s`` is then the window's end, the satellite state its middle's).
    """

    name = "leo_doppler"
    external_clock = True

    def __init__(self, t_s, doppler_hz, sigma_hz, carrier_hz, pos_sv_ecef_m, vel_sv_ecef_mps, lever_arm_b_m, clock,
                 sat, orbit=None, window=None):
        super().__init__(t_s)
        self.measured = np.array([float(doppler_hz)])
        self.R = np.eye(1) * float(sigma_hz) ** 2
        self.carrier_hz = float(carrier_hz)
        self.pos_sv_ecef_m = np.asarray(pos_sv_ecef_m, dtype=float).reshape(3)
        self.vel_sv_ecef_mps = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(3)
        self.lever_arm_b_m = np.asarray(lever_arm_b_m, dtype=float).reshape(3)
        self.orbit = orbit
        self.window_s, self.clone = (None, None) if window is None else (float(window[0]), window[1])
        self.states = (clock, sat) + tuple(b for b in (orbit, self.clone) if b is not None)
        self._last_geometry = (None, None)

    def _sv_state(self, ins):
        """The satellite as believed: position less the estimated orbit error and velocity (ECEF), (3,) each."""
        if self.orbit is None:
            return self.pos_sv_ecef_m, self.vel_sv_ecef_mps
        return self.pos_sv_ecef_m - ins.states[self.orbit.key], self.vel_sv_ecef_mps

    def _geometry(self, ins):
        """``C_e_n``, ``C_n_b``, lever arm and its rotation velocity (ENU), antenna position and velocity,
        satellite position and velocity (ECEF), as a tuple; the lever terms are None without a lever arm. With a
        window the antenna position is the window's midpoint and the velocity its chord. Kept for the last ``ins``
        (the engine asks :meth:`matrices`, then :meth:`rate`, of one view)."""
        if self._last_geometry[0] is ins:
            return self._last_geometry[1]
        C, C_n_b, l_n, w_n, r, v = _antenna(ins, self.lever_arm_b_m)
        if self.window_s is not None:
            start = ins.states[self.clone.key]
            r, v = 0.5 * (r + start), (r - start) / self.window_s
        g = (C, C_n_b, l_n, w_n, r, v, *self._sv_state(ins))
        self._last_geometry = (ins, g)
        return g

    def _clock_hz(self, ins):
        return ins.states[self.states[0].key][0] + ins.states[self.states[1].key][0]

    def _predict(self, ins, g):
        rate = frames.range_rate(g[6], g[7], g[4], g[5])
        return np.array([-float(rate) * self.carrier_hz / C_MPS + self._clock_hz(ins)])

    def _jacobian(self, g):
        """``dh/dr_a`` and ``dh/dv_a`` (ECEF), (3,) each."""
        J = doppler_jacobian(g[6][None], g[7][None], g[4], g[5], self.carrier_hz)[0]
        return J[:3], J[3:6]

    def predict(self, ins):
        return self._predict(ins, self._geometry(ins))

    def rate(self, ins):
        # With a window: the chord's rate (v(t + T/2) - v(t - T/2)) / T taken as the acceleration at its end.
        g = self._geometry(ins)
        J_r, J_v = self._jacobian(g)
        return np.array([J_r @ g[5] + J_v @ g[0] @ ins.accel_enu_mps2])

    def design(self, ins):
        return self._design(ins, self._geometry(ins))

    def matrices(self, ins):
        g = self._geometry(ins)
        return self._predict(ins, g) - self.measured, self._design(ins, g), self.R

    def _ins_row(self, ins, g):
        """The INS columns of ``H`` (N_INS,) from ``dh/dr_a``, ``dh/dv_a``, and those two, (3,) each (ECEF)."""
        s = ins.state
        C, C_n_b, l_n, w_n = g[:4]
        J_r, J_v = self._jacobian(g)
        row = np.zeros(N_INS)
        if self.window_s is None:
            JC_r, JC_v = J_r @ C, J_v @ C
            M = _frame_turn(s.lat_rad)
            row[DV] = JC_v
            row[DPOS] = JC_r @ pos_jacobian(s.lat_rad, s.alt_m) - JC_v @ skew(s.vel_enu_mps) @ M
            if l_n is not None:
                row[PHI] = JC_r @ skew(l_n) + JC_v @ skew(w_n)
                row[DPOS] -= (JC_r @ skew(l_n) + JC_v @ skew(w_n)) @ M
                row[EPS] = -JC_v @ C_n_b @ skew(self.lever_arm_b_m)
        else:  # r = (r_end + start) / 2, v = (r_end - start) / T: the end through the INS, the start its clone
            row[:] = (0.5 * J_r + J_v / self.window_s) @ _antenna_jacobian(ins, C, l_n)
        return row, J_r, J_v

    def _design(self, ins, g):
        c = N_INS + self.states[0].size  # the satellite's columns
        H = np.zeros((1, c + sum(b.size for b in self.states[1:])))
        H[0, :N_INS], J_r, J_v = self._ins_row(ins, g)
        if self.window_s is not None:
            H[0, -3:] = 0.5 * J_r - J_v / self.window_s
        H[0, N_INS] = 1.0  # receiver offset (a drift enters through the block's transition)
        H[0, c] = 1.0  # satellite offset
        if self.orbit is not None:
            H[0, c + 1:c + 4] = J_r  # the satellite believed at r_s - dr: dh/d(dr) = -dh/d(r_s) = dh/d(r_a)
        return H


def leo_aids(t_s, sat_id, clock_label, doppler_hz, sigma_hz, carrier_hz, pos_sv_ecef_m, vel_sv_ecef_mps,
             lever_arm_b_m, options=None, *, sat_offset_mean_hz=None, sat_offset_sigma_hz=None):
    """One :class:`LeoDoppler` per measurement, sharing the state blocks of each clock and each satellite.

    Parameters
    ----------
    t_s : ndarray, (m,)
        On the aids' clock.
    sat_id, clock_label : array_like of str, (m,)
        Satellite and receiver clock (constellation) of each row.
    doppler_hz, sigma_hz, carrier_hz : ndarray, (m,)
        ``sigma_hz`` NaN: ``options.default_sigma_hz``.
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (m, 3)
    lever_arm_b_m : array_like, (3,)
    options : LeoOptions, optional
    sat_offset_mean_hz, sat_offset_sigma_hz : ndarray, (m,), optional
        Prior of the offset of each row's satellite (its first row's is
        taken); default zero and ``options.sat_offset_sigma_hz``.

    Returns
    -------
    list of LeoDoppler and LeoWindowStart
        Rows with a non-finite Doppler or satellite state are left out. With
        ``options.window_s``: each row's aid at ``t_s + window_s / 2`` and,
        per distinct ``t_s``, a :class:`LeoWindowStart` at ``t_s - window_s / 2``.
    """
    o = options or LeoOptions()
    if o.orbit_model not in ORBIT_MODELS:
        raise ValueError(f"orbit_model {o.orbit_model!r}: expected one of {', '.join(ORBIT_MODELS)}")
    if o.window_s is not None and not o.window_s > 0.0:
        raise ValueError(f"window_s {o.window_s!r}: expected a positive integration time [s] or None")
    m = len(doppler_hz)
    mean = np.zeros(m) if sat_offset_mean_hz is None else np.asarray(sat_offset_mean_hz, dtype=float)
    spread = np.full(m, o.sat_offset_sigma_hz) if sat_offset_sigma_hz is None else np.asarray(sat_offset_sigma_hz)
    clocks, sats, orbits, windows, out = {}, {}, {}, {}, []
    sigma = np.where(np.isfinite(sigma_hz), sigma_hz, o.default_sigma_hz)
    ok = np.isfinite(doppler_hz) & np.isfinite(pos_sv_ecef_m).all(-1) & np.isfinite(vel_sv_ecef_mps).all(-1)
    for k in np.flatnonzero(ok):
        g, j = str(clock_label[k]), str(sat_id[k])
        if g not in clocks:
            clocks[g] = _clock_block(g, o)
        if j not in sats:
            sats[j] = StateBlock(f"leo_sat:{j}", (float(mean[k]),), (float(spread[k]),),
                                 (o.sat_offset_psd_hz2_per_s,), drop_after_s=SAT_DROP_AFTER_S)
        orbit = None
        if o.orbit_sigma_m is not None:
            key = "common" if o.orbit_model == "common" else j
            if key not in orbits:
                orbits[key] = StateBlock(f"leo_orbit:{key}", (0.0,) * 3, (o.orbit_sigma_m,) * 3, (0.0,) * 3,
                                         drop_after_s=None if key == "common" else SAT_DROP_AFTER_S)
            orbit = orbits[key]
        t, window = float(t_s[k]), None
        if o.window_s is not None:
            if t not in windows:
                # Kept until the next window has ended: its aids, due at its end, are then past.
                clone = StateBlock(f"leo_window:{t!r}", (0.0,) * 3, (0.0,) * 3, (0.0,) * 3,
                                   drop_after_s=1.5 * o.window_s, cloned=True)
                windows[t] = clone
                out.append(LeoWindowStart(t - 0.5 * o.window_s, lever_arm_b_m, clone))
            t, window = t + 0.5 * o.window_s, (o.window_s, windows[t])
        out.append(LeoDoppler(t, doppler_hz[k], sigma[k], carrier_hz[k], pos_sv_ecef_m[k], vel_sv_ecef_mps[k],
                              lever_arm_b_m, clocks[g], sats[j], orbit, window))
    return out


def _clock_block(label, o):
    """The receiver offset of clock ``label``: offset and drift, or the offset alone (a random walk)."""
    if o.rx_drift_sigma_hz_per_s is None:
        return StateBlock(f"leo_clock:{label}", (0.0,), (o.rx_offset_sigma_hz,), (o.rx_offset_psd_hz2_per_s,))
    return StateBlock(f"leo_clock:{label}", (0.0, 0.0), (o.rx_offset_sigma_hz, o.rx_drift_sigma_hz_per_s),
                      (o.rx_offset_psd_hz2_per_s, o.rx_drift_psd_hz2_per_s3), integrated=True)
