"""One INS error-state filter that takes time-ordered aids.

The strapdown INS (:func:`leosop.ins.strapdown.update`, two-sample, ENU)
runs on every pair of IMU increments less the bias estimates; the 15 INS
errors of :mod:`leosop.ins.error_model` are propagated with its ``model15``
(second-order series, at most every ``settings.step_s`` and before every aid applied)
plus random walks of both biases; each aid (:mod:`leosop.fusion.aids`) gives
``(z, H, R)``, the aids due at one instant are gated one after the other
and make one update, the Joseph form of :mod:`leosop.fusion.kalman`
(:meth:`_Filter.apply`), and the estimated errors are fed back at once
(closed loop, so the prior error estimate is always zero).

An aid at ``t_s`` is applied after the INS update that ends at or just after
``t_s``; it sees the INS moved back to ``t_s`` along its velocity (a pair of
100 Hz samples is 20 ms, 0.2 m at 10 m/s, far above an RTK fix's 1 cm).

Optional states after the 15 INS errors (:class:`EngineSettings`): the
gyro and accelerometer scale-factor errors (3 + 3, ``s`` in ``measured =
(1 + s) true + bias``; they enter the error model as the bias columns times
the body rate or specific force) and the IMU time offset ``td`` (IMU clock
minus the aids' clock). Aids on the aids' clock (``aid.external_clock``,
GNSS) are applied at ``t_s + td_hat`` on the IMU clock, and their design
matrix gets the column ``dh/dt`` (:meth:`leosop.fusion.aids.Aid.rate`): an
offset ``td_hat - td`` moves ``h`` by ``dh/dt (td_hat - td)``. Aids derived
from the IMU itself (ZUPT, NHC) are on its clock and see no offset.

States of the aids (:class:`leosop.fusion.aids.StateBlock`, e.g. a LEO
receiver's clock per constellation and each satellite's offset) come after
those: a block is added with its prior when the first aid naming it is due,
propagated by its own transition (no coupling to the INS errors) and
dropped (marginalised) once stale (:class:`leosop.fusion.blocks.Blocks`), or
made by an aid that clones (stochastic cloning: a copy of INS quantities at
its time, with their cross-covariance, for an aid due later); its
estimate is kept beside ``P`` and corrected by every update (error =
estimate minus truth, as the time offset). The result is an
:class:`leosop.fusion.record.EngineResult`.

Heading: a MEMS IMU cannot find North at rest, so a run may start with the
yaw unknown (:class:`CourseAlignment`): the first GNSS velocity faster than
``min_speed_mps`` sets the yaw to the course over ground (the body's Forward
axis along the velocity, as a car drives) and the yaw's covariance row to
the variance of that course alone (:func:`course_sigma_rad`: the velocity
aid's covariance across the track over the speed squared, at that instant)
plus ``sigma_rad**2``, the heading's own departure from the course (sideslip,
crab); aids with ``needs_heading`` wait until then.
"""

import itertools
import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.stats

from .. import earth
from ..ins import error_model, strapdown
from ..ins.error_model import DPOS, DV, EPS, NABLA, PHI
from ..ins.strapdown import NavState
from ..rotations import dcm_to_euler, euler_to_dcm
from . import kalman
from .aids import Aid, InsView
from .blocks import Blocks
from .common import N_INS
from .record import EngineResult, Recorder
from .settings import (
    CROSS_IJ,
    CourseAlignment,
    EngineSettings,
    course_sigma_rad,
    cross_slice,
    initial_covariance,
    state_slices,
)

__all__ = ["CourseAlignment", "EngineResult", "EngineSettings", "course_sigma_rad", "initial_covariance", "run",
           "state_slices"]


#: Slack on comparisons of times [s] (sums of IMU intervals round far below it).
_TIME_SLACK_S = 1e-9


