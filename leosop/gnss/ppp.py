"""Precise point positioning (PPP), static or kinematic, GPS + Galileo; float, and fixed with ``ar``.

Ambiguity fixing (:mod:`leosop.gnss.ar`) runs on each epoch of this float
filter and conditions a copy of it; the float filter itself is never
changed by a fix.

Observations: dual-frequency ionosphere-free (IF) code and phase, GPS
C1W/C2W (C1C when C1W is missing) with L1C/L2W, Galileo C1C/C5Q with
L1C/L5Q, the pairs of the IGS / MGEX clock products. Undifferenced
formulation: the receiver clock of each system is a state, re-estimated
every epoch with no memory (white noise), which for float ambiguities is
equivalent to the between-satellite single differences of [Liu 2016] (the
clock eliminated) without the bookkeeping of reference-satellite changes;
ambiguities are undifferenced float IF ambiguities, one state per
satellite, reset on a cycle slip or a new arc.

State ``x``: ``[x, y, z (marker, ECEF m), clk_G, clk_E (m), ZWD (m),
G_N, G_E (troposphere gradients, m; with ``gradients``), N_1 .. N_n (IF
ambiguities, m), c_1 .. c_n (time-correlated phase errors, m)]``.

Models (``leosop.gnss.models``): precise orbit and clock interpolation,
relativistic clock term, Sagnac rotation, Shapiro delay, Saastamoinen
hydrostatic delay with [Boehm 2006]'s global mapping functions (GMF; or
[Niell 1996]'s with ``mapping="niell"``) and an estimated
zenith wet delay (random walk), optionally north and east troposphere
gradients with [Chen 1997]'s mapping (random walks; ``gradients``, off by
default), phase wind-up, solid Earth tide, antenna reference point height
from the RINEX header; with an ANTEX file
(:mod:`leosop.gnss.antex`), the receiver antenna's offset and elevation-
dependent variations and the satellites' offsets (nominal yaw; satellites
without a block valid on the day are left out, ``PppResult.no_antenna``).
Not modelled: satellite antenna variations, ocean loading, eclipse yaw
manoeuvres. Without ANTEX the receiver offset alone
(4.3 cm up, ionosphere-free, for ESBC00DNK's ASH701945E_M) goes into the
height.

Noise. White: ``sigma^2 = sigma_0^2 (1 + 1 / sin^2(elev)) / 2`` (an
elevation-independent floor plus the elevation-dependent part, equal at 90
deg), code:phase standard deviations 100:1 as in [Liu 2016], at the
ionosphere-free level: 0.3 m and 3 mm on each frequency become 0.9 m and 9
mm (the IF combination multiplies white noise by ``sqrt(g1^2 + g2^2) =
2.98`` for L1/L2). Time-correlated: phase multipath and what the models
leave (antenna variations, troposphere asymmetry) do not average out over
30 s epochs; with white noise only the filter believed its phase to the
millimetre after an hour while ESBC00DNK's errors wandered by centimetres
(about half of the kinematic epoch-axis errors within 3 sigma, static 3.2
cm off against 1.1 mm sigma at 6 h). Each satellite's phase carries a
first-order Gauss-Markov error state ``c_j`` (``phase_gm_sigma_m`` at 90
deg with the same elevation factor, correlation time ``phase_gm_tau_s``,
reset with the ambiguity), the standard state augmentation for coloured
measurement noise ([Gelb 1974] sec. 4.5). Errors that stay for hours
(the reference coordinate's own uncertainty, the antenna calibration's, the
effects not modelled) are not a process of the filter: the reported sigma
adds a floor in quadrature (``floor_enu_m``; with no ANTEX the larger
``floor_no_antex_enu_m``, for the unmodelled offsets), outside the gain,
so it changes no estimate; its values were set from the one day with
observations here (ESBC00DNK, 24 h, against its ITRF2014 coordinate):
with ANTEX, kinematic 3-D RMS after 2 h 4.3 cm, 99.0 % of epoch-axis
errors within 3 sigma (66.5 % within 1); static final 1.2 cm, within 1.4
sigma at 1, 3, 6 and 24 h; without ANTEX 99.99 % within 3 sigma.

Cycle slips: Melbourne-Wuebbena jump against its
running arc mean and geometry-free phase jump between epochs, plus the
receiver's loss-of-lock flag. Outliers: normalised
innovations above ``k_outlier`` are removed one at a time (a phase outlier
resets that satellite's ambiguity, a code outlier drops the code); the
clock's 100 m prior is in every row's variance, so only gross errors reach
the threshold (docs/ppp.md, "One system alone").

Time: GPS time inside (``t_s`` seconds since the first epoch's day in GPS
time); UTC at the output (GPS - UTC = 18 s from 2017).
"""

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..constants import C_MPS, DAY_S
from ..errors import InputError
from ..frames import C_e_n, ecef_to_geodetic, rotate_to_later_ecef
from . import models
from .antex import Antex, antenna_corrections_if
from .ar import ArOptions, fix_epoch, mw_arc_stats, nl_constants
from .ppp_obs import SIGNALS, detect_slips, if_observations, spp_position
from .products import Clocks, Orbits, seconds_gps
from .rinex import ObsData

