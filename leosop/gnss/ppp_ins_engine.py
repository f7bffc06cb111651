"""Tight PPP/INS as a composition of the fusion engine: float solution and ambiguity fixing (issue 21).

The observations of :func:`leosop.gnss.ppp_ins.run` become one
:class:`leosop.fusion.aids_gnss.PppEpoch` aid per GNSS epoch (SD IF code,
phase and range rate; the wet delay and one undifferenced ambiguity per arc
as engine state blocks; arcs cut by :func:`leosop.gnss.ppp_obs.detect_slips`)
and :func:`leosop.fusion.engine.run` is the filter. What follows an
epoch's update runs in the engine's ``after_aid`` hook (:class:`_AfterEpoch`),
as in :mod:`leosop.gnss.ppp_ins`: the inertial wide-lanes after a gap (an
update of their ranges), SD wide-lanes rounded from the arcs'
Melbourne-Wuebbena means, narrow-lanes by LAMBDA with partial fixing on the
float filter (no fix-and-hold), and before a gap the bridge from the fixed
solution (the hook hands the engine those corrections to feed back).

Not hosted yet: the per-row outlier screening of :mod:`leosop.gnss.ppp_ins`
(normalised innovations above ``k_outlier``; a phase outlier restarts the
ambiguity), which needs ``P`` before the update, so :func:`run` takes every
row. Measured against :func:`leosop.gnss.ppp_ins.run` on the simulated car
(which has no outliers): the same fixed epochs and integers, positions
within millimetres, except where a LAMBDA test sits on its threshold (one
epoch's re-fix after a gap, seed 0 of the 330 s outage case).
"""

from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS, DAY_S
from ..frames import geodetic_to_ecef
from ..fusion import engine, kalman
from ..fusion.aids import InsView
from ..fusion.aids_gnss import ZWD_KEY, PppEpoch, ambiguity_block, zwd_block
from ..fusion.common import N_INS, initial_covariance, pos_jacobian
from ..ins.error_model import DPOS, DV, PHI
from . import models
from .geometry import range_and_rate, satellite_clock
from .lambda_ import partial_fix
from .ppp import PppOptions
from .ppp_ins import (
    BETA_M,
    LAM_NL_M,
    LAM_WL_M,
    PppInsOptions,
    PppInsResult,
    _InertialWideLane,
    _mw_mean,
    _mw_var_mean,
    if_combinations,
)
from .ppp_obs import detect_slips

__all__ = ["ppp_aids", "run"]


