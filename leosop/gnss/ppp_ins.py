"""Tightly coupled PPP / INS with wide-lane then narrow-lane ambiguity resolution ([Liu 2016]), on the fusion engine.

The filter is :func:`leosop.fusion.engine.run` (the toolkit's strapdown INS,
the 15 INS errors of :mod:`leosop.ins.error_model`, closed-loop feedback)
with one :class:`leosop.fusion.aids_gnss.PppEpoch` aid per GNSS epoch:
between-satellite single-differenced (SD) ionosphere-free code and phase
and SD Doppler range rate, predicted at the INS position and velocity (the
receiver clock and its drift cancel), weights ``sigma / sin(elev)`` with
code:phase 1:100 ([Liu 2016]); the zenith wet delay (random walk) and one
undifferenced ionosphere-free ambiguity [m] per arc are engine state
blocks. [Liu 2016] writes the INS errors in ECEF; here they are the
toolkit's local-level errors, which is the same filter in another frame.

Arcs (:func:`ppp_aids`): a satellite's arc, its ambiguity and its
Melbourne-Wuebbena average restart at a cycle slip (loss-of-lock flag,
Melbourne-Wuebbena and geometry-free tests of
:func:`leosop.gnss.ppp_obs.detect_slips`), when it comes back above the
elevation mask, and after a gap (fewer than two satellites above the mask;
elevations at a code-only position per epoch). Outliers are screened per
row before the update (:meth:`leosop.fusion.aids_gnss.PppEpoch.screen`:
normalised innovations above ``k_outlier``); a phase outlier restarts that
satellite's ambiguity and its Melbourne-Wuebbena average.

Ambiguity resolution, after each epoch's update (:mod:`leosop.gnss.ppp_ins_ar`,
the engine's ``after_aid`` hook), on the float filter ([Liu 2016]: no
fix-and-hold): the SD wide-lanes from the arc means of the Melbourne-
Wuebbena combinations less the satellites' wide-lane biases, rounded when
within ``wl_tol_cyc`` of an integer; then the narrow-lanes
``N1 = (B_IF - beta N_WL) / lambda_NL`` (``beta = c f2 / (f1^2 - f2^2)``)
by LAMBDA with the ratio test (``ratio_min``), a bootstrapped success rate
of at least ``success_min`` and partial fixing (:mod:`leosop.gnss.lambda_`);
the fixed ambiguities condition the state (a noise-free pseudo-observation
on a copy) for the fixed solution. When the GNSS is lost after a fixed
epoch (``bridge_fixed``), the INS bridges the gap from that fixed solution
and its conditioned covariance rather than from the float one: every
ambiguity is dropped in the gap, so nothing is held beyond it, and the
outage starts from centimetres instead of the float solution's decimetre
(``tools/bench_ppp_ins_outage.py``).

After a gap every arc restarts; [Liu 2016]'s fast re-fix uses the INS:
with ``wl_inertial`` the new arcs' wide-lanes are fixed at the first
epochs from the wide-lane phase less the range predicted at the bridged
position (:class:`leosop.gnss.ppp_ins_widelane.InertialWideLane`), and the
fixed wide-lanes, as ranges, update the float solution; otherwise they wait
for the Melbourne-Wuebbena averages. A one-time update, so its
few-centimetre error stays in the new float ambiguities for tens of
minutes: on average it helps the float solution, at single seeds it can go
either way (``docs/ppp.md``).

Measured (``leosop reproduce ppp-ins``, ``tools/bench_ppp_ins.py``): on the
simulated car, 20 seeds of 15 min, the float-position NEES averaged over
the seeds is 2.57 (3 expected; inside its 95 % band at 95 % of epochs),
with the single-differenced filter this one replaced (issue 21; 2.54 on
the engine over 4 seeds where that gave 2.55).
"""

from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS
from ..frames import ecef_to_geodetic, geodetic_to_ecef
from ..fusion import engine
from ..fusion.aids_gnss import PppEpoch, ambiguity_block, zwd_block
from ..fusion.common import N_INS, initial_covariance
from .geometry import satellite_at_reception, satellite_clock
from .ppp import PppOptions
from .ppp_ins_ar import AfterEpoch
from .troposphere import mjd
from .ppp_ins_widelane import BETA_M, KAPPA_WL_PER_GF, LAM_NL_M, LAM_WL_M, if_combinations
from .ppp_obs import detect_slips, spp_position

