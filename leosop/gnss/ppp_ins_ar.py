"""Ambiguity resolution of PPP/INS, run after each epoch's update (the fusion engine's ``after_aid`` hook).

:class:`AfterEpoch` records the float solution, fixes the wide-lanes from
the INS geometry after a gap (and updates the float filter with them as
ranges), rounds the SD wide-lanes from the arcs' Melbourne-Wuebbena means,
fixes the narrow-lanes by LAMBDA with partial fixing on the float filter
(no fix-and-hold; :func:`_fix`), and before a gap hands the engine the
fixed solution to bridge it from. See :mod:`leosop.gnss.ppp_ins`.
"""

import numpy as np

from ..frames import geodetic_to_ecef
from ..fusion import kalman
from ..fusion.aids import InsView
from ..fusion.aids_gnss import ZWD_KEY
from ..fusion.common import N_INS, pos_jacobian
from ..ins.error_model import DPOS, DV, PHI
from .lambda_ import partial_fix
from .ppp import PppOptions
from .ppp_ins_widelane import BETA_M, LAM_NL_M, LAM_WL_M, InertialWideLane, if_combinations, mw_mean, mw_var_mean
from .ppp_obs import detect_slips

__all__ = ["AfterEpoch"]


class AfterEpoch:
    """The engine's ``after_aid`` hook: records the float solution, fixes, re-fixes wide-lanes, bridges gaps.

    On the engine's state: error sense ``estimate - truth`` for the wet
    delay and the ambiguities too (hence the wet delay's sign in the rows
    given to :class:`leosop.gnss.ppp_ins_widelane.InertialWideLane`, which
    keeps corrections).

    Parameters
    ----------
    gnss : leosop.gnss.simulate.GnssSim
    n_ep : int
    out : leosop.gnss.ppp_ins.PppInsResult
        Filled in at each GNSS epoch.
    epochs : dict of int to leosop.gnss.ppp_ins._Epoch
        Each aid's epoch, by ``id(aid)``.
    o : leosop.gnss.ppp_ins.PppInsOptions
    """

    def __init__(self, gnss, n_ep, out, epochs, o):
        Pc, Lc, self.MW, self.GF = if_combinations(gnss.P1_m[:n_ep], gnss.P2_m[:n_ep], gnss.L1_cyc[:n_ep],
                                                   gnss.L2_cyc[:n_ep])
        self.t = gnss.t_s[:n_ep]
        self.aid_k = {e.k for e in epochs.values()}  # epochs with an aid: the others are gaps
        self.new_arc = detect_slips(self.t, self.MW, self.GF, gnss.lli[:n_ep], np.isfinite(Pc) & np.isfinite(Lc),
                                    PppOptions(max_gap_s=1.5 * (self.t[1] - self.t[0]) if n_ep > 1 else 1.0))
        self.LW = (gnss.L1_cyc[:n_ep] - gnss.L2_cyc[:n_ep]) * LAM_WL_M
        self.wsb = gnss.wsb_cyc
        self.out, self.epochs, self.o = out, epochs, o
        self.iwl = InertialWideLane(len(gnss.sv))
        self.snap_k = -1  # the last epoch before the gap the inertial wide-lanes were prepared for
        self.ref_sv, self.last_sv = -1, set()
        # Melbourne-Wuebbena sums, squares, counts at each arc's last restart by an outlier ((3, n_sv)); the
        # last epoch's sums less them (for the snapshot before a gap).
        self.mw_base = np.zeros((3, len(gnss.sv)))
        self.mw_last = None

    def __call__(self, aid, state, P, blocks):
        if aid.used.size < 2:  # all but one below the mask at the INS (the builder's code position saw more)
            return None
        ep, o, out, iwl = self.epochs[id(aid)], self.o, self.out, self.iwl
        k, js = ep.k, ep.js
        if o.wl_inertial and iwl.k_last >= 0 and iwl.k_last < k - 1 and self.snap_k != iwl.k_last:
            self._snapshot()
        iwl.new_arcs(ep.fresh, js[aid.used], self.t[k])
        # A phase outlier restarted its satellite's ambiguity (PppEpoch.screen): its MW average restarts too.
        self.mw_base[:, ep.fresh] = 0.0
        self.mw_base[:, js[aid.restarted]] = np.stack([ep.mw_sum, ep.mw_sq, ep.mw_n])[:, js[aid.restarted]]
        out.n_outliers += aid.n_outliers
        mw = (ep.mw_sum - self.mw_base[0], ep.mw_sq - self.mw_base[1], ep.mw_n - self.mw_base[2].astype(int))
        self.mw_last = mw
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
        held = _fix(out, k, state, P, est, col, js, used, ref, mw, (iwl.on, iwl.wl_cyc), self.wsb, o) if o.ar else None
        P_last = P
        if held is not None:
            g = g - (h_pos @ held[0][DPOS] - m_wet * held[0][col[0]]) / LAM_WL_M
            P_last = held[1]
        pz = np.r_[np.arange(N_INS)[DPOS], col[0]]
        iwl.store(js[used], g, sin_el, self.t[k], k, np.column_stack([h_pos, -m_wet]), P_last[np.ix_(pz, pz)])
        if o.bridge_fixed and held is not None and k + 1 < self.t.size and k + 1 not in self.aid_k:
            # GNSS lost: the INS bridges the gap from the fixed solution, not the float one (every
            # ambiguity is dropped in the gap, so conditioning on the fixed ones loses nothing).
            fixes.append(held)
        return fixes

    def _reference(self, sv, fresh, sin_el, gap):
        """The reference of the SD ambiguities fixed (index into ``sv``), as [Liu 2016]'s SD filter chose it.

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
        zhd, m_wet = aid.troposphere(elev[used], state)
        h_pos = los[used] @ C @ pos_jacobian(state.lat_rad, state.alt_m)
        g = (self.LW[k, sv] + clk_m - zhd - rho[used] - m_wet * zwd_m) / LAM_WL_M
        return h_pos, m_wet, g, np.sin(elev[used])

    def _snapshot(self):
        """The first aid after a gap: the old arcs' Melbourne-Wuebbena means, as at the gap's first epoch."""
        iwl = self.iwl
        k0 = iwl.k_last
        mw_sum, mw_sq, mw_n = self.mw_last
        mean, _ = mw_mean(mw_sum, mw_sq, mw_n)
        var_mean = mw_var_mean(self.MW[:k0 + 1], mw_n, mean, self.o.wl_mw_lags)
        iwl.snapshot(self.t, self.GF, self.new_arc, mean, var_mean, self.o.wl_iono_window_s)
        self.snap_k = k0


def _record(out, k, state, P):
    out.cov_ins[k] = P[:N_INS, :N_INS]
    out.pos_float_ecef_m[k] = geodetic_to_ecef(state.lat_rad, state.lon_rad, state.alt_m)
    J = pos_jacobian(state.lat_rad, state.alt_m)
    out.cov_pos_enu_m2[k] = J @ P[DPOS, DPOS] @ J.T


def _fix(out, k, state, P, est, col, js, used, ref, mw, inertial, wsb, o):
    """Wide-lanes rounded (or from the INS after a gap), narrow-lanes by LAMBDA; the fixed position into ``out``.

    ``mw``: the Melbourne-Wuebbena arcs' sums, sums of squares and counts
    ((n_sv,) each); a SD wide-lane is rounded when both arcs have
    ``wl_min_epochs``, the standard error of the SD mean is below
    ``wl_se_max_cyc`` and the rounding is below ``wl_tol_cyc``. ``inertial``:
    which satellites have a wide-lane fixed from the INS geometry after a gap
    and its value (:class:`leosop.gnss.ppp_ins_widelane.InertialWideLane`),
    used where the reference has one too. The SD
    ambiguities are ``B_j - B_ref`` of the undifferenced ambiguity estimates
    ``est[1:]`` (columns ``col[1:]`` of ``P``), their covariance ``A P A^T``;
    the fixed ones condition the state: ``dx = P A^T (A P A^T)^-1 (A b_hat -
    b_fix)`` (error sense). Returns ``(dx, P conditioned)`` or None.
    """
    on, wl_cyc = inertial
    mw_sum, mw_sq, mw_n = mw
    mean, var_mean = mw_mean(mw_sum, mw_sq, mw_n)
    others = used[used != ref]
    jo, jr = js[others], js[ref]
    by_ins = on[jo] & on[jr]
    wl_mw = mean[jo] - mean[jr] - (wsb[jo] - wsb[jr])
    n_mw = np.round(wl_mw)
    by_mw = ((mw_n[jo] >= o.wl_min_epochs) & (mw_n[jr] >= o.wl_min_epochs)
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
