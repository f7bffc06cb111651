"""Tightly coupled PPP / INS filter with wide-lane then narrow-lane ambiguity resolution ([Liu 2016]).

Error-state EKF around the toolkit's strapdown INS (:class:`leosop.fusion.
common.FeedbackIns`: the 15 INS errors of :mod:`leosop.ins.error_model`,
attitude, velocity, position, gyro and accelerometer biases, propagated
with Q from the IMU's random walks, fed back after every update), augmented
with the zenith wet delay (random walk) and the between-satellite single-
differenced (SD) ionosphere-free ambiguities [m], one per satellite other
than the reference. [Liu 2016] writes the INS errors in ECEF; here they are
the toolkit's local-level errors, and the measurement rows map them to ECEF
(``C_e_n`` and the position Jacobian), which is the same filter written in
another frame.

Measurements, every GNSS epoch, against the reference satellite (the
highest when it is (re)chosen): SD ionosphere-free code and phase and SD
Doppler range rate, predicted at the INS position and velocity (the
receiver clock and its drift cancel). Weights: ``sigma / sin(elev)`` with
code:phase 1:100 ([Liu 2016]); the SD covariance keeps the reference's
shared term. A change of reference maps the SD ambiguities and their
covariance (``x' = T x``, ``P' = T P T^T``); a cycle slip (loss-of-lock
flag, Melbourne-Wuebbena and geometry-free tests of
:func:`leosop.gnss.ppp.detect_slips`) or an outlier (normalised innovation
above ``k_outlier``) restarts that satellite's ambiguity.

Ambiguity resolution, each epoch, on the float filter ([Liu 2016]: no
fix-and-hold): the SD wide-lane from the arc means of the Melbourne-
Wuebbena combinations less the satellites' wide-lane biases, rounded when
within ``wl_tol_cyc`` of an integer; then the narrow-lane
``N1 = (B_IF - beta N_WL) / lambda_NL`` (``beta = c f2 / (f1^2 - f2^2)``)
by LAMBDA with the ratio test (``ratio_min``), a bootstrapped success rate
of at least ``success_min`` and partial fixing (:mod:`leosop.gnss.lambda_`);
the fixed ambiguities condition the state (a noise-free pseudo-observation
on a copy) for the fixed solution. When the GNSS is lost after a fixed
epoch (``bridge_fixed``), the INS bridges the gap from that fixed solution
and its conditioned covariance rather than from the float one: every
ambiguity is dropped in the gap, so nothing is held beyond it, and the
outage starts from centimetres instead of the float solution's
decimetre (``tools/bench_ppp_ins_outage.py``).

After a gap every arc restarts; [Liu 2016]'s fast re-fix uses the INS:
with ``wl_inertial`` the new arcs' wide-lanes are fixed at the first
epochs from the wide-lane phase less the range predicted at the bridged
position, the ionosphere carried over the gap by the geometry-free
phase's slope before it, and the old arcs' Melbourne-Wuebbena means
(:class:`_InertialWideLane`: LAMBDA on the INS covariance, a bootstrapped
success rate of at least ``wl_success_min``), and the fixed wide-lanes,
as ranges, update the float solution; otherwise they wait for the
Melbourne-Wuebbena averages. The old arcs' means carry code multipath
correlated over seconds: their variances sum the autocovariances
(:func:`_mw_var_mean`); the white-noise scatter made their errors 1.7
times their sigma (1.2 now) over 6 seeds, and the wide-lane ranges, all
terms together, have NIS 0.93 per row (0.84 before). A one-time update,
so its few-centimetre error stays in the new float ambiguities for tens of
minutes: on average it helps the float solution, at single seeds it can
go either way (``docs/ppp.md``).

Measured (``leosop reproduce ppp-ins``, ``tools/bench_ppp_ins.py``): on the
simulated car, 20 seeds of 15 min, the float-position NEES averaged over
the seeds is 2.57 (3 expected; inside its 95 % band at 95 % of epochs).
"""

from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS, DAY_S
from ..frames import C_e_n, geodetic_to_ecef
from ..fusion import kalman
from ..fusion.common import N_INS, FeedbackIns, initial_covariance, pos_jacobian
from ..ins.error_model import DPOS, DV
from . import models
from .geometry import range_and_rate, satellite_clock
from .lambda_ import partial_fix
from .ppp import PppOptions
from .ppp_obs import detect_slips
from .simulate import F1_HZ, F2_HZ

__all__ = ["PppInsOptions", "PppInsResult", "if_combinations", "run"]