__all__ = ["BETA_M", "KAPPA_WL_PER_GF", "LAM_NL_M", "LAM_WL_M", "PppInsOptions", "PppInsResult", "if_combinations",
           "ppp_aids", "run"]


@dataclass(frozen=True)
class PppInsOptions:
    """GNSS side of the filter (SI units; sigmas at zenith, ionosphere-free level)."""

    mask_deg: float = 10.0
    sigma_code_m: float = 0.9
    sigma_phase_m: float = 0.009
    sigma_rate_mps: float = 0.06
    zwd0_m: float = 0.1
    zwd_sigma_m: float = 0.1
    zwd_rw_m_per_rt_s: float = 1e-4
    amb_sigma_m: float = 5.0
    k_outlier: float = 5.0
    ar: bool = True
    ratio_min: float = 3.0
    success_min: float = 0.999
    min_fixed: int = 4
    wl_tol_cyc: float = 0.25
    wl_se_max_cyc: float = 0.1
    wl_min_epochs: int = 5
    bridge_fixed: bool = True
    wl_inertial: bool = True
    wl_inertial_window_s: float = 20.0
    wl_iono_window_s: float = 120.0
    wl_mw_lags: int = 10
    wl_phase_sigma_cyc: float = 0.015
    wl_success_min: float = 1.0 - 1e-4
    # The troposphere models of the float and fixed PPP (PppOptions; docs/ppp.md, "Models and settings").
    mapping: str = PppOptions.mapping
    zhd_pressure: str = PppOptions.zhd_pressure


@dataclass
class PppInsResult:
    """Per-epoch output, shapes (n_epochs, ...).

    Attributes
    ----------
    t_s : ndarray
    pos_float_ecef_m, pos_fixed_ecef_m : ndarray, shape (n, 3)
        Float solution (the INS after feedback) and the fixed one (NaN when
        no subset passes the ratio test).
    cov_pos_enu_m2 : ndarray, shape (n, 3, 3)
        Covariance of the float position, ENU.
    cov_ins : ndarray, shape (n, 15, 15)
        Covariance of the INS errors (:mod:`leosop.ins.error_model` order
        and units) after the epoch's update; in a gap, after the prediction
        (from the fixed solution's, with ``bridge_fixed``).
    n_sats, n_fixed, n_wl : ndarray of int
        Satellites used, narrow-lane and wide-lane ambiguities fixed.
    ratio : ndarray
    gnss : ndarray of bool
        A GNSS update was made.
    n_slips, n_outliers, n_ref_changes : int
        Arcs cut by a slip while tracked, rows screened as outliers,
        changes of the reference satellite of the fixed ambiguities.
    n_wl_checked, n_wl_mismatch : int
        Satellite-epochs where a wide-lane fixed from the INS geometry after
        a gap is also fixed by the Melbourne-Wuebbena rule on the same arc,
        and those where the two differ (the check of the inertial
        wide-lanes).
    """

    t_s: np.ndarray
    pos_float_ecef_m: np.ndarray
    pos_fixed_ecef_m: np.ndarray
    cov_pos_enu_m2: np.ndarray
    cov_ins: np.ndarray
    n_sats: np.ndarray
    n_fixed: np.ndarray
    n_wl: np.ndarray
    ratio: np.ndarray
    gnss: np.ndarray
    n_slips: int
    n_outliers: int
    n_ref_changes: int
    n_wl_checked: int = 0
    n_wl_mismatch: int = 0


