"""Tight PPP/INS as a composition of the fusion engine: the float solution (first step of issue 21).

The observations of :func:`leosop.gnss.ppp_ins.run` become one
:class:`leosop.fusion.aids_gnss.PppEpoch` aid per GNSS epoch (SD IF code,
phase and range rate; the wet delay and one undifferenced ambiguity per arc
as engine state blocks; arcs cut by :func:`leosop.gnss.ppp_obs.detect_slips`)
and :func:`leosop.fusion.engine.run` is the filter. What the engine cannot
host yet, and :mod:`leosop.gnss.ppp_ins` still does in its own loop: the
per-row outlier screening (it needs ``P`` before the update), ambiguity
fixing on the float filter and the bridge from the fixed solution into a gap
(they read and replace the engine's ``P`` and states after an update), and
the inertial wide-lane re-fix after a gap.
"""

import numpy as np

from ..constants import C_MPS
from ..frames import geodetic_to_ecef
from ..fusion import engine
from ..fusion.aids_gnss import PppEpoch, ambiguity_block, zwd_block
from ..fusion.common import N_INS, initial_covariance
from .geometry import satellite_clock
from .ppp import PppOptions
from .ppp_ins import PppInsOptions, PppInsResult, if_combinations
from .ppp_obs import detect_slips

__all__ = ["ppp_aids", "run_float"]


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
    list of PppEpoch
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
    aids = []
    for k in range(n_ep):
        js = np.flatnonzero(have[k])
        for j in js[new_arc[k, js] | ~seen[js]]:
            arc[j] = ambiguity_block(gnss.sv[j], t[k], Lc[k, j] - Pc[k, j], options.amb_sigma_m, step_s)
        seen[:] = False
        seen[js] = True
        if js.size < 2:
            continue
        clk_m, drift_mps = satellite_clock(orbits, clocks, gnss.orb_idx[js], gnss.clk_idx[js],
                                           t[k] - gnss.P1_m[k, js] / C_MPS)
        aids.append(PppEpoch(t_filter_s[k], t[k], orbits, gnss.orb_idx[js], Pc[k, js] + clk_m, Lc[k, js] + clk_m,
                             gnss.rate_mps[k, js] + drift_mps, [arc[j] for j in js], zwd, doy, options))
    return aids


def run_float(gnss, orbits, clocks, state0, dtheta_b_rad, dvel_b_mps, dt_s, settings, options=None):
    """The float PPP/INS solution on the engine (no outlier screening, no ambiguity fixing).

    Arguments as :func:`leosop.gnss.ppp_ins.run` (``options`` None: the
    defaults of :class:`PppInsOptions`). The filter's clock is the
    GNSS time ``gnss.t_s``; the IMU increments end at ``gnss.t_s[0] + (i + 1)
    dt_s``; the INS biases have no random walk (as :mod:`leosop.gnss.ppp_ins`).

    Returns
    -------
    PppInsResult
        Float positions and their ENU covariance at the GNSS epochs;
        ``pos_fixed_ecef_m`` NaN, ``cov_ins`` NaN (the engine keeps only the
        sigmas of the INS errors), the counters zero.
    """
    options = PppInsOptions() if options is None else options
    per = round(settings.step_s / dt_s)
    n_ep = min(len(gnss.t_s), dtheta_b_rad.shape[0] // per + 1)
    n_imu = (n_ep - 1) * per
    t_imu = gnss.t_s[0] + np.arange(1, n_imu + 1) * dt_s
    t_filter = np.r_[t_imu[0] - dt_s, t_imu[per - 1::per]]  # the engine's own record times, exactly
    aids = ppp_aids(gnss, orbits, clocks, n_ep, t_filter, settings.step_s, options)
    es = engine.EngineSettings(settings.gyro_arw_rad_per_rt_s, settings.accel_vrw_mps2_per_rt_hz, 0.0, 0.0,
                               step_s=settings.step_s)
    P0 = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    res = engine.run(state0, P0, t_imu, np.full(n_imu, dt_s), dtheta_b_rad[:n_imu], dvel_b_mps[:n_imu], aids, es)
    rec = np.arange(n_ep) * (per // 2)
    pos = geodetic_to_ecef(res.lat_rad[rec], res.lon_rad[rec], res.alt_m[rec])
    n_sats = np.zeros(n_ep, int)
    k_aid = np.searchsorted(t_filter, [a.t_s for a in aids])
    n_sats[k_aid] = [a.orb_idx.size for a in aids]
    return PppInsResult(t_s=gnss.t_s[:n_ep], pos_float_ecef_m=np.asarray(pos).reshape(n_ep, 3),
                        pos_fixed_ecef_m=np.full((n_ep, 3), np.nan), cov_pos_enu_m2=res.cov_pos_enu_m2[rec],
                        cov_ins=np.full((n_ep, N_INS, N_INS), np.nan), n_sats=n_sats, n_fixed=np.zeros(n_ep, int),
                        n_wl=np.zeros(n_ep, int), ratio=np.full(n_ep, np.nan), gnss=n_sats > 0, n_slips=0,
                        n_outliers=0, n_ref_changes=0)