_ZWD = N_INS  # state index of the zenith wet delay; the SD ambiguities follow, one slot per satellite
_A0 = N_INS + 1
_POS_ZWD = np.r_[np.arange(N_INS)[DPOS], _ZWD]  # position errors and the wet delay
LAM_NL_M = C_MPS / (F1_HZ + F2_HZ)
LAM_WL_M = C_MPS / (F1_HZ - F2_HZ)
# Ionosphere in the wide-lane phase [cycles] per metre of geometry-free phase L1 - L2 [m]: (f1/f2) I1 / LAM_WL
# against (f1^2/f2^2 - 1) I1.
KAPPA_WL_PER_GF = (F1_HZ / F2_HZ) / (LAM_WL_M * ((F1_HZ / F2_HZ) ** 2 - 1.0))
BETA_M = C_MPS * F2_HZ / (F1_HZ**2 - F2_HZ**2)  # IF ambiguity [m] = LAM_NL N1 + BETA N_WL


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
        (at its first epoch from the fixed solution's, with ``bridge_fixed``).
    n_sats, n_fixed, n_wl : ndarray of int
        Satellites used, narrow-lane and wide-lane ambiguities fixed.
    ratio : ndarray
    gnss : ndarray of bool
        A GNSS update was made.
    n_slips, n_outliers, n_ref_changes : int
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


def if_combinations(P1_m, P2_m, L1_cyc, L2_cyc):
    """Ionosphere-free code and phase [m], Melbourne-Wuebbena [wide-lane cycles], geometry-free phase [m].

    Arrays of any one shape (GPS L1/L2).
    """
    f1, f2 = F1_HZ, F2_HZ
    g1, g2 = f1**2 / (f1**2 - f2**2), f2**2 / (f1**2 - f2**2)
    L1, L2 = L1_cyc * C_MPS / f1, L2_cyc * C_MPS / f2
    mw = ((f1 * L1 - f2 * L2) / (f1 - f2) - (f1 * P1_m + f2 * P2_m) / (f1 + f2)) / (C_MPS / (f1 - f2))
    return g1 * P1_m - g2 * P2_m, g1 * L1 - g2 * L2, mw, L1 - L2


def _sd_cov(var, ref_var):
    """Covariance of SD measurements ``z_j - z_ref``: ``diag(var) + ref_var``."""
    return np.diag(var) + ref_var


class _Ambiguities:
    """SD ambiguity slots: which are active, the reference, and the reference change."""

    def __init__(self, n_sv):
        self.on = np.zeros(n_sv, bool)
        self.ref = -1

    def drop(self, P, x, js):
        for j in js:
            a = _A0 + j
            P[a, :] = 0.0
            P[:, a] = 0.0
            x[a] = 0.0
            self.on[j] = False

    def reset(self, P, x, js, values, sigma):
        self.drop(P, x, js)
        for j, v in zip(js, values):
            P[_A0 + j, _A0 + j] = sigma**2
            x[_A0 + j] = v
            self.on[j] = True

    def change_reference(self, P, x, new):
        """SD states ``B_j - B_old`` -> ``B_j - B_new``; the old reference becomes ``B_old - B_new``."""
        old = self.ref
        n = x.size
        T = np.eye(n)
        for j in np.flatnonzero(self.on):
            T[_A0 + j, _A0 + new] -= 1.0
        if old >= 0:
            T[_A0 + old, :] = 0.0
            T[_A0 + old, _A0 + new] = -1.0
            self.on[old] = True
        T[_A0 + new, :] = 0.0
        x[:] = T @ x
        P[:] = T @ P @ T.T
        self.on[new] = False
        self.ref = new


class _InertialWideLane:
    """Wide-lanes of the arcs that restart after a GNSS gap, from the INS geometry ([Liu 2016]'s fast re-fix).

    Per satellite, undifferenced, with a term common to all satellites at
    each epoch (receiver clock and biases) that the single differences
    cancel: ``g = (L_WL - range) / LAM_WL`` [cycles], the wide-lane phase
    less the predicted range (troposphere included) at the filter's
    position. Across a gap, ``g`` changes by the new arc's wide-lane
    ambiguity less the old one and by the ionosphere's change, so the new
    arc's Melbourne-Wuebbena mean is predicted at its first epoch as
    ``u = m + g(t) - g(t0) - KAPPA_WL_PER_GF * gf_rate * (t - t0)``: ``m`` the
    old arc's Melbourne-Wuebbena mean, ``t0`` the last epoch before the gap
    (at the fixed solution when there is one), ``gf_rate`` the slope of the
    geometry-free phase over the last ``wl_iono_window_s`` of the old arc.
    ``m``'s variance counts the multipath correlation (:func:`_mw_var_mean`).
    The SD ``u`` less the satellites' wide-lane biases is fixed by LAMBDA
    with the covariance of the position and wet delay mapped through the
    SD lines of sight (the INS drift over the gap dominates) plus each
    satellite's own terms, when the ratio test passes and the bootstrapped
    success rate is at least ``wl_success_min``; what is fixed is kept in
    ``wl_cyc`` (undifferenced, SD minus SD wide-lane biases = the integers)
    until that satellite's arc ends. The fixed SD wide-lanes, less their
    integers, are then ranges of centimetre noise (the predicted ionosphere
    included) and update the float filter once, which brings the position
    to the centimetres the narrow-lane needs; their noise's correlation
    with the same epoch's ionosphere-free phase is neglected.

    Attributes
    ----------
    g_last : ndarray, shape (n_sv,)
        ``g`` at the last GNSS epoch (NaN where not used), ``t_last_s`` its time.
    m, var_m, g0, rate_gf_mps, var_rate : ndarray, shape (n_sv,)
        Snapshot of the last epoch before the gap; ``ok`` where usable.
    on : ndarray of bool, shape (n_sv,)
        Wide-lane fixed this way on the current arc; ``wl_cyc`` its value.
    """

    def __init__(self, n_sv):
        self.g_last = np.full(n_sv, np.nan)
        self.sin_last = np.full(n_sv, np.nan)
        self.t_last_s = np.nan
        self.k_last = -1
        self.ok = np.zeros(n_sv, bool)
        self.seen = np.zeros(n_sv, bool)
        self.on = np.zeros(n_sv, bool)
        self.wl_cyc = np.zeros(n_sv)
        self.t_end_s = np.nan  # first GNSS epoch after the gap
        # Separate arrays (not one aliased array): snapshot() replaces them, fix() reads them.
        self.m, self.var_m, self.g0, self.rate_gf_mps, self.var_rate, self.sin0 = np.zeros((6, n_sv))
        self.t0_s = np.nan
        self.H_last, self.H0 = np.zeros((2, n_sv, 4))
        self.P_last = self.P0 = np.zeros((4, 4))

    def snapshot(self, t_s, gf_m, new_arc, mw_mean, mw_var_mean, window_s):
        """At the first epoch of a gap: keep the old arcs' MW means, ``g`` and geometry-free slopes."""
        k0 = self.k_last
        self.ok = np.isfinite(self.g_last)
        self.m, self.var_m = mw_mean.copy(), mw_var_mean.copy()
        self.g0, self.sin0, self.t0_s = self.g_last.copy(), self.sin_last.copy(), self.t_last_s
        self.H0, self.P0 = self.H_last.copy(), self.P_last
        self.rate_gf_mps = np.zeros_like(self.m)
        self.var_rate = np.full_like(self.m, np.inf)
        lo = int(np.searchsorted(t_s, t_s[k0] - window_s))
        for j in np.flatnonzero(self.ok):
            starts = np.flatnonzero(new_arc[lo:k0 + 1, j])
            rows = np.arange(lo + (starts[-1] if starts.size else 0), k0 + 1)
            rows = rows[np.isfinite(gf_m[rows, j])]
            if rows.size < 10:
                self.ok[j] = False
                continue
            tt = t_s[rows] - t_s[rows].mean()
            slope, icpt = np.polyfit(tt, gf_m[rows, j], 1)
            res = gf_m[rows, j] - (slope * tt + icpt)
            # The residuals are correlated over seconds (multipath): their variance counted twice.
            self.rate_gf_mps[j] = slope
            self.var_rate[j] = 2.0 * res.var() * rows.size / (rows.size - 2) / np.sum(tt**2)
        self.ok &= np.isfinite(self.var_m)
        self.seen[:] = False
        self.on[:] = False
        self.t_end_s = np.nan

    def new_arcs(self, fresh, js, t_s):
        """Arcs that end lose their wide-lane; after a gap, a second arc start makes a satellite unusable."""
        self.on[fresh] = False
        if np.isnan(self.t_end_s):
            self.t_end_s = t_s
        self.ok[fresh & self.seen] = False
        self.seen[js] = True

    def store(self, js, g, sin_el, t_s, k, H, P_sub):
        """Keep this GNSS epoch's ``g``, sin(elevation), range Jacobian ``H`` (shape (m, p)) of the
        satellites ``js`` and the covariance ``P_sub`` of its position and wet delay (the last before a gap)."""
        self.g_last[:] = np.nan
        self.g_last[js], self.sin_last[js] = g, sin_el
        self.H_last[js] = H
        self.t_last_s, self.k_last, self.P_last = t_s, k, P_sub

    def fix(self, js, ref, g, sin_el, t_s, H_sd, P_sub, wsb, o):
        """Fix the SD wide-lanes of ``js`` (reference ``ref``) from the INS geometry.

        Parameters
        ----------
        js : ndarray of int, shape (m,)
            The epoch's satellites, ``ref`` among them.
        g, sin_el : ndarray, shape (m,)
            ``g`` [cycles] and sin(elevation) at this epoch.
        H_sd : ndarray, shape (m, p)
            SD range [m] against the position and wet-delay errors (reference row zero).
        P_sub : ndarray, shape (p, p)
            Their covariance.
        wsb : ndarray, shape (n_sv,)
            Satellite wide-lane biases [cycles].

        Returns
        -------
        rows : ndarray of int, shape (f,)
            Indices into ``js`` of the wide-lanes fixed now (empty when none).
        y_m : ndarray, shape (f,)
            SD wide-lane phase less the range, the ionosphere and the fixed
            integer [m]: a measurement of ``H_sd[rows] @ (position, wet delay)
            error``, what the fixed wide-lanes give the float filter.
        R_m2 : ndarray, shape (f, f)
            Its covariance.
        """
        none = np.zeros(0, int), np.zeros(0), np.zeros((0, 0))
        if not self.ok[ref] or t_s - self.t_end_s > o.wl_inertial_window_s:
            return none
        dt = t_s - self.t0_s
        u = self.m[js] + g - self.g0[js] - KAPPA_WL_PER_GF * self.rate_gf_mps[js] * dt
        var_u = (self.var_m[js] + (o.wl_phase_sigma_cyc / sin_el) ** 2 + (o.wl_phase_sigma_cyc / self.sin0[js]) ** 2
                 + (KAPPA_WL_PER_GF * dt) ** 2 * self.var_rate[js])
        iref = int(np.flatnonzero(js == ref)[0])
        sel = np.flatnonzero(self.ok[js] & ~self.on[js] & (js != ref))
        if sel.size < o.min_fixed:
            return none
        a_hat = u[sel] - u[iref] - (wsb[js[sel]] - wsb[ref])
        Hs = H_sd[sel] / LAM_WL_M
        # The position error at the last epoch before the gap is in g0: counted as independent of today's.
        H0 = (self.H0[js[sel]] - self.H0[ref]) / LAM_WL_M
        Q_own = H0 @ self.P0 @ H0.T + np.diag(var_u[sel]) + var_u[iref]
        Q = Hs @ P_sub @ Hs.T + Q_own
        fixed, n_wl, _ = partial_fix(a_hat, Q, ratio_min=o.ratio_min, min_fixed=o.min_fixed,
                                     success_min=o.wl_success_min)
        if not fixed.any():
            return none
        base = self.wl_cyc[ref] if self.on[ref] else 0.0
        jf = js[sel[fixed]]
        self.wl_cyc[jf] = base + n_wl[fixed] + wsb[jf] - wsb[ref]
        self.on[jf] = True
        if not self.on[ref]:
            self.wl_cyc[ref], self.on[ref] = 0.0, True
        return sel[fixed], LAM_WL_M * (a_hat[fixed] - n_wl[fixed]), LAM_WL_M**2 * Q_own[np.ix_(fixed, fixed)]


def run(gnss, orbits, clocks, state0, dtheta_b_rad, dvel_b_mps, dt_s, settings, options=PppInsOptions()):
    """Run the tightly coupled PPP/INS filter.

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
        Measured IMU increments from the first epoch on.
    dt_s : float
    settings : leosop.fusion.common.FilterSettings
        INS priors and IMU noise; ``step_s`` is the GNSS interval.
    options : PppInsOptions

    Returns
    -------
    PppInsResult
    """
    o = options
    ins = FeedbackIns(state0, dtheta_b_rad, dvel_b_mps, dt_s, settings)
    n_ep = min(len(gnss.t_s), ins.n_epochs)
    n_sv = len(gnss.sv)
    Pc, Lc, MW, GF = if_combinations(gnss.P1_m[:n_ep], gnss.P2_m[:n_ep], gnss.L1_cyc[:n_ep], gnss.L2_cyc[:n_ep])
    t = gnss.t_s[:n_ep]
    have = np.isfinite(Pc) & np.isfinite(Lc)
    new_arc = detect_slips(t, MW, GF, gnss.lli[:n_ep], have, PppOptions(max_gap_s=1.5 * settings.step_s))
    LW = (gnss.L1_cyc[:n_ep] - gnss.L2_cyc[:n_ep]) * LAM_WL_M  # wide-lane phase [m]
    n_x = _A0 + n_sv
    day = np.datetime64(orbits.ref_gps, "D")
    doy = float((day - day.astype("datetime64[Y]")).astype(int) + 1)
    x = np.zeros(n_x)
    P = np.zeros((n_x, n_x))
    P[:N_INS, :N_INS] = initial_covariance(settings, state0.lat_rad, state0.alt_m)
    x[_ZWD], P[_ZWD, _ZWD] = o.zwd0_m, o.zwd_sigma_m**2
    amb = _Ambiguities(n_sv)
    mw_sum, mw_sq, mw_n = np.zeros(n_sv), np.zeros(n_sv), np.zeros(n_sv, int)
    iwl = _InertialWideLane(n_sv)
    out = PppInsResult(t_s=t, pos_float_ecef_m=np.full((n_ep, 3), np.nan), pos_fixed_ecef_m=np.full((n_ep, 3), np.nan),
                       cov_pos_enu_m2=np.full((n_ep, 3, 3), np.nan), cov_ins=np.full((n_ep, N_INS, N_INS), np.nan),
                       n_sats=np.zeros(n_ep, int), n_fixed=np.zeros(n_ep, int), n_wl=np.zeros(n_ep, int),
                       ratio=np.full(n_ep, np.nan), gnss=np.zeros(n_ep, bool), n_slips=0, n_outliers=0, n_ref_changes=0)
    held = None  # the previous epoch's fixed solution: (state increment, conditioned covariance)
    for k in range(n_ep):
        if k > 0:
            if o.bridge_fixed and held is not None and np.count_nonzero(have[k]) < 2:
                # GNSS lost: the INS bridges the gap from the fixed solution, not the float one (every
                # ambiguity is dropped in the gap, so conditioning on the fixed ones loses nothing).
                ins.feedback(held[0])
                x[N_INS:] += held[0][N_INS:]
                P = held[1]
            held = None
            P = ins.predict(k, P)
            P[_ZWD, _ZWD] += o.zwd_rw_m_per_rt_s**2 * settings.step_s
        s = ins.state
        C = C_e_n(s.lat_rad, s.lon_rad)
        J = pos_jacobian(s.lat_rad, s.alt_m)
        r_ins = geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m)
        v_ins = C @ s.vel_enu_mps
        js = np.flatnonzero(have[k])
        if js.size >= 2:
            rho, rate, los, _ = range_and_rate(orbits, gnss.orb_idx[js], t[k], r_ins, v_ins)
            elev = np.arcsin(np.clip(los @ C[:, 2], -1.0, 1.0))
            keep = elev > np.radians(o.mask_deg)
            js, rho, rate, los, elev = js[keep], rho[keep], rate[keep], los[keep], elev[keep]
        if js.size < 2:
            if o.wl_inertial and iwl.k_last == k - 1:
                mean, _ = _mw_mean(mw_sum, mw_sq, mw_n)
                var_mean = _mw_var_mean(MW[:k], mw_n, mean, o.wl_mw_lags)
                iwl.snapshot(t, GF, new_arc, mean, var_mean, o.wl_iono_window_s)
            amb.drop(P, x, np.flatnonzero(amb.on))
            amb.ref = -1
            mw_sum[:], mw_sq[:], mw_n[:] = 0.0, 0.0, 0
            _record(out, k, ins, P, r_ins, C, J)
            continue
        clk_m, drift_mps = satellite_clock(orbits, clocks, gnss.orb_idx[js], gnss.clk_idx[js],
                                           t[k] - gnss.P1_m[k, js] / C_MPS)
        m_dry, m_wet = models.niell_mapping(elev, s.lat_rad, s.alt_m, doy + t[k] / DAY_S)
        zhd = models.saastamoinen_zhd_m(s.lat_rad, s.alt_m) * m_dry
        pc = Pc[k, js] + clk_m - zhd
        lc = Lc[k, js] + clk_m - zhd
        rr = gnss.rate_mps[k, js] + drift_mps
        # Arcs: a slip or a new satellite restarts its MW mean and its ambiguity; satellites gone are dropped.
        nw = new_arc[k, js]
        out.n_slips += int(np.sum(nw & amb.on[js]))
        fresh = np.ones(n_sv, bool)
        fresh[js[~nw]] = False
        mw_sum[fresh], mw_sq[fresh], mw_n[fresh] = 0.0, 0.0, 0
        mw_sum[js] += MW[k, js]
        mw_sq[js] += MW[k, js] ** 2
        mw_n[js] += 1
        iwl.new_arcs(fresh, js, t[k])
        if not (amb.ref in js and not new_arc[k, amb.ref]):
            cand = [js[i] for i in np.argsort(-elev) if amb.on[js[i]] and not nw[i]]
            if cand and amb.ref >= 0:
                amb.change_reference(P, x, cand[0])
                out.n_ref_changes += 1
            else:
                amb.drop(P, x, np.flatnonzero(amb.on))
                amb.ref = js[int(np.argmax(elev))]
        amb.drop(P, x, np.setdiff1d(np.flatnonzero(amb.on), js))
        iref = int(np.flatnonzero(js == amb.ref)[0])
        others = np.flatnonzero(js != amb.ref)
        jo = js[others]
        stale = others[nw[others] | ~amb.on[jo]]
        amb.reset(P, x, js[stale], (lc - pc)[stale] - (lc - pc)[iref], o.amb_sigma_m)
        # SD measurements: code, phase, range rate; rows per kind for the satellites in ``others``.
        geo = _Geometry(rho, rate, los, m_wet, np.sin(elev), iref, others, jo)
        use = [np.ones(others.size, bool) for _ in range(3)]
        for _ in range(6):
            H, y, R, sizes = _sd_measurements(geo, (pc, lc, rr), x, C, J, use, o)
            S = H @ P @ H.T + R
            w = np.abs(y) / np.sqrt(np.diag(S))
            worst = int(np.argmax(w)) if w.size else 0
            if not w.size or w[worst] <= o.k_outlier:
                break
            out.n_outliers += 1
            kind = int(np.searchsorted(sizes, worst, side="right") - 1)
            idx = np.flatnonzero(use[kind])[worst - sizes[kind]]
            use[kind][idx] = False
            if kind == 1:  # a phase outlier is a slip: restart that ambiguity
                amb.reset(P, x, [jo[idx]], [(lc - pc)[others[idx]] - (lc - pc)[iref]], o.amb_sigma_m)
                mw_sum[jo[idx]], mw_sq[jo[idx]], mw_n[jo[idx]] = 0.0, 0.0, 0
        dx, P, _, _ = kalman.update(np.zeros(n_x), P, y, H, R)
        ins.feedback(dx)
        x[N_INS:] += dx[N_INS:]
        C_prior, J_prior = C, J
        s = ins.state
        C = C_e_n(s.lat_rad, s.lon_rad)
        J = pos_jacobian(s.lat_rad, s.alt_m)
        r_ins = geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m)
        _record(out, k, ins, P, r_ins, C, J)
        out.gnss[k] = True
        out.n_sats[k] = js.size
        # Wide-lane phase less the range at the updated state [cycles], undifferenced (see _InertialWideLane).
        h_pos = los @ C_prior @ J_prior
        g = (LW[k, js] + clk_m - zhd - rho - m_wet * x[_ZWD] - h_pos @ dx[DPOS]) / LAM_WL_M
        if o.ar:
            if o.wl_inertial:
                H_sd = np.column_stack([h_pos - h_pos[iref], m_wet - m_wet[iref]])
                rows, y_wl, R_wl = iwl.fix(js, amb.ref, g, np.sin(elev), t[k], H_sd, P[np.ix_(_POS_ZWD, _POS_ZWD)],
                                           gnss.wsb_cyc, o)
                if rows.size:  # the fixed wide-lanes as ranges: the position to centimetres for the narrow-lane
                    H_wl = np.zeros((rows.size, n_x))
                    H_wl[:, _POS_ZWD] = H_sd[rows]
                    dx2, P, _, _ = kalman.update(np.zeros(n_x), P, y_wl, H_wl, R_wl)
                    ins.feedback(dx2)
                    x[N_INS:] += dx2[N_INS:]
                    g = g - (h_pos @ dx2[DPOS] + m_wet * dx2[_ZWD]) / LAM_WL_M
                    s = ins.state
                    C, J = C_e_n(s.lat_rad, s.lon_rad), pos_jacobian(s.lat_rad, s.alt_m)
                    _record(out, k, ins, P, geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m), C, J)
            held = _fix(out, k, ins, P, x, jo, amb.ref, (mw_sum, mw_sq, mw_n), (iwl.on, iwl.wl_cyc), gnss.wsb_cyc, o)
        P_last = P
        if held is not None:
            g = g - (h_pos @ held[0][DPOS] + m_wet * held[0][_ZWD]) / LAM_WL_M
            P_last = held[1]
        iwl.store(js, g, np.sin(elev), t[k], k, np.column_stack([h_pos, m_wet]), P_last[np.ix_(_POS_ZWD, _POS_ZWD)])
    return out