def run(gnss, orbits, clocks, state0, dtheta_b_rad, dvel_b_mps, dt_s, settings, options=None):
    """Run the tightly coupled PPP/INS filter: float solution and, with ``options.ar``, the fixed one.

    Parameters
    ----------
    gnss : leosop.gnss.simulate.GnssSim
        Observations (the fields ``t_s, sv, orb_idx, clk_idx, P1_m, P2_m,
        L1_cyc, L2_cyc, rate_mps, lli, wsb_cyc``); epoch k is at
        ``gnss.t_s[0] + k * settings.step_s``.
    orbits, clocks : leosop.gnss.products.Orbits, Clocks
    state0 : leosop.ins.strapdown.NavState
        INS state at the first epoch.
    dtheta_b_rad, dvel_b_mps : ndarray, shape (n_imu, 3)
        Measured IMU increments from the first epoch on; an even number of
        them per GNSS epoch (the engine's INS updates take pairs).
    dt_s : float
    settings : leosop.fusion.common.FilterSettings
        INS priors and IMU noise (the biases have no random walk); ``step_s``
        is the GNSS interval.
    options : PppInsOptions, optional
        None: the defaults.

    Returns
    -------
    PppInsResult
        At the GNSS epochs. The filter's clock is the GNSS time ``gnss.t_s``;
        the IMU increments end at ``gnss.t_s[0] + (i + 1) dt_s``.
    """
    options = PppInsOptions() if options is None else options
    per = round(settings.step_s / dt_s)
    if per % 2:
        raise ValueError(f"{per=} IMU increments per GNSS epoch: an even number is needed")
    n_ep = min(len(gnss.t_s), dtheta_b_rad.shape[0] // per + 1)
    n_imu = (n_ep - 1) * per
    t_imu = gnss.t_s[0] + np.arange(1, n_imu + 1) * dt_s
    t_filter = np.r_[t_imu[0] - dt_s, t_imu[per - 1::per]]  # the engine's own record times, exactly
    aids, epochs, n_slips = ppp_aids(gnss, orbits, clocks, n_ep, t_filter, settings.step_s, options,
                                     geodetic_to_ecef(state0.lat_rad, state0.lon_rad, state0.alt_m))
    out = PppInsResult(t_s=gnss.t_s[:n_ep], pos_float_ecef_m=np.full((n_ep, 3), np.nan),
                       pos_fixed_ecef_m=np.full((n_ep, 3), np.nan), cov_pos_enu_m2=np.full((n_ep, 3, 3), np.nan),
                       cov_ins=np.full((n_ep, N_INS, N_INS), np.nan), n_sats=np.zeros(n_ep, int),
                       n_fixed=np.zeros(n_ep, int), n_wl=np.zeros(n_ep, int), ratio=np.full(n_ep, np.nan),
                       gnss=np.zeros(n_ep, bool), n_slips=n_slips, n_outliers=0, n_ref_changes=0)
    hook = AfterEpoch(gnss, n_ep, out, dict(zip(map(id, aids), epochs)), options)
    es = engine.EngineSettings(settings.gyro_arw_rad_per_rt_s, settings.accel_vrw_mps2_per_rt_hz, 0.0, 0.0,
                               step_s=settings.step_s, record_every=per // 2, record_cov_ins=True)
    P0 = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    res = engine.run(state0, P0, t_imu, np.full(n_imu, dt_s), dtheta_b_rad[:n_imu], dvel_b_mps[:n_imu], aids, es,
                     after_aid=hook)
    gap = ~out.gnss  # recorded once per GNSS epoch, after its covariance propagation
    out.pos_float_ecef_m[gap] = geodetic_to_ecef(res.lat_rad[gap], res.lon_rad[gap], res.alt_m[gap])
    out.cov_pos_enu_m2[gap] = res.cov_pos_enu_m2[gap]
    out.cov_ins[gap] = res.cov_ins[gap]
    return out


def ppp_aids(gnss, orbits, clocks, n_ep, t_filter_s, step_s, options, pos_approx_ecef_m):
    """One :class:`PppEpoch` per GNSS epoch with at least two satellites above the mask.

    Elevations from a code-only position of the epoch
    (:func:`leosop.gnss.ppp_obs.spp_position`, metres, so the mask falls as
    at the INS; the last one, else ``pos_approx_ecef_m``, with fewer than 4
    satellites). A satellite's arc restarts at a slip, when it comes back
    above the mask and after a gap. The undifferenced ambiguities' common
    mode is not observed (the SD rows see only differences): where every arc
    starts afresh (the first epoch, after a gap) the highest satellite's
    ambiguity is the datum, prior sigma zero, the others ``amb_sigma_m``
    each, which gives the SD ambiguities against it independent priors of
    ``amb_sigma_m``; elsewhere a new arc's ``amb_sigma_m`` is its SD prior
    too, the others' common mode being known through the datum.

    Parameters
    ----------
    gnss : leosop.gnss.simulate.GnssSim
        As :func:`run`.
    orbits, clocks : leosop.gnss.products.Orbits, Clocks
    n_ep : int
        Epochs used.
    t_filter_s : ndarray, shape (n_ep,)
        The epochs on the filter's clock.
    step_s : float
        GNSS interval (an arc ends at a gap longer than 1.5 of it).
    options : PppInsOptions
    pos_approx_ecef_m : ndarray, shape (3,)
        The receiver's position, roughly (the start of the code-only solutions).

    Returns
    -------
    aids : list of PppEpoch
    epochs : list of _Epoch
        Per aid: its epoch, satellites, arcs and satellite clocks.
    n_slips : int
        Arcs cut by a slip while their satellite was tracked above the mask.
    """
    Pc, Lc, MW, GF = if_combinations(gnss.P1_m[:n_ep], gnss.P2_m[:n_ep], gnss.L1_cyc[:n_ep], gnss.L2_cyc[:n_ep])
    t = gnss.t_s[:n_ep]
    have = np.isfinite(Pc) & np.isfinite(Lc)
    new_arc = detect_slips(t, MW, GF, gnss.lli[:n_ep], have, PppOptions(max_gap_s=1.5 * step_s))
    mjd0 = mjd(orbits.ref_gps)
    zwd = zwd_block(options)
    n_sv = len(gnss.sv)
    arc = [None] * n_sv
    seen = np.zeros(n_sv, bool)
    mw_sum, mw_sq, mw_n = np.zeros(n_sv), np.zeros(n_sv), np.zeros(n_sv, int)
    pos = np.asarray(pos_approx_ecef_m, float)
    # Satellite clocks and positions of every observation at once (light time from the rough position:
    # 50 km off moves a satellite by 0.7 m, far below what the mask and the code position need).
    kk, jj = np.nonzero(have)
    clk_all, drift_all, rs_all = np.zeros((n_ep, n_sv)), np.zeros((n_ep, n_sv)), np.zeros((n_ep, n_sv, 3))
    clk_all[kk, jj], drift_all[kk, jj] = satellite_clock(orbits, clocks, gnss.orb_idx[jj], gnss.clk_idx[jj],
                                                         t[kk] - gnss.P1_m[kk, jj] / C_MPS)
    rs_all[kk, jj] = satellite_at_reception(orbits, gnss.orb_idx[jj], t[kk], pos)[0]
    aids, arcs, n_slips = [], [], 0
    for k in range(n_ep):
        js = np.flatnonzero(have[k])
        clk_m, drift_mps, rs = clk_all[k, js], drift_all[k, js], rs_all[k, js]
        if js.size >= 2:
            if js.size >= 4:
                pos = spp_position(rs, Pc[k, js] + clk_m, iterations=4 if k else 8)
            lat, lon, _ = ecef_to_geodetic(pos)
            up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
            sin_el = (rs - pos) @ up / np.linalg.norm(rs - pos, axis=1)
            above = sin_el > np.sin(np.radians(options.mask_deg))
            js, clk_m, drift_mps, sin_el = js[above], clk_m[above], drift_mps[above], sin_el[above]
        if js.size < 2:
            js = js[:0]
        n_slips += int(np.sum(new_arc[k, js] & seen[js]))
        starts = js[new_arc[k, js] | ~seen[js]]
        sigma = np.full(n_sv, options.amb_sigma_m)
        if js.size and starts.size == js.size:
            sigma[js[np.argmax(sin_el)]] = 0.0  # the datum: the highest satellite
        for j in starts:
            arc[j] = ambiguity_block(gnss.sv[j], t[k], Lc[k, j] - Pc[k, j], sigma[j], step_s)
        seen[:] = False
        seen[js] = True
        fresh = np.ones(n_sv, bool)  # a Melbourne-Wuebbena arc restarts with the ambiguity's, and in a gap
        fresh[js] = False
        fresh[starts] = True
        mw_sum[fresh], mw_sq[fresh], mw_n[fresh] = 0.0, 0.0, 0
        if not js.size:
            continue
        mw_sum[js] += MW[k, js]
        mw_sq[js] += MW[k, js] ** 2
        mw_n[js] += 1
        arcs.append(_Epoch(k, js, fresh, mw_sum.copy(), mw_sq.copy(), mw_n.copy(), clk_m))
        aids.append(PppEpoch(t_filter_s[k], t[k], orbits, gnss.orb_idx[js], Pc[k, js] + clk_m, Lc[k, js] + clk_m,
                             gnss.rate_mps[k, js] + drift_mps, [arc[j] for j in js], zwd, mjd0, options))
    return aids, arcs, n_slips


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