__all__ = ["PppOptions", "PppResult", "gps_to_utc", "prepare", "run_ppp"]

_LEAPS = [(np.datetime64("2006-01-01"), 14), (np.datetime64("2009-01-01"), 15), (np.datetime64("2012-07-01"), 16),
          (np.datetime64("2015-07-01"), 17), (np.datetime64("2017-01-01"), 18)]


def gps_to_utc(time_gps):
    """GPS time -> UTC (``datetime64[ns]``), leap seconds from 2006 on."""
    t = np.asarray(time_gps, "datetime64[ns]")
    if np.any(t < _LEAPS[0][0]):
        raise InputError("epochs before 2006 are not supported (leap-second table)")
    leap = np.zeros(t.shape, np.int64)
    for day, n in _LEAPS:
        leap = np.where(t >= day + np.timedelta64(n, "s"), n, leap)
    return t - leap.astype("timedelta64[s]")


@dataclass(frozen=True)
class PppOptions:
    """Filter settings (SI units)."""

    static: bool = True
    systems: str = "GE"
    # 7 deg: the satellites between 7 and 10 deg separate the height from the zenith delay and the clock (on
    # ESBC00DNK 0.5 cm closer in up, static and kinematic); at 5 deg the horizontal loses consistency. Without
    # the receiver antenna's calibration (no ANTEX block) its variations are not modelled and weigh more low
    # down (static day 1.4 cm further in up at 7 deg): 10 deg (docs/ppp.md, "Models and settings").
    mask_deg: float = 7.0
    mask_no_antex_deg: float = 10.0
    sigma_code_m: float = 0.9
    sigma_phase_m: float = 0.009
    zwd_rw_m_per_rt_s: float = 1e-4
    # Troposphere gradients: off, because on ESBC00DNK they change the position by millimetres either way
    # (docs/ppp.md, "Troposphere: the mapping function and gradients"); 1 mm/sqrt(h) after a 2 mm prior,
    # about a typical mid-latitude gradient.
    gradients: bool = False
    # Troposphere mapping functions: "gmf" [Boehm 2006] (the IERS 2010 choice without weather-model grids; on
    # ESBC00DNK 0.7 mm closer in up than NMF) or "niell" [Niell 1996] (docs/ppp.md, "Troposphere: the mapping
    # function and gradients").
    mapping: Literal["gmf", "niell"] = "gmf"
    # Pressure of the a priori hydrostatic zenith delay: "gpt" [Boehm 2007]'s climatology or "standard" (the
    # standard atmosphere's); no meteorological file is read.
    zhd_pressure: Literal["gpt", "standard"] = "gpt"
    grad_rw_m_per_rt_s: float = 1e-3 / 60.0
    init_grad_sigma_m: float = 0.002
    kin_pos_sigma_m: float = 100.0
    init_pos_sigma_m: float = 100.0
    init_amb_sigma_m: float = 30.0
    clk_sigma_m: float = 100.0
    phase_gm_sigma_m: float = 0.005
    phase_gm_tau_s: float = 1800.0
    floor_enu_m: tuple[float, float, float] = (0.01, 0.01, 0.01)
    floor_no_antex_enu_m: tuple[float, float, float] = (0.03, 0.03, 0.05)
    k_outlier: float = 5.0
    gf_slip_m: float = 0.05
    mw_slip_cycles: float = 4.0
    gf_rate_window_s: float = 300.0
    max_gap_s: float = 600.0