def _mw_mean(mw_sum, mw_sq, mw_n):
    """Means of the Melbourne-Wuebbena arcs and their variances (from the scatter), shape (n_sv,)."""
    mean = mw_sum / np.maximum(mw_n, 1)
    var_mean = np.maximum(mw_sq / np.maximum(mw_n, 1) - mean**2, 0.0) / np.maximum(mw_n - 1, 1)
    return mean, var_mean


def _mw_var_mean(mw_cyc, mw_n, mean, lags):
    """Variances of the Melbourne-Wuebbena arc means, the time correlation of their noise counted.

    The code multipath in the Melbourne-Wuebbena combination is correlated
    over seconds, so the scatter over ``n - 1`` (:func:`_mw_mean`) is too
    small for the mean. Here the autocovariances up to ``lags`` epochs,
    Bartlett-weighted (Newey-West), sum to the variance of the mean.

    Parameters
    ----------
    mw_cyc : ndarray, shape (n_epochs, n_sv)
        Melbourne-Wuebbena combinations [cycles] up to the arcs' last epoch
        (NaN where not observed).
    mw_n : ndarray of int, shape (n_sv,)
        Epochs in each arc's mean: its last ``mw_n`` finite values.
    mean : ndarray, shape (n_sv,)
        The arcs' means.
    lags : int

    Returns
    -------
    var_mean : ndarray, shape (n_sv,)
        [cycles^2]; inf for arcs of fewer than ``2 lags`` epochs.
    """
    var_mean = np.full(mean.shape, np.inf)
    w = 1.0 - np.arange(1, lags + 1) / (lags + 1.0)
    for j in np.flatnonzero(mw_n >= 2 * lags):
        x = mw_cyc[:, j][np.isfinite(mw_cyc[:, j])][-mw_n[j]:] - mean[j]
        n = x.size
        acov = np.array([x[lag:] @ x[:n - lag] for lag in range(lags + 1)]) / n
        var_mean[j] = max(acov[0] + 2.0 * w @ acov[1:], acov[0]) / n  # never below the white-noise value
    return var_mean


