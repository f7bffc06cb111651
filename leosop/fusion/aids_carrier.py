"""Differential LEO carrier-phase aid (tight coupling): time-differenced single differences, across satellites.

A base at a known site ``b`` gives per satellite j a phase correction, its
accumulated phase plus the phase its site predicts from the element-set
state ``s_j`` (cycles; interpolated linearly in time to the rover's epochs
with the weights of :func:`~leosop.positioning.differential_base.base_corrections`).
The rover's phase less it is, with ``rho(x, s) = |s - x|``, the satellite's
true state ``s_j + e_j`` and ``lambda_j = c / f0_j``::

    y_j(t) = -[rho(a, s_j + e_j) - rho(b, s_j + e_j) + rho(b, s_j)] / lambda_j + K(t) + N_j + noise,

the satellite's oscillator cancelled, ``K`` the rover-minus-base clock
phase and ``N_j`` the arcs' integer ambiguities. Between two consecutive
rover epochs ``t1 < t2`` of one arc the ambiguity goes: ``dy_j = y_j(t2) -
y_j(t1)`` is a delta-range over the interval, which needs the antenna
``a1`` at ``t1``: a cloned block made there by a
:class:`~leosop.fusion.aids_leo.LeoWindowStart` ([Roumeliotis 2002],
stochastic cloning, as the Doppler's integration window), with ``a2`` from
the INS (and lever arm) at ``t2``. The clock's ``K(t2) - K(t1)``, the
integral of the two oscillators' frequency difference (a consumer TCXO's
wander is ~10 Hz at 11 GHz over 1 s, far too much for a clock model at the
millimetre), is the same in every satellite's ``dy``: the aid's rows are
differences across satellites, ``z_i = dy_i - dy_0`` (satellite 0 the
epoch's first). The satellite states ``e_j``: the differential Doppler's
blocks (radial / along-track / cross-track offset ``d_j``, ``e = C d`` in
each epoch's frame, :func:`~leosop.positioning.differential.rtn_frames`), or
none.

An epoch's phase noise ``n_j(t)`` (rover and interpolated base) is in two
consecutive intervals, with opposite signs: taken as independent, the
intervals' noise would be -1/2 correlated and the filter conservative (a
mean position NEES of 2.1 for 3 in ``tools/bench_differential_ins.py``'s
standing start). The aid carries it exactly instead: each epoch's noise is a
block of states (one per satellite, prior its variance, no process noise),
``dy_j = ... + n_j(t2) - n_j(t1)`` with no further noise of its own, the
block of ``t1`` as the previous interval left it (the augmented state of
coloured measurement noise [Bryson and Henrikson 1968]); it is dropped once
the next interval has used it (a base row that two rover epochs
interpolate is in both their blocks, taken as independent: exact when the
base is on the rover's epochs). ``K`` and the ambiguities need no states, so
an arc's arbitrary integer and a receiver clock phase of any size cost
nothing (float ambiguity states would need priors that cover both).
``tests/fusion/test_aids_differential.py``
checks ``H`` against central differences of this model.
"""

import numpy as np

from ..constants import C_MPS
from ..positioning.differential import rtn_frames
from .aids import Aid, StateBlock
from .aids_leo import LeoWindowStart, _antenna, _antenna_jacobian
from .common import N_INS

__all__ = ["DifferentialCarrier", "carrier_aids"]


def _unit(pos_sv_ecef_m, pos_rx_ecef_m):
    """Ranges (k,) and unit vectors (k, 3) from receivers to satellites."""
    d = pos_sv_ecef_m - pos_rx_ecef_m
    rho = np.linalg.norm(d, axis=-1)
    return rho, d / rho[:, None]