@dataclass
class PppResult:
    """Per-epoch solutions, shapes (n_epochs, ...).

    ``pos_ecef_m`` / ``sigma_enu_m`` are the fixed solution where ``fixed``,
    the float one elsewhere (``pos_float_ecef_m`` / ``sigma_float_enu_m``
    always float). ``n_fixed`` counts the narrow-lane SD ambiguities fixed,
    ``ratio`` is the ratio test of the fixed subset (NaN where none).
    ``no_antenna``: satellites without an ANTEX block (out of the
    solution); ``no_ar``: satellites left out of ambiguity fixing, with why.
    ``grad_ne_m`` (n_epochs, 2): the north and east troposphere gradients
    (NaN without ``PppOptions.gradients``).
    """

    time_gps: np.ndarray
    pos_ecef_m: np.ndarray
    sigma_enu_m: np.ndarray
    zwd_m: np.ndarray
    clock_m: np.ndarray
    n_used: np.ndarray
    sv: list
    n_slips: int
    n_outliers: int
    no_antenna: list
    pos_float_ecef_m: np.ndarray
    sigma_float_enu_m: np.ndarray
    fixed: np.ndarray
    n_fixed: np.ndarray
    ratio: np.ndarray
    no_ar: dict
    grad_ne_m: np.ndarray