class _Filter:
    """The running filter: INS state, sensor error estimates, covariance and the pending propagation."""

    def __init__(self, state0, P0, settings, time_offset_s, on_aid=None):
        self.on_aid = on_aid
        self.state = state0
        self.settings = settings
        self.SG, self.SA, self.TD = state_slices(settings)
        self.MG = cross_slice(settings)
        self.P = initial_covariance(P0, settings) if np.shape(P0) == (N_INS, N_INS) else np.array(P0, dtype=float)
        self.n_core = self.P.shape[0]
        self.blocks = Blocks()
        self.Qc = settings.noise_psd()
        self.bias_q = np.r_[np.full(3, settings.gyro_bias_rw_rad_per_s_per_rt_s**2),
                            np.full(3, settings.accel_bias_rw_mps2_per_rt_s**2)]
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.sg = np.zeros(3)
        self.sa = np.zeros(3)
        self.mg = np.zeros((3, 3))
        self.td = float(time_offset_s)
        self.omega = np.zeros(3)
        self.accel_enu = np.zeros(3)
        self.pending_s = 0.0
        self.pending_dv_b = np.zeros(3)
        self.pending_dth_b = np.zeros(3)
        self.pending_var = np.zeros(6)
        self.counts = {}
        self.nll = {}
        self.rejected_run = {}
        self.gate = {}
        self.last_update_s = -math.inf

    def correct_increments(self, dth, dv, dt2):
        """Raw increments (2, 3) less the bias, scale-factor and cross-axis estimates."""
        th = dth * (1.0 - self.sg) - dth @ self.mg.T - self.bg * dt2[:, None]
        return th, dv * (1.0 - self.sa) - self.ba * dt2[:, None]

    def propagate(self):
        """Move ``P`` over the INS updates made since the last propagation."""
        dt = self.pending_s
        if dt <= 0.0:
            return
        s = self.state
        C = s.C_n_b
        f_b = self.pending_dv_b / dt
        F15, G15 = error_model.model15(C, C @ f_b, s.vel_enu_mps, s.lat_rad, s.alt_m)
        n_all, n = self.P.shape[0], self.n_core
        F, G = np.zeros((n, n)), np.zeros((n, 6))
        F[:N_INS, :N_INS], G[:N_INS] = F15, G15
        if self.SG is not None:
            F[:N_INS, self.SG] = F15[:, EPS] * (self.pending_dth_b / dt)
            F[:N_INS, self.SA] = F15[:, NABLA] * f_b
        if self.MG is not None:
            i, j = CROSS_IJ
            F[:N_INS, self.MG] = F15[:, EPS][:, i] * (self.pending_dth_b / dt)[j]
        Phi, Qd = error_model.discretize(F, G, self.Qc, dt, method="series")
        Qd[EPS, EPS] += np.diag(self.bias_q[:3] * dt)
        Qd[NABLA, NABLA] += np.diag(self.bias_q[3:] * dt)
        Qd[:N_INS, :N_INS] += (G15 * self.pending_var) @ G15.T
        if self.TD is not None:
            Qd[self.TD, self.TD] += self.settings.time_offset_rw_s_per_rt_s**2 * dt
        if n_all > n:
            Phi_all, Qd_all = np.eye(n_all), np.zeros((n_all, n_all))
            Phi_all[:n, :n], Qd_all[:n, :n] = Phi, Qd
            self.blocks.propagate(Phi_all, Qd_all, dt)
            Phi, Qd = Phi_all, Qd_all
        P = Phi @ self.P @ Phi.T + Qd
        self.P = 0.5 * (P + P.T)
        self.pending_s = 0.0
        self.pending_dv_b = np.zeros(3)
        self.pending_dth_b = np.zeros(3)
        self.pending_var = np.zeros(6)

    def due_s(self, aid):
        """When ``aid`` is due on the IMU clock."""
        return aid.t_s + self.td if aid.external_clock else aid.t_s

    def view(self, t_aid_s, t_now_s, dx):
        """The INS less the errors ``dx`` (n_x,), moved back along its velocity and acceleration from ``t_now_s``
        to the aid's time."""
        s, dt = self.state.corrected(dx[PHI], dx[DV], dx[DPOS]) if dx.any() else self.state, t_aid_s - t_now_s
        R_M, R_N = earth.radii_m(s.lat_rad)
        v = s.vel_enu_mps
        moved = strapdown.NavState(s.lat_rad + v[1] * dt / (R_M + s.alt_m),
                                   s.lon_rad + v[0] * dt / ((R_N + s.alt_m) * math.cos(s.lat_rad)),
                                   s.alt_m + v[2] * dt, v + self.accel_enu * dt, s.q_n_b)
        return InsView(moved, self.bg + dx[EPS], self.ba + dx[NABLA], self.omega, self.accel_enu,
                       self.blocks.estimates(dx))

    def admit(self, aid):
        """Drop the stale state blocks, add those ``aid`` names for the first time, mark its blocks named now."""
        self.P = self.blocks.admit(self.P, aid)

    def clone(self, aid, t_aid_s, t_now_s):
        """Make the cloned block of ``aid`` (:attr:`leosop.fusion.aids.Aid.clones`) from the INS at its time."""
        self.P = self.blocks.drop_stale(self.P, aid.t_s)
        estimate, G = aid.clone_rows(self.view(t_aid_s, t_now_s, np.zeros(self.P.shape[0])))
        self.P = self.blocks.clone(self.P, aid.states[0], estimate, G, aid.t_s)

    def innovation(self, aid, ins):
        """``(z, H, R)`` of ``aid`` over the full state (the time-offset column for aids on the aids' clock)."""
        z, Ha, R = aid.matrices(ins)
        H = np.zeros((z.size, self.P.shape[0]))
        self.blocks.design(aid, Ha, H)
        if self.TD is not None and aid.external_clock:
            H[:, self.TD.start] = aid.rate(ins)
        return z, H, R

    def waits(self, aid, t0_s):
        """Whether ``aid`` comes within the correction period of the last update (or of the start ``t0_s``)."""
        last = max(self.last_update_s, t0_s)
        period = self.settings.correction_period_s
        return period > 0 and aid.t_s != self.last_update_s and aid.t_s - last < period - _TIME_SLACK_S

    def apply(self, aids, t_aid_s, t_now_s, indices):
        """Gate the aids due at ``t_aid_s`` one after the other, apply those used as one update, feed back.

        The sequence of their updates, each aid linearised at the INS the
        ones before it corrected, without the (n_x, n_x) work of each: the
        correction ``dx`` and the gains ``K_i`` are carried from aid to aid
        (``P_i = P - U U^T``, ``U`` the columns ``K_i chol(S_i)``, so
        ``P_i H^T`` costs ``n_x m``); the one Joseph update of the aids used
        then makes the sequence's ``P`` (it depends on the ``H`` alone) and,
        given each innovation as if linearised before the instant (``z +
        H dx``), its correction. ``indices`` (len(aids),): the aids' places
        in the run's sequence.
        """
        n = self.P.shape[0]
        dx, U, used_rows = np.zeros(n), np.zeros((n, 0)), []
        for aid, index in zip(aids, indices):
            z, H, R = self.innovation(aid, self.view(t_aid_s, t_now_s, dx))
            PHt = self.P @ H.T - U @ (U.T @ H.T)
            S = H @ PHt + R
            count = self.counts.setdefault(aid.name, [0, 0])
            if aid.screens:  # such an aid is alone at its instant (run): P is the covariance before it
                screened = aid.screen(z, H, R, self.P)
                if screened is not None:
                    keep, restart = screened
                    self.blocks.restart(self.P, restart)
                    z, H, R = z[keep], H[keep], R[np.ix_(keep, keep)]
                    PHt = self.P @ H.T
                    S = H @ PHt + R
            nis = float(z @ np.linalg.solve(S, z))
            run = self.rejected_run.get(aid.name, 0)
            if z.size not in self.gate:
                self.gate[z.size] = scipy.stats.chi2.ppf(self.settings.gate_probability, z.size)
            failed = aid.gated and nis > self.gate[z.size]
            if failed and run < self.settings.reopen_after:
                count[1] += 1
                self.rejected_run[aid.name] = run + 1
                if self.on_aid is not None:
                    self.on_aid(index, aid, z, S, False, False)
                continue
            if failed and self.settings.reopen_inflates:  # such an aid is alone at its instant (run)
                H_plus = np.linalg.pinv(H[:, :N_INS])
                self.P[:N_INS, :N_INS] += H_plus @ np.diag(z**2) @ H_plus.T
                PHt = self.P @ H.T
                S = H @ PHt + R
                nis = float(z @ np.linalg.solve(S, z))
            if self.on_aid is not None:
                self.on_aid(index, aid, z, S, True, failed)
            self.last_update_s = aid.t_s
            self.rejected_run[aid.name] = 0
            count[0] += 1
            nll = 0.5 * (nis + np.linalg.slogdet(2.0 * math.pi * S)[1])
            self.nll[aid.name] = self.nll.get(aid.name, 0.0) + nll
            K = np.linalg.solve(S, PHt.T).T
            used_rows.append((z + H @ dx, H, R))
            dx = dx + K @ z
            U = np.column_stack([U, K @ np.linalg.cholesky(S)])
        if used_rows:
            z, H = np.concatenate([r[0] for r in used_rows]), np.concatenate([r[1] for r in used_rows])
            R, lo = np.zeros((z.size, z.size)), 0
            for _, _, Ra in used_rows:
                R[lo:lo + Ra.shape[0], lo:lo + Ra.shape[0]] = Ra
                lo += Ra.shape[0]
            dx, P, _, _ = kalman.update(np.zeros(n), self.P, z, H, R)
            self.feed_back(dx, P)

    def feed_back(self, dx, P):
        """Remove the estimated errors ``dx`` (n_x,) from the INS, sensor and block estimates.

        ``P`` (n_x, n_x) is the covariance after the update.
        """
        self.P = P
        self.state = self.state.corrected(dx[PHI], dx[DV], dx[DPOS])
        self.bg = self.bg + dx[EPS]
        self.ba = self.ba + dx[NABLA]
        if self.SG is not None:
            self.sg = self.sg + dx[self.SG]
            self.sa = self.sa + dx[self.SA]
        if self.MG is not None:
            self.mg[CROSS_IJ] += dx[self.MG]
        if self.TD is not None:
            self.td -= float(dx[self.TD.start])  # dx is td_hat minus the true offset
        self.blocks.feed_back(dx)

    def align_yaw(self, vel_enu_mps, sigma_rad):
        """Set the yaw to the course of ``vel_enu_mps``, keeping pitch and roll; reset the yaw's covariance."""
        s = self.state
        pitch, roll, _ = dcm_to_euler(s.C_n_b)
        yaw = math.atan2(-vel_enu_mps[0], vel_enu_mps[1])  # counter-clockwise from North, Forward along v
        self.state = strapdown.NavState.from_dcm(s.lat_rad, s.lon_rad, s.alt_m, s.vel_enu_mps,
                                                 euler_to_dcm(pitch, roll, yaw))
        k = PHI.start + 2
        self.P[k, :] = 0.0
        self.P[:, k] = 0.0
        self.P[k, k] = sigma_rad**2

    def step(self, dth, dv, dt2, var2):
        """One INS update over a pair of raw increments (2, 3) whose errors have the variances ``var2`` (2, 6)."""
        th, dvc = self.correct_increments(dth, dv, dt2)
        T = float(dt2[0] + dt2[1])
        v0 = self.state.vel_enu_mps
        self.state = strapdown.update(self.state, th, dvc, 0.5 * T)
        self.omega = (th[0] + th[1]) / T
        self.accel_enu = (self.state.vel_enu_mps - v0) / T
        self.pending_s += T
        self.pending_dv_b += dvc[0] + dvc[1]
        self.pending_dth_b += th[0] + th[1]
        self.pending_var += var2[0] + var2[1]


