"""Differential LEO Doppler aids (tight coupling): the rover's Doppler less a base's correction, per satellite.

A base at a known site sees satellite j at the rover's time ``t`` (its
correction interpolated linearly between its rows,
:func:`~leosop.positioning.differential_base.base_corrections`)::

    c_j = y_base - D(b; s_j) = D(b; s_j + e_j) - D(b; s_j) + o_j + T_b + noise,

with ``D(x; s)`` the Doppler the toolkit's sign gives a receiver at rest at
``x`` of a satellite in state ``s`` (position and velocity, ECEF), ``s_j``
the element-set state, ``e_j`` its error, ``o_j`` the satellite's
oscillator and ``T_b`` the base clock. The aid's measurement is the
rover's Doppler less that correction, where ``o_j`` cancels and the orbit
error to first order::

    z_j = y_rover - c_j = D(a; s_j + e_j) - D(b; s_j + e_j) + D(b; s_j) + T(t) + noise,

``a`` the rover's antenna (position and velocity from the INS and the lever
arm, as :class:`~leosop.fusion.aids_leo.LeoDoppler`) and ``T = T_rover -
T_b`` the rover-minus-base frequency offset: one state block, offset and
drift (a drift enters through the block's transition). What is left of the
orbit error, ``[dD(a)/ds - dD(b)/ds] e_j``, grows with the baseline (~1 Hz
for 300 m along-track at 7.5 km, :mod:`~leosop.positioning.differential`);
optionally ``e_j`` is a block of three states per satellite, its radial /
along-track / cross-track offset ``d_j`` in the inertial orbit's frame
(:func:`~leosop.positioning.differential.rtn_frames`: ``e = (C d, W d)``),
with the differential fix's prior. ``R`` is the rover's variance plus the
interpolated base's; rover rows that interpolate one base row share its
noise, which the filter takes as independent (exact when the base is on the
rover's epochs). ``tests/fusion/test_aids_differential.py`` checks ``H`` against
finite differences of this model.

With the accumulated carrier phase in both tables (``phase_cycles``),
:func:`differential_aids` adds the delta-range aids of
:mod:`~leosop.fusion.aids_carrier`, sharing the orbit states.
"""

import dataclasses

import numpy as np

from .. import frames
from ..constants import C_MPS
from ..geometry.doppler import doppler_jacobian
from ..positioning.differential import ORBIT_SIGMA_RTN_M, rtn_frames
from ..positioning.differential_base import MAX_GAP_S, base_corrections, sv_states
from .aids import StateBlock
from .aids_carrier import carrier_aids
from .aids_leo import SAT_DROP_AFTER_S, LeoDoppler
from .common import N_INS

__all__ = ["DifferentialDoppler", "DifferentialOptions", "differential_aids"]


@dataclasses.dataclass(frozen=True)
class DifferentialOptions:
    """Priors and noise of the differential Doppler aids.

    ``clock_offset_sigma_hz`` and ``clock_drift_sigma_hz_per_s``: prior of
    the rover-minus-base frequency offset and its drift (two receivers'
    oscillators, each kHz off at 11 GHz; the first epoch settles the
    offset); ``clock_offset_psd_hz2_per_s`` and ``clock_drift_psd_hz2_per_s3``
    their random walks; ``default_sigma_hz`` the noise of a rover row
    without ``sigma_hz``; ``orbit_sigma_rtn_m`` the prior of each
    satellite's element-set offset, radial / along-track / cross-track [m]
    (None: no orbit states, the residual orbit error left out of the model);
    ``carrier``: add the carrier-phase aids when both tables have phases,
    ``default_phase_sigma_cycles`` the noise of a phase without
    ``phase_sigma_cycles`` (0.1 cycles: 2.6 mm at 11.325 GHz).
    """

    clock_offset_sigma_hz: float = 3000.0
    clock_drift_sigma_hz_per_s: float = 1.5
    clock_offset_psd_hz2_per_s: float = 1e-6
    clock_drift_psd_hz2_per_s3: float = 1e-6
    default_sigma_hz: float = 1.0
    orbit_sigma_rtn_m: tuple | None = ORBIT_SIGMA_RTN_M
    carrier: bool = True
    default_phase_sigma_cycles: float = 0.1