class DifferentialCarrier(Aid):
    """One interval's time-differenced single differences less the first satellite's [cycles] (the module's model).

    Parameters
    ----------
    t_s : float
        The interval's end ``t2``, on the aids' clock.
    dy_cycles : array_like, (k,)
        Each satellite's rover-minus-base phase change over the interval
        (``k >= 2``; satellite 0 the reference).
    noise : tuple of StateBlock, (2,)
        The phase noise of the epochs ``t1`` and ``t2`` [cycles], one state
        per satellite of the epoch.
    noise_index : array_like of int, (2, k)
        Each satellite's state in the two blocks.
    carrier_hz : array_like, (k,)
    pos_sv_ecef_m : array_like, (2, k, 3)
        The satellites' element-set positions at ``t1`` and ``t2`` (ECEF).
    vel_sv_ecef_mps : array_like, (2, k, 3)
        Their velocities (the orientation of the offsets' frames).
    base_pos_ecef_m : array_like, (3,)
    lever_arm_b_m : array_like, (3,)
        Antenna minus IMU in the body frame (Right-Forward-Up).
    clone : StateBlock
        The antenna position at ``t1`` (ECEF, m), cloned by a
        :class:`~leosop.fusion.aids_leo.LeoWindowStart`.
    orbits : tuple of StateBlock, (k,), optional
        Each satellite's element-set offset, radial / along-track / cross-track [m].
    """

    name = "differential_carrier"
    external_clock = True

    def __init__(self, t_s, dy_cycles, noise, noise_index, carrier_hz, pos_sv_ecef_m, vel_sv_ecef_mps,
                 base_pos_ecef_m, lever_arm_b_m, clone, orbits=None):
        super().__init__(t_s)
        dy = np.asarray(dy_cycles, dtype=float)
        k = dy.size
        self.D = np.hstack([-np.ones((k - 1, 1)), np.eye(k - 1)])  # (k - 1, k): each satellite less the first
        self.measured = self.D @ dy
        self.R = np.zeros((k - 1, k - 1))  # the noise is in the states of ``noise``
        self.noise = tuple(noise)
        self.noise_index = np.asarray(noise_index, dtype=int).reshape(2, k)
        self.per_m = np.asarray(carrier_hz, dtype=float) / C_MPS  # cycles per metre, (k,)
        self.pos_sv_ecef_m = np.asarray(pos_sv_ecef_m, dtype=float).reshape(2, k, 3)
        vel = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(2, k, 3)
        self.rtn_to_ecef = rtn_frames(self.pos_sv_ecef_m, vel)[0]  # (2, k, 3, 3): position offset of an RTN one
        self.base_pos_ecef_m = np.asarray(base_pos_ecef_m, dtype=float).reshape(3)
        self.lever_arm_b_m = np.asarray(lever_arm_b_m, dtype=float).reshape(3)
        self.base_model_m = np.stack([_unit(p, self.base_pos_ecef_m)[0] for p in self.pos_sv_ecef_m])  # (2, k)
        self.orbits = tuple(orbits) if orbits is not None else ()
        self.states = (*self.orbits, *self.noise, clone)

    def _geometry(self, ins):
        """Antenna at ``t1`` and ``t2`` (3,) each, the believed satellites (2, k, 3), ``C_e_n``, lever arm (ENU)
        and antenna velocity (ECEF) at ``t2``."""
        C, _, l_n, _, r2, v2 = _antenna(ins, self.lever_arm_b_m)
        sv = self.pos_sv_ecef_m
        if self.orbits:
            d = np.stack([ins.states[b.key] for b in self.orbits])  # (k, 3)
            sv = sv + np.einsum("tkij,kj->tki", self.rtn_to_ecef, d)
        return ins.states[self.states[-1].key], r2, sv, C, l_n, v2

    def _dy_m(self, a1, a2, sv):
        """Each satellite's modelled delta-range [m] (k,) and the unit vectors (2, k, 3) from the antenna and from
        the base at ``t1`` and ``t2``."""
        rho_a1, u_a1 = _unit(sv[0], a1)
        rho_a2, u_a2 = _unit(sv[1], a2)
        rho_b1, u_b1 = _unit(sv[0], self.base_pos_ecef_m)
        rho_b2, u_b2 = _unit(sv[1], self.base_pos_ecef_m)
        dy = (rho_a2 - rho_b2 + self.base_model_m[1]) - (rho_a1 - rho_b1 + self.base_model_m[0])
        return dy, np.stack([u_a1, u_a2]), np.stack([u_b1, u_b2])

    def _noise(self, ins):
        """Each satellite's ``n(t2) - n(t1)`` (k,) of the states [cycles]."""
        n1, n2 = (ins.states[b.key][i] for b, i in zip(self.noise, self.noise_index))
        return n2 - n1

    def predict(self, ins):
        a1, a2, sv = self._geometry(ins)[:3]
        return self.D @ (-self.per_m * self._dy_m(a1, a2, sv)[0] + self._noise(ins))

    def rate(self, ins):
        # An IMU time offset moves both ends of the interval (the clone was made at t1 on the IMU clock too), the
        # antenna at the velocity of t2 at both; the satellites' states are those of the rows' times.
        a1, a2, sv, _, _, v2 = self._geometry(ins)
        u_a = self._dy_m(a1, a2, sv)[1]
        return self.D @ (self.per_m * ((u_a[1] - u_a[0]) @ v2))

    def design(self, ins):
        a1, a2, sv, C, l_n, _ = self._geometry(ins)
        _, u_a, u_b = self._dy_m(a1, a2, sv)
        f = self.per_m[:, None]
        # y = -f (rho(a2) - rho(a1) + ...): d rho / d a = -u, d rho / d s = u.
        J_a2, J_a1 = f * u_a[1], -f * u_a[0]  # (k, 3) each
        k = self.per_m.size
        n1, n2 = (b.size for b in self.noise)
        H = np.zeros((k - 1, N_INS + 3 * len(self.orbits) + n1 + n2 + 3))
        first = N_INS + 3 * len(self.orbits)
        H[:, first + self.noise_index[0]] = -self.D
        H[:, first + n1 + self.noise_index[1]] = self.D
        H[:, :N_INS] = self.D @ J_a2 @ _antenna_jacobian(ins, C, l_n)
        H[:, -3:] = self.D @ J_a1
        if self.orbits:
            J_d = -f * (np.einsum("ki,kij->kj", u_a[1] - u_b[1], self.rtn_to_ecef[1])
                        - np.einsum("ki,kij->kj", u_a[0] - u_b[0], self.rtn_to_ecef[0]))  # (k, 3)
            H[:, N_INS:N_INS + 3 * k] = (self.D[:, :, None] * J_d[None]).reshape(k - 1, 3 * k)
        return H


