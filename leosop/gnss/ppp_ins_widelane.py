"""Wide-lane side of PPP/INS: L1/L2 combinations, Melbourne-Wuebbena arc means, wide-lanes fixed from the INS.

:func:`if_combinations` gives the ionosphere-free code and phase, the
Melbourne-Wuebbena (MW) combination and the geometry-free phase;
:func:`mw_mean` and :func:`mw_var_mean` the MW arc means and their
variances (the second with the code multipath's time correlation);
:class:`InertialWideLane` [Liu 2016]'s fast re-fix after a GNSS gap: the new
arcs' wide-lanes from the wide-lane phase less the range predicted at the
INS. Used by the PPP/INS filter of :mod:`leosop.gnss.ppp_ins`.
"""

import numpy as np

from ..constants import C_MPS
from .lambda_ import partial_fix
from .simulate import F1_HZ, F2_HZ

__all__ = ["BETA_M", "KAPPA_WL_PER_GF", "LAM_NL_M", "LAM_WL_M", "InertialWideLane", "if_combinations", "mw_mean",
           "mw_var_mean"]

LAM_NL_M = C_MPS / (F1_HZ + F2_HZ)
LAM_WL_M = C_MPS / (F1_HZ - F2_HZ)
# Ionosphere in the wide-lane phase [cycles] per metre of geometry-free phase L1 - L2 [m]: (f1/f2) I1 / LAM_WL
# against (f1^2/f2^2 - 1) I1.
KAPPA_WL_PER_GF = (F1_HZ / F2_HZ) / (LAM_WL_M * ((F1_HZ / F2_HZ) ** 2 - 1.0))
BETA_M = C_MPS * F2_HZ / (F1_HZ**2 - F2_HZ**2)  # IF ambiguity [m] = LAM_NL N1 + BETA N_WL


def if_combinations(P1_m, P2_m, L1_cyc, L2_cyc):
    """Ionosphere-free code and phase [m], Melbourne-Wuebbena [wide-lane cycles], geometry-free phase [m].

    Arrays of any one shape (GPS L1/L2).
    """
    f1, f2 = F1_HZ, F2_HZ
    g1, g2 = f1**2 / (f1**2 - f2**2), f2**2 / (f1**2 - f2**2)
    L1, L2 = L1_cyc * C_MPS / f1, L2_cyc * C_MPS / f2
    mw = ((f1 * L1 - f2 * L2) / (f1 - f2) - (f1 * P1_m + f2 * P2_m) / (f1 + f2)) / (C_MPS / (f1 - f2))
    return g1 * P1_m - g2 * P2_m, g1 * L1 - g2 * L2, mw, L1 - L2


def mw_mean(mw_sum, mw_sq, mw_n):
    """Means of the Melbourne-Wuebbena arcs and their variances (from the scatter), shape (n_sv,)."""
    mean = mw_sum / np.maximum(mw_n, 1)
    var_mean = np.maximum(mw_sq / np.maximum(mw_n, 1) - mean**2, 0.0) / np.maximum(mw_n - 1, 1)
    return mean, var_mean


def mw_var_mean(mw_cyc, mw_n, mean, lags):
    """Variances of the Melbourne-Wuebbena arc means, the time correlation of their noise counted.

    The code multipath in the Melbourne-Wuebbena combination is correlated
    over seconds, so the scatter over ``n - 1`` (:func:`mw_mean`) is too
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


class InertialWideLane:
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
    ``m``'s variance counts the multipath correlation (:func:`mw_var_mean`).
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

    def snapshot(self, t_s, gf_m, new_arc, mean, var_mean, window_s):
        """At the first epoch of a gap: keep the old arcs' MW means, ``g`` and geometry-free slopes."""
        k0 = self.k_last
        self.ok = np.isfinite(self.g_last)
        self.m, self.var_m = mean.copy(), var_mean.copy()
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