def run(state0: NavState, P0: npt.ArrayLike, t_s: npt.ArrayLike, dt_s: npt.ArrayLike,
        dtheta_b_rad: npt.NDArray[np.float64], dvel_b_mps: npt.NDArray[np.float64], aids: Iterable[Aid],
        settings: EngineSettings, *, course_alignment: CourseAlignment | None = None, time_offset_s: float = 0.0,
        progress: Callable[[range], Iterable[int]] | None = None, on_aid: Callable[..., None] | None = None,
        after_aid: Callable[[Aid, NavState, npt.NDArray[np.float64], dict[str, Any]],
                            Iterable[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] | None] | None = None,
        increment_var: npt.ArrayLike | None = None) -> EngineResult:
    """Run the filter over an IMU log with time-ordered aids.

    Parameters
    ----------
    state0 : leosop.ins.strapdown.NavState
        The INS at ``t_s[0] - dt_s[0]`` (the start of the first increment).
    P0 : ndarray, (15, 15) or (n_x, n_x)
        Initial covariance of the INS errors (the optional states then get
        the sigmas of ``settings``), or of the full state.
    t_s, dt_s : ndarray, (n,)
        End of each increment's interval and its length [s], IMU clock.
    dtheta_b_rad, dvel_b_mps : ndarray, (n, 3)
        Increments in the body frame (Right-Forward-Up).
    aids : sequence of leosop.fusion.aids.Aid
        Sorted by ``t_s``; those before the start or after the end are not used.
    settings : EngineSettings
    course_alignment : CourseAlignment, optional
        The yaw of ``state0`` is unknown: set it from the first fast GNSS
        velocity aid. None: the yaw is known.
    time_offset_s : float
        IMU clock minus the aids' clock (the initial estimate when it is a state).
    progress : callable, optional
        Wraps the iterator over INS updates (a progress bar).
    on_aid : callable, optional
        Called after each aid's gate test (and its rows' screening,
        :meth:`leosop.fusion.aids.Aid.screen`) as ``on_aid(index, aid, z, S, used, reopened)``:
        the aid's place in ``aids``, its innovation (m,) and covariance
        (m, m) as gated (given the aids used before it at the same instant),
        whether it was used, and whether it failed the gate and was used all
        the same.
    after_aid : callable, optional
        Called after each aid is applied as ``after_aid(aid, state, P, blocks)``
        (each aid is then an update of its own; without it the aids due at
        one instant make one update, :meth:`_Filter.apply`):
        the INS after the feedback, the full covariance and the state blocks
        ``{key: (first index in P, estimate)}`` (read-only). It returns a list
        of further corrections ``(dx, P_after)`` to feed back in turn (error
        sense, as an update's), or None: steps on the filter that are not one
        aid's (z, H, R), e.g. the PPP ambiguity fixing, wide-lane update and
        bridge into a gap of :mod:`leosop.gnss.ppp_ins_ar`.

    increment_var : ndarray, (n, 6), optional
        Variance of the error of each increment ``[dtheta (rad^2), dvel
        ((m/s)^2)]`` beyond the white noise of ``settings``, added to the
        process noise (a bridged gap, :func:`leosop.ins.gaps.bridge`).

    Returns
    -------
    EngineResult
    """
    t_s, dt_s = np.asarray(t_s, dtype=float), np.asarray(dt_s, dtype=float)
    m, every = t_s.size // 2, settings.record_every
    t_pairs = np.r_[t_s[0] - dt_s[0], t_s[1:2 * m:2]]
    f = _Filter(state0, P0, settings, time_offset_s, on_aid)
    out = Recorder(m // every + 1, f.n_core, settings.record_cov_ins)
    aligned_s = None
    heading_known = course_alignment is None
    # The aids due with one join its update, unless a re-opened gate may raise P, after_aid must see each
    # aid's update, or (aids on the aids' clock) an update of the time offset moves when the next is due.
    # And once the heading is known: no aid then waits for it.
    stack = after_aid is None and not settings.reopen_inflates
    aids = list(aids)
    if any(b.t_s < a.t_s for a, b in itertools.pairwise(aids)):
        raise ValueError("aids must be sorted by time")
    queues = [[(j, a) for j, a in enumerate(aids) if a.external_clock],
              [(j, a) for j, a in enumerate(aids) if not a.external_clock]]
    heads = [0, 0]
    for q, i in zip(queues, (0, 1)):
        while heads[i] < len(q) and f.due_s(q[heads[i]][1]) < t_pairs[0]:
            heads[i] += 1
    var = np.zeros((t_s.size, 6)) if increment_var is None else np.asarray(increment_var, dtype=float)
    out.record(0, f)
    ks = range(m) if progress is None else progress(range(m))
    for k in ks:
        i = 2 * k
        f.step(dtheta_b_rad[i:i + 2], dvel_b_mps[i:i + 2], dt_s[i:i + 2], var[i:i + 2])
        t_now = t_pairs[k + 1]
        while True:
            due = [(f.due_s(q[h][1]), c) for c, (q, h) in enumerate(zip(queues, heads)) if h < len(q)]
            due = [d for d in due if d[0] <= t_now]
            if not due:
                break
            t_aid, c = min(due)
            index, aid = queues[c][heads[c]]
            heads[c] += 1
            if course_alignment is not None and not heading_known:  # the heading is unknown only with an alignment
                v = getattr(aid, "vel_enu_mps", None)
                if v is None or math.hypot(v[0], v[1]) < course_alignment.min_speed_mps:
                    if aid.needs_heading:
                        continue
                else:
                    _, _, R = aid.matrices(f.view(t_aid, t_now, np.zeros(f.P.shape[0])))
                    f.align_yaw(v, math.hypot(course_alignment.sigma_rad, course_sigma_rad(v, R)))
                    heading_known, aligned_s = True, aid.t_s
            if aid.clones:
                f.propagate()
                f.clone(aid, t_aid, t_now)
                continue
            if not f.blocks.alive(aid.states):  # its clone's time came before the run's start
                continue
            if f.waits(aid, t_pairs[0]):
                f.admit(aid)
                continue
            group = [(index, aid)]
            joins = stack and heading_known and not aid.screens and not (aid.external_clock and f.TD is not None)
            while joins and heads[c] < len(queues[c]) and f.due_s(queues[c][heads[c]][1]) == t_aid \
                    and not queues[c][heads[c]][1].screens and not queues[c][heads[c]][1].clones:
                group.append(queues[c][heads[c]])
                heads[c] += 1
            f.propagate()
            for _, a in group:
                f.admit(a)
            f.apply([a for _, a in group], t_aid, t_now, [j for j, _ in group])
            if after_aid is not None:
                for dx, P in after_aid(aid, f.state, f.P, f.blocks.layout()) or ():
                    f.feed_back(dx, P)
        if f.pending_s >= settings.step_s - _TIME_SLACK_S:
            f.propagate()
        if (k + 1) % every == 0:
            out.record((k + 1) // every, f)
    f.propagate()
    return out.result(t_pairs[::every], f, aligned_s)