@dataclass
class _Geometry:
    """One epoch's predicted ranges, rates, lines of sight, wet mappings, sin(elev); reference and others."""

    rho: np.ndarray
    rate: np.ndarray
    los: np.ndarray
    m_wet: np.ndarray
    sin_el: np.ndarray
    iref: int
    others: np.ndarray
    jo: np.ndarray


def _sd_measurements(g, observed, x, C, J, use, o):
    """SD innovations, design matrix and covariance of one epoch.

    Parameters
    ----------
    g : _Geometry
    observed : tuple of ndarray, each shape (m,)
        Corrected IF code, IF phase [m] and range rate [m/s] of the epoch's satellites.
    x : ndarray, shape (n_x,)
        Non-INS states (ZWD, SD ambiguities).
    C, J : ndarray, shape (3, 3)
        ``C_e_n`` and the position Jacobian at the INS.
    use : list of 3 ndarray of bool, shape (m - 1,)
        Rows kept per kind (code, phase, rate).

    Returns
    -------
    H : ndarray, shape (r, n_x)
    y : ndarray, shape (r,)
    R : ndarray, shape (r, r)
        Block diagonal: each kind ``diag(var_j) + var_ref``.
    sizes : ndarray of int, shape (4,)
        Row offsets of the three kinds.
    """
    n_x = x.size
    e_sd = g.los[g.others] - g.los[g.iref]
    mw_sd = g.m_wet[g.others] - g.m_wet[g.iref]
    rng = g.rho + g.m_wet * x[_ZWD]
    rows_H, rows_y, blocks = [], [], []
    for kind, (obs, pred, sig) in enumerate(zip(observed, (rng, rng, g.rate),
                                                (o.sigma_code_m, o.sigma_phase_m, o.sigma_rate_mps))):
        u = use[kind]
        H = np.zeros((u.sum(), n_x))
        y = (obs[g.others] - obs[g.iref]) - (pred[g.others] - pred[g.iref])
        if kind < 2:
            H[:, DPOS] = e_sd[u] @ C @ J
            H[:, _ZWD] = mw_sd[u]
        else:
            H[:, DV] = e_sd[u] @ C
        if kind == 1:
            H[np.arange(u.sum()), _A0 + g.jo[u]] = 1.0
            y = y - x[_A0 + g.jo]
        var = (sig / g.sin_el) ** 2
        rows_H.append(H)
        rows_y.append(y[u])
        blocks.append(_sd_cov(var[g.others][u], var[g.iref]))
    R = np.zeros((sum(len(b) for b in blocks),) * 2)
    sizes = np.cumsum([0] + [len(b) for b in blocks])
    for b, off in zip(blocks, sizes):
        R[off:off + len(b), off:off + len(b)] = b
    return np.vstack(rows_H), np.concatenate(rows_y), R, sizes