def ppp_aids(gnss, orbits, clocks, n_ep, t_filter_s, step_s, options, pos_approx_ecef_m):
    """One :class:`PppEpoch` per GNSS epoch with at least two satellites.

    The undifferenced ambiguities' common mode is not observed (the SD rows
    see only differences): where every arc starts afresh (the first epoch,
    after a gap) the highest satellite's ambiguity is the datum, prior sigma
    zero, the others ``amb_sigma_m`` each, which gives the SD ambiguities
    against it the priors of :mod:`leosop.gnss.ppp_ins` (independent,
    ``amb_sigma_m``); elsewhere a new arc's ``amb_sigma_m`` is its SD prior
    too, the others' common mode being known through the datum.

    Parameters
    ----------
    gnss : leosop.gnss.simulate.GnssSim
        As :func:`leosop.gnss.ppp_ins.run`.
    orbits, clocks : leosop.gnss.products.Orbits, Clocks
    n_ep : int
        Epochs used.
    t_filter_s : ndarray, shape (n_ep,)
        The epochs on the filter's clock.
    step_s : float
        GNSS interval (an arc ends at a gap longer than 1.5 of it).
    options : PppInsOptions
    pos_approx_ecef_m : ndarray, shape (3,)
        Where the elevations that choose the datum are computed (kilometres
        off move them by hundredths of a degree).

    Returns
    -------
    aids : list of PppEpoch
    epochs : list of _Epoch
        Per aid: its epoch, satellites, arcs and satellite clocks.
    """
    Pc, Lc, MW, GF = if_combinations(gnss.P1_m[:n_ep], gnss.P2_m[:n_ep], gnss.L1_cyc[:n_ep], gnss.L2_cyc[:n_ep])
    t = gnss.t_s[:n_ep]
    have = np.isfinite(Pc) & np.isfinite(Lc)
    new_arc = detect_slips(t, MW, GF, gnss.lli[:n_ep], have, PppOptions(max_gap_s=1.5 * step_s))
    day = np.datetime64(orbits.ref_gps, "D")
    doy = float((day - day.astype("datetime64[Y]")).astype(int) + 1)
    zwd = zwd_block(options)
    n_sv = len(gnss.sv)
    arc = [None] * n_sv
    seen = np.zeros(n_sv, bool)
    mw_sum, mw_sq, mw_n = np.zeros(n_sv), np.zeros(n_sv), np.zeros(n_sv, int)
    aids, arcs = [], []
    for k in range(n_ep):
        js = np.flatnonzero(have[k])
        starts = js[new_arc[k, js] | ~seen[js]]
        sigma = np.full(n_sv, options.amb_sigma_m)
        if js.size >= 2 and starts.size == js.size:
            los = range_and_rate(orbits, gnss.orb_idx[js], t[k], pos_approx_ecef_m, np.zeros(3))[2]
            sigma[js[np.argmax(los @ pos_approx_ecef_m)]] = 0.0  # the highest: largest component along the radius
        for j in starts:
            arc[j] = ambiguity_block(gnss.sv[j], t[k], Lc[k, j] - Pc[k, j], sigma[j], step_s)
        seen[:] = False
        seen[js] = True
        fresh = np.ones(n_sv, bool)  # a Melbourne-Wuebbena arc restarts with the ambiguity's, and in a gap
        fresh[js] = js.size < 2
        fresh[starts] = True
        mw_sum[fresh], mw_sq[fresh], mw_n[fresh] = 0.0, 0.0, 0
        if js.size < 2:
            continue
        mw_sum[js] += MW[k, js]
        mw_sq[js] += MW[k, js] ** 2
        mw_n[js] += 1
        clk_m, drift_mps = satellite_clock(orbits, clocks, gnss.orb_idx[js], gnss.clk_idx[js],
                                           t[k] - gnss.P1_m[k, js] / C_MPS)
        arcs.append(_Epoch(k, js, fresh, mw_sum.copy(), mw_sq.copy(), mw_n.copy(), clk_m))
        aids.append(PppEpoch(t_filter_s[k], t[k], orbits, gnss.orb_idx[js], Pc[k, js] + clk_m, Lc[k, js] + clk_m,
                             gnss.rate_mps[k, js] + drift_mps, [arc[j] for j in js], zwd, doy, options))
    return aids, arcs


@dataclass(frozen=True)
class _Epoch:
    """One aid's epoch ``k``: satellites ``js`` (into ``gnss.sv``), arcs restarted (``fresh``, (n_sv,)), the
    Melbourne-Wuebbena sums, sums of squares and counts of the arcs so far ((n_sv,) each), satellite clocks (m,)."""

    k: int
    js: np.ndarray
    fresh: np.ndarray
    mw_sum: np.ndarray
    mw_sq: np.ndarray
    mw_n: np.ndarray
    clk_m: np.ndarray


