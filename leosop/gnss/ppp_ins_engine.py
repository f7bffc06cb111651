"""Tight PPP/INS as a composition of the fusion engine: float solution and ambiguity fixing (issue 21).

The observations of :func:`leosop.gnss.ppp_ins.run` become one
:class:`leosop.fusion.aids_gnss.PppEpoch` aid per GNSS epoch (SD IF code,
phase and range rate; the wet delay and one undifferenced ambiguity per arc
as engine state blocks; arcs cut by :func:`leosop.gnss.ppp_obs.detect_slips`)
and :func:`leosop.fusion.engine.run` is the filter. Ambiguity fixing reads
the float filter after each epoch (the engine's ``after_aid`` hook) as
:mod:`leosop.gnss.ppp_ins` does: SD wide-lanes rounded from the arcs'
Melbourne-Wuebbena means, narrow-lanes by LAMBDA with partial fixing, the
fixed position the float one conditioned on them (no fix-and-hold). Not
hosted yet, and still done by :mod:`leosop.gnss.ppp_ins` in its own loop:
the per-row outlier screening (it needs ``P`` before the update), the bridge
from the fixed solution into a gap and the inertial wide-lane re-fix after
it (they replace the engine's ``P`` and states).
"""

import numpy as np

from ..constants import C_MPS
from ..frames import geodetic_to_ecef
from ..fusion import engine
from ..fusion.aids_gnss import PppEpoch, ambiguity_block, zwd_block
from ..fusion.common import N_INS, initial_covariance
from ..ins.error_model import DPOS
from .geometry import satellite_clock
from .lambda_ import partial_fix
from .ppp import PppOptions
from .ppp_ins import (
    BETA_M,
    LAM_NL_M,
    PppInsOptions,
    PppInsResult,
    _mw_mean,
    if_combinations,
)
from .ppp_obs import detect_slips

__all__ = ["ppp_aids", "run"]