def prepare(obs: ObsData, orbits: Orbits, clocks: Clocks, options: PppOptions = PppOptions(),
            antex: Antex | None = None) -> dict[str, Any]:
    """Corrected IF observations and geometry for every (epoch, satellite).

    Returns
    -------
    dict
        ``Pc, Lc`` (n_epochs, n_sats) IF code and phase with the satellite
        clock, hydrostatic delay, Shapiro delay (and wind-up for phase)
        removed, so that ``Pc = rho + clk + m_wet ZWD + m_grad . (G_N, G_E)``
        and ``Lc = Pc + N``; ``RS`` (n_epochs, n_sats, 3) satellite positions
        (Sagnac applied), ``elev``, ``m_wet``, ``m_grad`` (n_epochs, n_sats, 2)
        (:func:`leosop.gnss.models.gradient_mapping`), ``ok`` (usable),
        ``new_arc``, ``MW`` (Melbourne-Wuebbena, wide-lane cycles), ``tide``
        (n_epochs, 3), ``arp_ecef`` (3,), ``x0`` a priori position, ``t_s``.
    """
    opt = options
    ref = obs.time_gps[0].astype("datetime64[D]").astype("datetime64[ns]")
    t_s = seconds_gps(obs.time_gps, ref)
    sv = obs.sv
    n_ep, n_sv = len(t_s), len(sv)
    meas = if_observations(obs, opt.systems)
    # Products for the observation's satellites.
    orb_idx = np.array([orbits.sv.index(s) if s in orbits.sv else -1 for s in sv])
    clk_idx = np.array([clocks.sv.index(s) if s in clocks.sv else -1 for s in sv])
    common = (orb_idx >= 0) & (clk_idx >= 0) & np.isfinite(meas["P"]).any(axis=0)
    if not common.any():
        raise InputError(f"{obs.path}: no satellite in common with {orbits.path} and {clocks.path}")
    t_orb = seconds_gps(orbits.ref_gps + (orbits.t_s * 1e9).astype("timedelta64[ns]"), ref)
    t_clk = seconds_gps(clocks.ref_gps + (clocks.t_s * 1e9).astype("timedelta64[ns]"), ref)
    orbits = Orbits(orbits.path, ref, t_orb, orbits.sv, orbits.pos_ecef_m)
    clocks = dataclasses.replace(clocks, ref_gps=ref, t_s=t_clk)
    for prod, tp in ((orbits, t_orb), (clocks, t_clk)):
        if tp[-1] < t_s[0] or tp[0] > t_s[-1]:
            raise InputError(f"{prod.path}: line 1: product covers {str(ref + np.timedelta64(int(tp[0]), 's'))[:19]}"
                             f" to {str(ref + np.timedelta64(int(tp[-1]), 's'))[:19]} GPST, the observations "
                             f"{str(obs.time_gps[0])[:19]} to {str(obs.time_gps[-1])[:19]}")
    # Satellite states at transmission time, all epochs at once.
    ok = np.isfinite(meas["P"]) & np.isfinite(meas["L"]) & common[None, :]
    ie, js = np.nonzero(ok)
    t_tx = t_s[ie] - meas["P"][ie, js] / C_MPS
    dts = clocks.bias(clk_idx[js], t_tx)
    t_tx = t_tx - dts
    pos_sv, vel_sv = orbits.state(orb_idx[js], t_tx)
    dts = clocks.bias(clk_idx[js], t_tx) + models.relativistic_clock_s(pos_sv, vel_sv)
    good = np.isfinite(dts) & np.isfinite(pos_sv).all(axis=1)
    ie, js, pos_sv, dts = ie[good], js[good], pos_sv[good], dts[good]
    ok[:] = False
    ok[ie, js] = True
    RS = np.full((n_ep, n_sv, 3), np.nan)
    RS[ie, js] = pos_sv
    DTS = np.full((n_ep, n_sv), np.nan)
    DTS[ie, js] = dts
    # A priori position: code-only fix of the first epochs with enough satellites.
    x0 = None
    for i in range(n_ep):
        m = ok[i]
        if m.sum() >= 6:
            x0 = spp_position(RS[i, m], meas["P"][i, m] + C_MPS * DTS[i, m])
            if np.isfinite(x0).all() and 6.3e6 < np.linalg.norm(x0) < 6.5e6:
                break
    if x0 is None or not np.isfinite(x0).all():
        raise InputError(f"{obs.path}: no epoch with 6 satellites and products for a first fix")
    lat0, lon0, alt0 = ecef_to_geodetic(x0)
    up0 = C_e_n(lat0, lon0)[:, 2]
    arp_ecef = obs.antenna_delta_hen_m[0] * up0  # ARP above the marker (E/N eccentricities are zero here)
    arp_ecef = arp_ecef + C_e_n(lat0, lon0)[:, :2] @ obs.antenna_delta_hen_m[[1, 2]]
    # Geometry-dependent models at the a priori position.
    jd_tt = 2440587.5 + (seconds_gps(obs.time_gps, np.datetime64("1970-01-01")) + models.TT_MINUS_GPST_S) / DAY_S
    sun, moon = models.sun_moon_ecef_m(jd_tt)
    tide = models.solid_tide_ecef_m(x0, sun, moon)  # (n_ep, 3)
    tau = np.linalg.norm(RS - x0, axis=-1) / C_MPS
    RS = rotate_to_later_ecef(RS, tau)
    los = RS - x0
    rng = np.linalg.norm(los, axis=-1)
    los_enu = los @ C_e_n(lat0, lon0)
    elev = np.arcsin(np.clip(los_enu[..., 2] / rng, -1, 1))
    m_grad = models.gradient_mapping(elev, np.arctan2(los_enu[..., 0], los_enu[..., 1]))
    mjd = jd_tt - 2400000.5  # TT for UTC in the climatologies: a minute is nothing to an annual term
    slant_dry, m_wet = models.slant_hydrostatic_and_wet(elev, lat0, lon0, alt0, mjd[:, None], mapping=opt.mapping,
                                                        zhd_pressure=opt.zhd_pressure)
    wind = models.windup_cycles(RS, x0, sun, lat0, lon0)
    missing, rx_cal = [], False
    if antex is not None:
        RS, d_ant, missing, rx_cal = antenna_corrections_if(antex, obs, RS, x0, sun, C_e_n(lat0, lon0), elev,
                                                     {k: v[4:6] for k, v in SIGNALS.items()})
        corr = -d_ant  # NaN for the satellites without a block: left out below
    else:
        corr = 0.0
    shap = models.shapiro_m(RS, x0)
    corr = corr + C_MPS * DTS - slant_dry - shap  # add to observations: P + c dts - T_dry - shapiro
    Pc = meas["P"] + corr
    Lc = meas["L"] + corr - wind * meas["lam_nl"]
    ok &= elev > np.radians(opt.mask_deg if rx_cal else opt.mask_no_antex_deg)
    ok &= np.isfinite(Pc) & np.isfinite(Lc)
    new_arc = detect_slips(t_s, meas["MW"], meas["GF"], meas["lli"], ok, opt)
    return {"Pc": Pc, "Lc": Lc, "RS": RS, "elev": elev, "m_wet": m_wet, "m_grad": m_grad, "ok": ok,
            "new_arc": new_arc, "tide": tide, "arp_ecef": arp_ecef, "no_antenna": missing, "rx_calibrated": rx_cal,
            "x0": x0, "t_s": t_s, "lat0": lat0, "lon0": lon0, "MW": meas["MW"]}