def run(gnss, orbits, clocks, state0, dtheta_b_rad, dvel_b_mps, dt_s, settings, options=None):
    """PPP/INS on the engine: float solution and, with ``options.ar``, the fixed one.

    Arguments as :func:`leosop.gnss.ppp_ins.run` (``options`` None: the
    defaults of :class:`PppInsOptions`; ``k_outlier`` is not used). The
    filter's clock is the GNSS time ``gnss.t_s``; the IMU increments end at
    ``gnss.t_s[0] + (i + 1) dt_s``; the INS biases have no random walk (as
    :mod:`leosop.gnss.ppp_ins`).

    Returns
    -------
    PppInsResult
        At the GNSS epochs; ``cov_ins`` at the GNSS epochs only (after the
        epoch's last step; NaN in gaps, where the engine records only the
        sigmas), the counters of slips and outliers zero.
    """
    options = PppInsOptions() if options is None else options
    per = round(settings.step_s / dt_s)
    n_ep = min(len(gnss.t_s), dtheta_b_rad.shape[0] // per + 1)
    n_imu = (n_ep - 1) * per
    t_imu = gnss.t_s[0] + np.arange(1, n_imu + 1) * dt_s
    t_filter = np.r_[t_imu[0] - dt_s, t_imu[per - 1::per]]  # the engine's own record times, exactly
    aids, epochs = ppp_aids(gnss, orbits, clocks, n_ep, t_filter, settings.step_s, options,
                            geodetic_to_ecef(state0.lat_rad, state0.lon_rad, state0.alt_m))
    out = PppInsResult(t_s=gnss.t_s[:n_ep], pos_float_ecef_m=np.full((n_ep, 3), np.nan),
                       pos_fixed_ecef_m=np.full((n_ep, 3), np.nan), cov_pos_enu_m2=np.full((n_ep, 3, 3), np.nan),
                       cov_ins=np.full((n_ep, N_INS, N_INS), np.nan), n_sats=np.zeros(n_ep, int),
                       n_fixed=np.zeros(n_ep, int), n_wl=np.zeros(n_ep, int), ratio=np.full(n_ep, np.nan),
                       gnss=np.zeros(n_ep, bool), n_slips=0, n_outliers=0, n_ref_changes=0)
    hook = _AfterEpoch(gnss, n_ep, out, dict(zip(map(id, aids), epochs)), options)
    es = engine.EngineSettings(settings.gyro_arw_rad_per_rt_s, settings.accel_vrw_mps2_per_rt_hz, 0.0, 0.0,
                               step_s=settings.step_s)
    P0 = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    res = engine.run(state0, P0, t_imu, np.full(n_imu, dt_s), dtheta_b_rad[:n_imu], dvel_b_mps[:n_imu], aids, es,
                     after_aid=hook)
    rec = np.arange(n_ep) * (per // 2)
    gap = ~out.gnss
    out.pos_float_ecef_m[gap] = geodetic_to_ecef(res.lat_rad[rec[gap]], res.lon_rad[rec[gap]], res.alt_m[rec[gap]])
    out.cov_pos_enu_m2[gap] = res.cov_pos_enu_m2[rec[gap]]
    return out


class _AfterEpoch:
    """The engine's ``after_aid`` hook: records the float solution, fixes, re-fixes wide-lanes, bridges gaps.

    The steps of :func:`leosop.gnss.ppp_ins.run` after its update, on the
    engine's state (error sense: ``estimate - truth`` for the wet delay and
    the ambiguities too, where :mod:`leosop.gnss.ppp_ins` keeps corrections,
    hence the wet delay's sign in the rows given to
    :class:`leosop.gnss.ppp_ins._InertialWideLane`).
    """

    def __init__(self, gnss, n_ep, out, epochs, o):
        Pc, Lc, self.MW, self.GF = if_combinations(gnss.P1_m[:n_ep], gnss.P2_m[:n_ep], gnss.L1_cyc[:n_ep],
                                                   gnss.L2_cyc[:n_ep])
        self.t = gnss.t_s[:n_ep]
        self.have_n = np.count_nonzero(np.isfinite(Pc) & np.isfinite(Lc), axis=1)
        self.new_arc = detect_slips(self.t, self.MW, self.GF, gnss.lli[:n_ep], np.isfinite(Pc) & np.isfinite(Lc),
                                    PppOptions(max_gap_s=1.5 * (self.t[1] - self.t[0]) if n_ep > 1 else 1.0))
        self.LW = (gnss.L1_cyc[:n_ep] - gnss.L2_cyc[:n_ep]) * LAM_WL_M
        self.wsb = gnss.wsb_cyc
        self.out, self.epochs, self.o = out, epochs, o
        self.iwl = _InertialWideLane(len(gnss.sv))
        self.snap_k = -1  # the last epoch before the gap the inertial wide-lanes were prepared for
        self.ref_sv, self.last_sv = -1, set()

    def __call__(self, aid, state, P, blocks):
        ep, o, out, iwl = self.epochs[id(aid)], self.o, self.out, self.iwl
        k, js = ep.k, ep.js
        if o.wl_inertial and iwl.k_last >= 0 and iwl.k_last < k - 1 and self.snap_k != iwl.k_last:
            self._snapshot()
        iwl.new_arcs(ep.fresh, js[aid.used], self.t[k])
        col = np.r_[blocks[ZWD_KEY][0], [blocks[b.key][0] for b in aid.states[1:]]]
        est = np.r_[blocks[ZWD_KEY][1][0], [blocks[b.key][1][0] for b in aid.states[1:]]]
        used = aid.used
        fixes = []
        h_pos, m_wet, g, sin_el = self._wide_lane(aid, state, est[0], k, js[used], ep.clk_m[used])
        iref = self._reference(js[used], ep.fresh, sin_el, gap=iwl.k_last < k - 1)
        ref = used[iref]
        if o.ar and o.wl_inertial:
            H_sd = np.column_stack([h_pos - h_pos[iref], -(m_wet - m_wet[iref])])
            pz = np.r_[np.arange(N_INS)[DPOS], col[0]]
            rows, y_wl, R_wl = iwl.fix(js[used], js[ref], g, sin_el, self.t[k], H_sd, P[np.ix_(pz, pz)], self.wsb, o)
            if rows.size:  # the fixed wide-lanes as ranges: the position to centimetres for the narrow-lane
                H_wl = np.zeros((rows.size, P.shape[0]))
                H_wl[:, pz] = H_sd[rows]
                dx, P, _, _ = kalman.update(np.zeros(P.shape[0]), P, y_wl, H_wl, R_wl)
                fixes.append((dx, P))
                state = state.corrected(dx[PHI], dx[DV], dx[DPOS])
                est = est - dx[col]
                g = g - (h_pos @ dx[DPOS] - m_wet * dx[col[0]]) / LAM_WL_M
        _record(out, k, state, P)
        out.gnss[k], out.n_sats[k] = True, used.size
        held = _fix(out, k, state, P, est, col, js, used, ref, ep, (iwl.on, iwl.wl_cyc), self.wsb, o) if o.ar else None
        P_last = P
        if held is not None:
            g = g - (h_pos @ held[0][DPOS] - m_wet * held[0][col[0]]) / LAM_WL_M
            P_last = held[1]
        pz = np.r_[np.arange(N_INS)[DPOS], col[0]]
        iwl.store(js[used], g, sin_el, self.t[k], k, np.column_stack([h_pos, -m_wet]), P_last[np.ix_(pz, pz)])
        if o.bridge_fixed and held is not None and k + 1 < self.t.size and self.have_n[k + 1] < 2:
            # GNSS lost: the INS bridges the gap from the fixed solution, not the float one (every
            # ambiguity is dropped in the gap, so conditioning on the fixed ones loses nothing).
            fixes.append(held)
        return fixes

    def _reference(self, sv, fresh, sin_el, gap):
        """The reference of the SD ambiguities fixed (index into ``sv``), chosen as :mod:`leosop.gnss.ppp_ins` does.

        The float filter does not depend on it (:mod:`leosop.fusion.aids_gnss`),
        the wide-lane rule does (both arcs' lengths): kept while its arc goes
        on, else the highest satellite whose arc goes on (a reference
        change), else (after a gap, at the start) the highest.
        """
        was = self.ref_sv
        if gap:
            was = -1
        if not (was in sv and not fresh[was]):
            order = np.argsort(-sin_el)
            cand = [i for i in order if not fresh[sv[i]] and sv[i] in self.last_sv]
            if cand and was >= 0:
                self.ref_sv = int(sv[cand[0]])
                self.out.n_ref_changes += 1
            else:
                self.ref_sv = int(sv[order[0]])
        self.last_sv = set(sv.tolist())
        return int(np.flatnonzero(sv == self.ref_sv)[0])

    def _wide_lane(self, aid, state, zwd_m, k, sv, clk_m):
        """Range rows ``h_pos`` (m, 3), wet mappings, ``g`` [cycles] and sin(elevation) of the used satellites."""
        view = InsView(state, np.zeros(3), np.zeros(3), np.zeros(3))
        rho, _, los, elev, C = aid.geometry(view)
        used = aid.used
        m_dry, m_wet = models.niell_mapping(elev[used], state.lat_rad, state.alt_m, aid.doy + aid.t_orbit_s / DAY_S)
        zhd = models.saastamoinen_zhd_m(state.lat_rad, state.alt_m) * m_dry
        h_pos = los[used] @ C @ pos_jacobian(state.lat_rad, state.alt_m)
        g = (self.LW[k, sv] + clk_m - zhd - rho[used] - m_wet * zwd_m) / LAM_WL_M
        return h_pos, m_wet, g, np.sin(elev[used])

    def _snapshot(self):
        """The first aid after a gap: the old arcs' Melbourne-Wuebbena means, as at the gap's first epoch."""
        iwl = self.iwl
        k0 = iwl.k_last
        ep = next(e for e in self.epochs.values() if e.k == k0)
        mean, _ = _mw_mean(ep.mw_sum, ep.mw_sq, ep.mw_n)
        var_mean = _mw_var_mean(self.MW[:k0 + 1], ep.mw_n, mean, self.o.wl_mw_lags)
        iwl.snapshot(self.t, self.GF, self.new_arc, mean, var_mean, self.o.wl_iono_window_s)
        self.snap_k = k0


def _record(out, k, state, P):
    out.cov_ins[k] = P[:N_INS, :N_INS]
    out.pos_float_ecef_m[k] = geodetic_to_ecef(state.lat_rad, state.lon_rad, state.alt_m)
    J = pos_jacobian(state.lat_rad, state.alt_m)
    out.cov_pos_enu_m2[k] = J @ P[DPOS, DPOS] @ J.T


def _fix(out, k, state, P, est, col, js, used, ref, ep, inertial, wsb, o):
    """Wide-lanes rounded (or from the INS after a gap), narrow-lanes by LAMBDA; the fixed position into ``out``.

    As :func:`leosop.gnss.ppp_ins._fix` on the engine's state: the SD
    ambiguities are ``B_j - B_ref`` of the undifferenced ambiguity estimates
    ``est[1:]`` (columns ``col[1:]`` of ``P``), their covariance ``A P A^T``;
    the fixed ones condition the state: ``dx = P A^T (A P A^T)^-1 (A b_hat -
    b_fix)`` (error sense). Returns ``(dx, P conditioned)`` or None.
    """
    on, wl_cyc = inertial
    mean, var_mean = _mw_mean(ep.mw_sum, ep.mw_sq, ep.mw_n)
    others = used[used != ref]
    jo, jr = js[others], js[ref]
    by_ins = on[jo] & on[jr]
    wl_mw = mean[jo] - mean[jr] - (wsb[jo] - wsb[jr])
    n_mw = np.round(wl_mw)
    by_mw = ((ep.mw_n[jo] >= o.wl_min_epochs) & (ep.mw_n[jr] >= o.wl_min_epochs)
             & (np.abs(wl_mw - n_mw) < o.wl_tol_cyc) & (np.sqrt(var_mean[jo] + var_mean[jr]) < o.wl_se_max_cyc))
    n_wl = np.where(by_ins, np.round(wl_cyc[jo] - wl_cyc[jr] - (wsb[jo] - wsb[jr])), n_mw)
    out.n_wl_checked += int(np.sum(by_ins & by_mw))
    out.n_wl_mismatch += int(np.sum(by_ins & by_mw & (n_wl != n_mw)))
    good = by_ins | by_mw
    sel, n_wl = others[good], n_wl[good]
    out.n_wl[k] = sel.size
    if sel.size < o.min_fixed:
        return None
    A = np.zeros((sel.size, P.shape[0]))
    A[np.arange(sel.size), col[1 + sel]] = 1.0
    A[:, col[1 + ref]] -= 1.0
    d_hat = est[1 + sel] - est[1 + ref]
    fixed, n1, ratio = partial_fix((d_hat - BETA_M * n_wl) / LAM_NL_M, A @ P @ A.T / LAM_NL_M**2,
                                   ratio_min=o.ratio_min, min_fixed=o.min_fixed, success_min=o.success_min)
    out.ratio[k] = ratio
    if not fixed.any():
        return None
    Af = A[fixed]
    gain = np.linalg.solve(Af @ P @ Af.T, Af @ P).T  # (n_x, n_fixed)
    dx = gain @ (d_hat[fixed] - (LAM_NL_M * n1[fixed] + BETA_M * n_wl[fixed]))
    s = state.corrected(dpos=dx[DPOS])
    out.pos_fixed_ecef_m[k] = geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m)
    out.n_fixed[k] = fixed.sum()
    P_fixed = P - gain @ Af @ P
    return dx, 0.5 * (P_fixed + P_fixed.T)