class DifferentialDoppler(LeoDoppler):
    """One satellite's rover Doppler less the base's correction [Hz] (the module's model).

    Parameters
    ----------
    t_s : float
        On the aids' clock.
    z_hz : float
        Rover Doppler minus the base's correction at ``t_s``.
    sigma_hz : float
        Its standard deviation (rover and interpolated base).
    carrier_hz : float
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (3,)
        The satellite's element-set state at ``t_s`` (ECEF).
    base_pos_ecef_m : array_like, (3,)
        The base's known site.
    lever_arm_b_m : array_like, (3,)
        Antenna minus IMU in the body frame (Right-Forward-Up).
    clock : StateBlock
        Rover-minus-base frequency offset and drift (offset state 0).
    orbit : StateBlock, optional
        The satellite's element-set offset, radial / along-track / cross-track [m].
    """

    name = "differential_doppler"

    def __init__(self, t_s, z_hz, sigma_hz, carrier_hz, pos_sv_ecef_m, vel_sv_ecef_mps, base_pos_ecef_m,
                 lever_arm_b_m, clock, orbit=None):
        super().__init__(t_s, z_hz, sigma_hz, carrier_hz, pos_sv_ecef_m, vel_sv_ecef_mps, lever_arm_b_m, clock,
                         None)
        self.states = (clock,) if orbit is None else (clock, orbit)
        self.base_pos_ecef_m = np.asarray(base_pos_ecef_m, dtype=float).reshape(3)
        C, W = rtn_frames(self.pos_sv_ecef_m, self.vel_sv_ecef_mps)
        self.rtn_to_ecef = np.vstack([C, W])  # (6, 3): (position, velocity) offset of an RTN offset
        self.base_model_hz = self._base_hz(self.pos_sv_ecef_m, self.vel_sv_ecef_mps)

    def _base_hz(self, pos_sv, vel_sv):
        return -float(frames.range_rate(pos_sv, vel_sv, self.base_pos_ecef_m, np.zeros(3))) * self.carrier_hz / C_MPS

    def _sv_state(self, ins):
        """The satellite as believed: the element-set state plus the estimated offset, (3,) each."""
        if len(self.states) == 1:
            return self.pos_sv_ecef_m, self.vel_sv_ecef_mps
        e = self.rtn_to_ecef @ ins.states[self.states[1].key]
        return self.pos_sv_ecef_m + e[:3], self.vel_sv_ecef_mps + e[3:]

    def _clock_hz(self, ins):
        return ins.states[self.states[0].key][0]

    def _predict(self, ins, g):
        base = self._base_hz(g[6], g[7]) - self.base_model_hz if len(self.states) == 2 else 0.0
        return super()._predict(ins, g) - base

    def _design(self, ins, g):
        H = np.zeros((1, N_INS + sum(b.size for b in self.states)))
        H[0, :N_INS], J_r, J_v = self._ins_row(ins, g)
        H[0, N_INS] = 1.0  # the offset (the drift enters through the block's transition)
        if len(self.states) == 2:
            # D depends on the satellite through r_s - r and v_s - v: dD/ds = -dD/d(receiver).
            J_b = doppler_jacobian(g[6][None], g[7][None], self.base_pos_ecef_m, np.zeros(3), self.carrier_hz)[0]
            H[0, N_INS + 2:] = -(np.r_[J_r, J_v] - J_b[:6]) @ self.rtn_to_ecef
        return H


def differential_aids(rover, base, base_pos_ecef_m, lever_arm_b_m, options=None, *, max_gap_s=MAX_GAP_S):
    """One :class:`DifferentialDoppler` per rover row with a base correction, and the carrier aids; shared blocks.

    Parameters
    ----------
    rover, base : leosop.positioning.measurements.Measurements
        With satellite states and ``sigma_hz`` (NaN: ``options.default_sigma_hz``
        for the rover); ``t_s`` of both on the aids' clock. One carrier per
        satellite, one rover-minus-base offset for all rows. With
        ``phase_cycles`` in both (and ``options.carrier``), also the
        carrier aids (:func:`~leosop.fusion.aids_carrier.carrier_aids`).
    base_pos_ecef_m : array_like, (3,)
    lever_arm_b_m : array_like, (3,)
    options : DifferentialOptions, optional
    max_gap_s : float
        Widest gap between a satellite's base rows interpolated across.

    Returns
    -------
    list of DifferentialDoppler, DifferentialCarrier and LeoWindowStart
        Sorted by ``t_s`` (at one time: the rover's row order, then the
        carrier aid and its clone); rows of a satellite the base did not
        see, outside its base rows' span or in a gap, or with non-finite
        values are left out.
    """
    o = options or DifferentialOptions()
    pos_sv, vel_sv = sv_states(rover, "rover")
    sv_states(base, "base")
    corr, var_base, rows, weights = base_corrections(base, base_pos_ecef_m, rover.sat_id, rover.t_s,
                                                     max_gap_s=max_gap_s)
    sigma_rover = np.where(np.isfinite(rover.sigma_hz), rover.sigma_hz, o.default_sigma_hz)
    z = rover.doppler_hz - corr
    sigma = np.sqrt(sigma_rover**2 + var_base)
    ok = np.isfinite(z) & np.isfinite(sigma) & np.isfinite(pos_sv).all(-1) & np.isfinite(vel_sv).all(-1)
    clock = StateBlock("diff_clock", (0.0, 0.0), (o.clock_offset_sigma_hz, o.clock_drift_sigma_hz_per_s),
                       (o.clock_offset_psd_hz2_per_s, o.clock_drift_psd_hz2_per_s3), integrated=True)
    orbits = None
    if o.orbit_sigma_rtn_m is not None:
        orbits = {j: StateBlock(f"diff_orbit:{j}", (0.0,) * 3, tuple(float(s) for s in o.orbit_sigma_rtn_m),
                                (0.0,) * 3, drop_after_s=SAT_DROP_AFTER_S) for j in np.unique(rover.sat_id)}
    out = [DifferentialDoppler(rover.t_s[k], z[k], sigma[k], rover.carrier_hz[k], pos_sv[k], vel_sv[k],
                               base_pos_ecef_m, lever_arm_b_m, clock, orbits and orbits[rover.sat_id[k]])
           for k in np.flatnonzero(ok)]
    if o.carrier:
        out += carrier_aids(rover, base, base_pos_ecef_m, lever_arm_b_m, rows, weights, orbits,
                            default_sigma_cycles=o.default_phase_sigma_cycles)
    return sorted(out, key=lambda a: a.t_s)