def run_ppp(obs: ObsData, orbits: Orbits, clocks: Clocks, options: PppOptions = PppOptions(),
            antex: Antex | None = None, *, ar: ArOptions | None = None,
            no_ar: dict[str, str] | None = None, show_progress: bool = False) -> PppResult:
    """PPP over every epoch of ``obs``: float, and with ``ar`` ambiguity-fixed (:mod:`leosop.gnss.ar`).

    Parameters
    ----------
    ar : leosop.gnss.ar.ArOptions, optional
        Fix ambiguities: needs integer-recovery clocks with their satellite
        wide-lane biases (``clocks.wl_bias_cyc``); satellites without one
        are not fixed.
    no_ar : dict of str -> str, optional
        Satellites not to fix, with the reason (e.g. an antenna offset of
        another frame than the clocks').
    show_progress : bool
        A progress bar over the epochs on stderr (when it is a terminal).

    Returns
    -------
    PppResult
        ``pos_ecef_m`` is the marker (antenna height removed), NaN at epochs
        with fewer than 5 usable satellites.
    """
    opt = options
    d = prepare(obs, orbits, clocks, options, antex)
    Pc, Lc, RS, elev, ok, new_arc = (d[k] for k in ("Pc", "Lc", "RS", "elev", "ok", "new_arc"))
    # Troposphere states: the zenith wet delay, then the north and east gradients (with opt.gradients).
    n_tr = 3 if opt.gradients else 1
    m_trop = np.concatenate([d["m_wet"][..., None], d["m_grad"]], axis=-1)[..., :n_tr]
    tide, arp_ecef, x0, t_s, lat0, lon0 = (d[k] for k in ("tide", "arp_ecef", "x0", "t_s", "lat0", "lon0"))
    sv = obs.sv
    n_ep, n_sv = len(t_s), len(sv)
    # Filter.
    sysof = np.array([s[0] for s in sv])
    clk_col = np.where(sysof == "E", 4, 3)
    trop = slice(5, 5 + n_tr)
    amb0 = 5 + n_tr  # first ambiguity state
    gm0 = amb0 + n_sv  # first Gauss-Markov phase error state
    n_x = gm0 + n_sv
    x = np.zeros(n_x)
    P = np.zeros((n_x, n_x))
    x[:3] = x0
    P[:3, :3] = np.eye(3) * opt.init_pos_sigma_m**2
    x[5] = 0.1
    P[5, 5] = 0.3**2
    P[6:amb0, 6:amb0] = np.eye(n_tr - 1) * opt.init_grad_sigma_m**2
    # Arc of each satellite at each epoch; an ambiguity state belongs to one arc (-1: none yet). An arc that
    # starts at an epoch the filter skips (fewer than 5 satellites) must still restart the ambiguity.
    arc_id = np.cumsum(new_arc, axis=0)
    amb_arc = np.full(n_sv, -1)
    out_pos = np.full((n_ep, 3), np.nan)
    out_sig = np.full((n_ep, 3), np.nan)
    out_zwd = np.full(n_ep, np.nan)
    out_grad = np.full((n_ep, 2), np.nan)
    out_clk = np.full((n_ep, 2), np.nan)
    n_used = np.zeros(n_ep, int)
    n_slips = n_outl = 0
    C_en0 = C_e_n(lat0, lon0)
    floor2 = np.square(opt.floor_enu_m if d["rx_calibrated"] else opt.floor_no_antex_enu_m)
    last_t = None
    fix_pos, fix_sig = out_pos.copy(), out_sig.copy()
    n_fixed, ratio = np.zeros(n_ep, int), np.full(n_ep, np.nan)
    skip_ar = _no_ar(sv, d["no_antenna"], clocks.wl_bias_cyc, no_ar) if ar is not None else {}
    if ar is not None:
        mw_mean, mw_var, mw_n = mw_arc_stats(d["MW"], ok, new_arc)
        wsb = np.array([clocks.wl_bias_cyc.get(s, np.nan) for s in sv])
        wl_cyc = mw_mean + wsb
        wl_se = ar.wl_se_inflation * np.sqrt(mw_var / np.maximum(mw_n, 1))
        ar_ok = ok & (elev >= np.radians(ar.mask_deg)) & (mw_n >= ar.wl_min_epochs) & np.isfinite(wl_se)
        ar_ok[:, [sv.index(s) for s in skip_ar]] = False
        lam_nl, beta = nl_constants(sv)
    if show_progress:
        from ..progress import progress
    for i in progress(range(n_ep), desc="ppp", unit="epoch") if show_progress else range(n_ep):
        js_i = np.flatnonzero(ok[i])
        if len(js_i) < 5:
            continue
        dt = 0.0 if last_t is None else t_s[i] - last_t
        last_t = t_s[i]
        # Prediction: ZWD and gradients random walks, clocks white, position static or white (kinematic),
        # phase errors first-order Gauss-Markov (their variance elevation-dependent as the white noise's).
        Q = np.zeros(n_x)
        Q[5] = opt.zwd_rw_m_per_rt_s**2 * dt
        Q[6:amb0] = opt.grad_rw_m_per_rt_s**2 * dt
        phi = np.ones(n_x)
        phi[gm0:] = np.exp(-dt / opt.phase_gm_tau_s)
        el_factor = np.ones(n_sv)
        el_factor[js_i] = 0.5 * (1.0 + 1.0 / np.sin(elev[i, js_i]) ** 2)
        gm_var = opt.phase_gm_sigma_m**2 * el_factor
        Q[gm0:] = gm_var * (1.0 - phi[gm0:] ** 2)
        x = x * phi
        P = phi[:, None] * P * phi[None, :]
        if not opt.static:
            P[:3, :] = 0.0
            P[:, :3] = 0.0
            P[[0, 1, 2], [0, 1, 2]] = opt.kin_pos_sigma_m**2
        P[np.arange(n_x), np.arange(n_x)] += Q
        # Ambiguities: new arcs and satellites (re)initialised from phase minus code.
        rr = x[:3] + arp_ecef + tide[i]
        los_i = RS[i, js_i] - rr
        rho = np.linalg.norm(los_i, axis=1)
        e_i = los_i / rho[:, None]
        cs = clk_col[js_i]
        m_i = m_trop[i, js_i]  # (n, n_tr)
        for s_col in (3, 4):
            sel = cs == s_col
            P[s_col, :] = 0.0
            P[:, s_col] = 0.0
            P[s_col, s_col] = opt.clk_sigma_m**2
            if sel.any():
                x[s_col] = np.median(Pc[i, js_i[sel]] - rho[sel] - m_i[sel] @ x[trop])
        reset = js_i[arc_id[i, js_i] != amb_arc[js_i]]
        n_slips += int(np.sum(amb_arc[reset] >= 0))
        for j in reset:
            for a, var in ((amb0 + j, opt.init_amb_sigma_m**2), (gm0 + j, gm_var[j])):
                P[a, :] = 0.0
                P[:, a] = 0.0
                P[a, a] = var
                x[a] = 0.0
            x[amb0 + j] = Lc[i, j] - Pc[i, j]
            amb_arc[j] = arc_id[i, j]
        use_code = np.ones(len(js_i), bool)
        use_phase = np.ones(len(js_i), bool)
        sin_el = np.sin(elev[i, js_i])
        for _ in range(8):
            rows_c, rows_p = np.flatnonzero(use_code), np.flatnonzero(use_phase)
            m = len(rows_c) + len(rows_p)
            H = np.zeros((m, n_x))
            z = np.empty(m)
            r_var = np.empty(m)
            for k, (rows, is_phase) in enumerate(((rows_c, False), (rows_p, True))):
                off = 0 if k == 0 else len(rows_c)
                sl = slice(off, off + len(rows))
                jj = js_i[rows]
                H[sl, :3] = -e_i[rows]
                H[sl.start + np.arange(len(rows)), cs[rows]] = 1.0
                H[sl, trop] = m_i[rows]
                pred = rho[rows] + x[cs[rows]] + m_i[rows] @ x[trop]
                if is_phase:
                    H[sl.start + np.arange(len(rows)), amb0 + jj] = 1.0
                    H[sl.start + np.arange(len(rows)), gm0 + jj] = 1.0
                    z[sl] = Lc[i, jj] - pred - x[amb0 + jj] - x[gm0 + jj]
                    r_var[sl] = opt.sigma_phase_m**2 * 0.5 * (1.0 + 1.0 / sin_el[rows] ** 2)
                else:
                    z[sl] = Pc[i, jj] - pred
                    r_var[sl] = opt.sigma_code_m**2 * 0.5 * (1.0 + 1.0 / sin_el[rows] ** 2)
            PHt = P @ H.T
            S = H @ PHt + np.diag(r_var)
            w = np.abs(z) / np.sqrt(np.diag(S))
            worst = int(np.argmax(w))
            if w[worst] <= opt.k_outlier or m <= 8:
                break
            n_outl += 1
            if worst < len(rows_c):
                use_code[rows_c[worst]] = False
            else:
                j = js_i[rows_p[worst - len(rows_c)]]
                a = amb0 + j
                P[a, :] = 0.0
                P[:, a] = 0.0
                P[a, a] = opt.init_amb_sigma_m**2
                x[a] = Lc[i, j] - Pc[i, j]
                n_slips += 1
        K = np.linalg.solve(S, PHt.T).T
        x = x + K @ z
        IKH = np.eye(n_x) - K @ H
        P = IKH @ P @ IKH.T + (K * r_var) @ K.T
        P = 0.5 * (P + P.T)
        out_pos[i] = x[:3]
        out_sig[i] = np.sqrt(np.clip(np.diag(C_en0.T @ P[:3, :3] @ C_en0), 0, None) + floor2)
        out_zwd[i] = x[5]
        out_grad[i, :n_tr - 1] = x[6:amb0]
        out_clk[i] = x[3:5]
        n_used[i] = len(js_i)
        if ar is not None:
            jf = js_i[ar_ok[i, js_i]]
            f = fix_epoch(x, P, amb0, jf, wl_cyc[i], wl_se[i], sysof, elev[i], lam_nl, beta, ar) if jf.size else None
            if f is not None:
                fix_pos[i] = x[:3] + f.dx[:3]
                fix_sig[i] = np.sqrt(np.clip(np.diag(C_en0.T @ f.P[:3, :3] @ C_en0), 0, None) + floor2)
                n_fixed[i], ratio[i] = f.n_fixed, f.ratio
    fixed = n_fixed > 0
    return PppResult(time_gps=obs.time_gps, pos_ecef_m=np.where(fixed[:, None], fix_pos, out_pos),
                     sigma_enu_m=np.where(fixed[:, None], fix_sig, out_sig), zwd_m=out_zwd, clock_m=out_clk,
                     n_used=n_used, sv=sv, n_slips=n_slips, n_outliers=n_outl, no_antenna=d["no_antenna"],
                     pos_float_ecef_m=out_pos, sigma_float_enu_m=out_sig, fixed=fixed, n_fixed=n_fixed, ratio=ratio,
                     no_ar=skip_ar, grad_ne_m=out_grad)


def _no_ar(sv, no_antenna, wl_biases_cyc, no_ar):
    """Satellites left out of ambiguity fixing, with the reason, in the order of ``sv``."""
    out = {}
    for s in sv:
        if s in no_antenna:
            out[s] = "no ANTEX block (out of the solution)"
        elif no_ar and s in no_ar:
            out[s] = no_ar[s]
        elif s not in wl_biases_cyc:
            out[s] = "no wide-lane bias in the clock file"
    return out