def carrier_aids(rover, base, base_pos_ecef_m, lever_arm_b_m, base_rows, base_weights, orbits, *,
                 default_sigma_cycles):
    """A :class:`DifferentialCarrier` per pair of consecutive rover epochs, and the clones they need.

    Parameters
    ----------
    rover, base : leosop.positioning.measurements.Measurements
        With satellite states and ``phase_cycles`` (None: no aids);
        ``phase_sigma_cycles`` NaN or None: ``default_sigma_cycles``; ``arc``
        None: one arc per satellite.
    base_pos_ecef_m : array_like, (3,)
    lever_arm_b_m : array_like, (3,)
    base_rows, base_weights : ndarray, (m, 2)
        The base rows each rover row's correction interpolates and their
        weights (:func:`~leosop.positioning.differential_base.base_corrections`).
    orbits : dict of str to StateBlock, or None
        Each satellite's element-set offset block by ``sat_id`` (every
        satellite of the rover's rows; shared with the Doppler aids), or
        None: no orbit states.
    default_sigma_cycles : float

    Returns
    -------
    list of DifferentialCarrier and LeoWindowStart
        Sorted by ``t_s``, at one time the carrier aid before the clone made
        there; consecutive aids share the noise block of their common epoch.
        An interval takes a satellite when it has a finite phase at both
        epochs, in one rover arc and one base arc (the two base rows of each
        interpolation too); intervals with fewer than two are left out.
    """
    if rover.phase_cycles is None or base.phase_cycles is None:
        return []
    b = np.asarray(base_pos_ecef_m, dtype=float).reshape(3)
    sigma_b = _sigma(base, default_sigma_cycles)
    c_b = base.phase_cycles + np.linalg.norm(base.pos_sv_ecef_m - b, axis=-1) * base.carrier_hz / C_MPS
    take = np.maximum(base_rows, 0)
    y = rover.phase_cycles - np.sum(base_weights * c_b[take], axis=-1)
    var = _sigma(rover, default_sigma_cycles) ** 2 + np.sum(base_weights**2 * sigma_b[take] ** 2, axis=-1)
    arc_b = base.arc if base.arc is not None else np.full(len(base), "")
    arc_r = rover.arc if rover.arc is not None else np.full(len(rover), "")
    one_base_arc = (base_rows[:, 0] >= 0) & ((base_weights[:, 1] == 0) | (arc_b[take[:, 0]] == arc_b[take[:, 1]]))
    ok = np.isfinite(y) & np.isfinite(var) & one_base_arc
    arc = np.char.add(np.char.add(arc_r.astype(str), "|"), arc_b[take[:, 0]].astype(str))
    epochs, ep = np.unique(rover.t_s, return_inverse=True)
    # Per satellite, rows in epoch order; an interval joins a row to the row before it.
    order = np.lexsort((ep, rover.sat_id))
    prev, cur = order[:-1], order[1:]
    pair = ((rover.sat_id[prev] == rover.sat_id[cur]) & (ep[cur] == ep[prev] + 1) & ok[prev] & ok[cur]
            & (arc[prev] == arc[cur]))
    prev, cur = prev[pair], cur[pair]
    keep = np.bincount(ep[cur], minlength=epochs.size)[ep[cur]] >= 2  # intervals of at least two satellites
    prev, cur = prev[keep], cur[keep]
    if cur.size == 0:
        return []
    # Each epoch's noise block: the rows of that epoch the intervals use, in row order; a row's state in it.
    rows = np.unique(np.concatenate([prev, cur]))
    rows = rows[np.argsort(ep[rows], kind="stable")]
    first = np.searchsorted(ep[rows], ep[rows])
    index = np.zeros(len(rover), dtype=int)
    index[rows] = np.arange(rows.size) - first
    gap_s = np.diff(epochs)
    noise = {e: StateBlock(f"diff_carrier_noise:{float(epochs[e])!r}", (0.0,) * n,
                           tuple(np.sqrt(var[rows[ep[rows] == e]])), (0.0,) * n,
                           drop_after_s=1.5 * gap_s[min(e, gap_s.size - 1)])
             for e, n in zip(*np.unique(ep[rows], return_counts=True))}
    aids, clones = [], {}
    for e in np.unique(ep[cur]):
        at = ep[cur] == e
        p, q = prev[at], cur[at]
        t1, t2 = float(epochs[e - 1]), float(epochs[e])
        if e - 1 not in clones:
            clones[e - 1] = StateBlock(f"diff_carrier_start:{t1!r}", (0.0,) * 3, (0.0,) * 3, (0.0,) * 3,
                                       drop_after_s=1.5 * (t2 - t1), cloned=True)
        blocks = None if orbits is None else [orbits[str(j)] for j in rover.sat_id[q]]
        aids.append(DifferentialCarrier(
            t2, y[q] - y[p], (noise[e - 1], noise[e]), np.stack([index[p], index[q]]), rover.carrier_hz[q],
            np.stack([rover.pos_sv_ecef_m[p], rover.pos_sv_ecef_m[q]]),
            np.stack([rover.vel_sv_ecef_mps[p], rover.vel_sv_ecef_mps[q]]), b, lever_arm_b_m, clones[e - 1], blocks))
    starts = [LeoWindowStart(float(epochs[e]), lever_arm_b_m, block) for e, block in clones.items()]
    return sorted(aids + starts, key=lambda a: (a.t_s, a.clones))


def _sigma(meas, default):
    """Phase sigma of each row [cycles], ``default`` where not given."""
    s = meas.phase_sigma_cycles
    return np.full(len(meas), float(default)) if s is None else np.where(np.isfinite(s), s, default)