def _record(out, k, ins, P, r_ins, C, J):
    out.pos_float_ecef_m[k] = r_ins
    out.cov_pos_enu_m2[k] = J @ P[DPOS, DPOS] @ J.T
    out.cov_ins[k] = P[:N_INS, :N_INS]


def _fix(out, k, ins, P, x, jo, ref, mw, inertial, wsb, o):
    """Wide-lane rounding, narrow-lane LAMBDA; the fixed position into ``out`` when a subset passes.

    Returns the fixed solution as the state increment ``dx`` (shape (n_x,))
    and the covariance conditioned on the fixed ambiguities (shape (n_x, n_x)),
    or None when nothing is fixed.

    ``mw`` holds the running sums, sums of squares and counts of each
    satellite's Melbourne-Wuebbena arc; a SD wide-lane is rounded when both
    arcs have ``wl_min_epochs``, the standard error of the SD mean is below
    ``wl_se_max_cyc`` and the rounding is below ``wl_tol_cyc``. ``inertial``
    holds which satellites have a wide-lane fixed from the INS geometry
    after a gap and its value (:class:`_InertialWideLane`); those are used
    where the reference has one too.
    """
    mw_sum, mw_sq, mw_n = mw
    on, wl_cyc = inertial
    mean, var_mean = _mw_mean(mw_sum, mw_sq, mw_n)
    by_ins = on[jo] & on[ref]
    wl_mw = mean[jo] - mean[ref] - (wsb[jo] - wsb[ref])
    n_mw = np.round(wl_mw)
    by_mw = ((mw_n[jo] >= o.wl_min_epochs) & (mw_n[ref] >= o.wl_min_epochs) & (np.abs(wl_mw - n_mw) < o.wl_tol_cyc)
             & (np.sqrt(var_mean[jo] + var_mean[ref]) < o.wl_se_max_cyc))
    n_wl = np.where(by_ins, np.round(wl_cyc[jo] - wl_cyc[ref] - (wsb[jo] - wsb[ref])), n_mw)
    out.n_wl_checked += int(np.sum(by_ins & by_mw))
    out.n_wl_mismatch += int(np.sum(by_ins & by_mw & (n_wl != n_mw)))
    good = by_ins | by_mw
    jo, n_wl = jo[good], n_wl[good]
    out.n_wl[k] = jo.size
    if jo.size < o.min_fixed:
        return None
    a = _A0 + jo
    a_hat = (x[a] - BETA_M * n_wl) / LAM_NL_M
    Q = P[np.ix_(a, a)] / LAM_NL_M**2
    fixed, n1, ratio = partial_fix(a_hat, Q, ratio_min=o.ratio_min, min_fixed=o.min_fixed, success_min=o.success_min)
    out.ratio[k] = ratio
    if not fixed.any():
        return None
    af = a[fixed]
    b_fix = LAM_NL_M * n1[fixed] + BETA_M * n_wl[fixed]
    gain = np.linalg.solve(P[np.ix_(af, af)], P[af, :]).T  # (n_x, n_fixed)
    dx = gain @ (b_fix - x[af])
    s = ins.state.corrected(dpos=dx[DPOS])
    out.pos_fixed_ecef_m[k] = geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m)
    out.n_fixed[k] = fixed.sum()
    P_fixed = P - gain @ P[af, :]
    return dx, 0.5 * (P_fixed + P_fixed.T)