def ppp_aids(gnss, orbits, clocks, n_ep, t_filter_s, step_s, options):
    """One :class:`PppEpoch` per GNSS epoch with at least two satellites.

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

    Returns
    -------
    aids : list of PppEpoch
    arcs : list of tuple
        Per aid: its satellites (indices into ``gnss.sv``, shape (m,)) and
        the Melbourne-Wuebbena means of their arcs up to that epoch, the
        variances of the means from the scatter and the counts, each (m,).
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
        for j in starts:
            arc[j] = ambiguity_block(gnss.sv[j], t[k], Lc[k, j] - Pc[k, j], options.amb_sigma_m, step_s)
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
        mean, var_mean = _mw_mean(mw_sum[js], mw_sq[js], mw_n[js])
        arcs.append((js, mean, var_mean, mw_n[js].copy()))
        clk_m, drift_mps = satellite_clock(orbits, clocks, gnss.orb_idx[js], gnss.clk_idx[js],
                                           t[k] - gnss.P1_m[k, js] / C_MPS)
        aids.append(PppEpoch(t_filter_s[k], t[k], orbits, gnss.orb_idx[js], Pc[k, js] + clk_m, Lc[k, js] + clk_m,
                             gnss.rate_mps[k, js] + drift_mps, [arc[j] for j in js], zwd, doy, options))
    return aids, arcs


def run(gnss, orbits, clocks, state0, dtheta_b_rad, dvel_b_mps, dt_s, settings, options=None):
    """PPP/INS on the engine: float solution and, with ``options.ar``, the fixed one.

    Arguments as :func:`leosop.gnss.ppp_ins.run` (``options`` None: the
    defaults of :class:`PppInsOptions`; ``k_outlier``, ``bridge_fixed`` and
    the ``wl_inertial*`` options are not used). The filter's clock is the
    GNSS time ``gnss.t_s``; the IMU increments end at ``gnss.t_s[0] + (i + 1)
    dt_s``; the INS biases have no random walk (as :mod:`leosop.gnss.ppp_ins`).

    Returns
    -------
    PppInsResult
        At the GNSS epochs; ``cov_ins`` NaN (the engine keeps only the sigmas
        of the INS errors), the counters of slips, outliers, reference
        changes and inertial wide-lanes zero.
    """
    options = PppInsOptions() if options is None else options
    per = round(settings.step_s / dt_s)
    n_ep = min(len(gnss.t_s), dtheta_b_rad.shape[0] // per + 1)
    n_imu = (n_ep - 1) * per
    t_imu = gnss.t_s[0] + np.arange(1, n_imu + 1) * dt_s
    t_filter = np.r_[t_imu[0] - dt_s, t_imu[per - 1::per]]  # the engine's own record times, exactly
    aids, arcs = ppp_aids(gnss, orbits, clocks, n_ep, t_filter, settings.step_s, options)
    out = PppInsResult(t_s=gnss.t_s[:n_ep], pos_float_ecef_m=np.full((n_ep, 3), np.nan),
                       pos_fixed_ecef_m=np.full((n_ep, 3), np.nan), cov_pos_enu_m2=np.full((n_ep, 3, 3), np.nan),
                       cov_ins=np.full((n_ep, N_INS, N_INS), np.nan), n_sats=np.zeros(n_ep, int),
                       n_fixed=np.zeros(n_ep, int), n_wl=np.zeros(n_ep, int), ratio=np.full(n_ep, np.nan),
                       gnss=np.zeros(n_ep, bool), n_slips=0, n_outliers=0, n_ref_changes=0)
    epoch = {id(a): (int(k), arc) for a, k, arc in zip(aids, np.searchsorted(t_filter, [a.t_s for a in aids]), arcs)}

    def after_aid(aid, state, P, blocks):
        k, arc = epoch[id(aid)]
        out.gnss[k], out.n_sats[k] = True, aid.used.size
        if options.ar:
            _fix(out, k, aid, arc, state, P, blocks, gnss.wsb_cyc, options)

    es = engine.EngineSettings(settings.gyro_arw_rad_per_rt_s, settings.accel_vrw_mps2_per_rt_hz, 0.0, 0.0,
                               step_s=settings.step_s)
    P0 = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    res = engine.run(state0, P0, t_imu, np.full(n_imu, dt_s), dtheta_b_rad[:n_imu], dvel_b_mps[:n_imu], aids, es,
                     after_aid=after_aid)
    rec = np.arange(n_ep) * (per // 2)
    out.pos_float_ecef_m[:] = geodetic_to_ecef(res.lat_rad[rec], res.lon_rad[rec], res.alt_m[rec])
    out.cov_pos_enu_m2[:] = res.cov_pos_enu_m2[rec]
    return out


def _fix(out, k, aid, arc, state, P, blocks, wsb, o):
    """Wide-lanes rounded, narrow-lanes by LAMBDA on the float filter; the fixed position into ``out``.

    ``arc`` is the epoch's entry of :func:`ppp_aids`. The SD ambiguities are
    ``B_j - B_ref`` of the undifferenced ambiguity blocks, their covariance
    ``A P A^T``; the fixed ones condition the INS position error estimate:
    ``dx = P A^T (A P A^T)^-1 (A b_hat - b_fix)`` (error = estimate - truth).
    """
    js, mean, var_mean, mw_n = arc
    used, ref = aid.used, aid.ref
    others = used[used != ref]
    wl_mw = mean[others] - mean[ref] - (wsb[js[others]] - wsb[js[ref]])
    n_wl = np.round(wl_mw)
    good = ((mw_n[others] >= o.wl_min_epochs) & (mw_n[ref] >= o.wl_min_epochs) & (np.abs(wl_mw - n_wl) < o.wl_tol_cyc)
            & (np.sqrt(var_mean[others] + var_mean[ref]) < o.wl_se_max_cyc))
    jo, n_wl = others[good], n_wl[good]
    out.n_wl[k] = jo.size
    if jo.size < o.min_fixed:
        return
    col = np.array([blocks[b.key][0] for b in aid.states[1:]])
    b_hat = np.array([blocks[b.key][1][0] for b in aid.states[1:]])
    A = np.zeros((jo.size, P.shape[0]))
    A[np.arange(jo.size), col[jo]] = 1.0
    A[:, col[ref]] -= 1.0
    d_hat = b_hat[jo] - b_hat[ref]
    fixed, n1, ratio = partial_fix((d_hat - BETA_M * n_wl) / LAM_NL_M, A @ P @ A.T / LAM_NL_M**2,
                                   ratio_min=o.ratio_min, min_fixed=o.min_fixed, success_min=o.success_min)
    out.ratio[k] = ratio
    if not fixed.any():
        return
    Af = A[fixed]
    dx = P @ Af.T @ np.linalg.solve(Af @ P @ Af.T, d_hat[fixed] - (LAM_NL_M * n1[fixed] + BETA_M * n_wl[fixed]))
    s = state.corrected(dpos=dx[DPOS])
    out.pos_fixed_ecef_m[k] = geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m)
    out.n_fixed[k] = fixed.sum()
