"""Ambiguity resolution of the PPP (:mod:`leosop.gnss.ppp`) with integer-recovery clocks: wide-lane, then narrow-lane.

The CNES/GRG clocks ([Laurichesse 2009]) are computed so that, with the
satellite wide-lane biases of their header (:func:`leosop.gnss.products.
read_wl_biases`), the between-satellite single differences (SD) of the
ambiguities are integers. The undifferenced ionosphere-free ambiguity [m] is
``B = lambda_NL N1 + beta N_WL`` plus receiver biases common to a system
(``lambda_NL = c / (f1 + f2)``, ``beta = c f2 / (f1^2 - f2^2)``), so per
system, against a reference satellite (the highest of those with a
wide-lane):

- wide-lane: ``N_WL`` of the SD is the rounded SD of the Melbourne-
  Wuebbena arc means plus the satellites' biases (``MW + wsb``: on
  ESBC00DNK 2020-06-25 their fractional parts agree within 0.045 cycle,
  against 0.24 with the opposite sign), accepted when the arcs have
  ``wl_min_epochs``, the rounding is within ``wl_tol_cyc`` and the standard
  error of the SD mean (white-noise formula times ``wl_se_inflation`` for
  the correlation of the 30 s code multipath) is below ``wl_se_max_cyc``;
- narrow-lane: ``N1 = (B_SD - beta N_WL) / lambda_NL`` by LAMBDA
  (:mod:`leosop.gnss.lambda_`) on the float filter's covariance, validated
  by the ratio test (``ratio_min``) and the bootstrapped success rate
  (``success_min``; a lower bound of the integer least-squares success
  rate [Teunissen 1998], on top of the ratio test that RTKLIB and
  PRIDE-PPPAR use alone: on ESBC00DNK 2020-06-25 0.999 / 0.99 / 0.95 give a
  kinematic first fix after 28 / 19.5 / 14.5 min, all without a step
  above 5 cm between fixed epochs over 24 h and three 5-min data cuts),
  with partial fixing (the least precise dropped first)
  down to ``min_fixed``; satellites below ``mask_deg`` are left out.

The fixed ambiguities condition the float state (a noise-free pseudo-
observation on a copy): the fixed position and its covariance. Nothing is
held: every epoch is fixed anew from the float filter, as in [Liu 2016].
"""

from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS
from .lambda_ import partial_fix
from .ppp_obs import SIGNALS

__all__ = ["ArFix", "ArOptions", "fix_epoch", "mw_arc_stats", "nl_constants"]


@dataclass(frozen=True)
class ArOptions:
    """Settings of the wide-lane and narrow-lane fixing (cycles, degrees)."""

    wl_min_epochs: int = 10
    wl_tol_cyc: float = 0.25
    wl_se_max_cyc: float = 0.1
    wl_se_inflation: float = 2.0
    mask_deg: float = 15.0
    ratio_min: float = 3.0
    success_min: float = 0.95
    min_fixed: int = 4


@dataclass
class ArFix:
    """One epoch's fixed solution.

    Attributes
    ----------
    dx : ndarray, shape (n_x,)
        Increment of the float state to the fixed one.
    P : ndarray, shape (n_x, n_x)
        Covariance conditioned on the fixed ambiguities.
    n_fixed, n_wl : int
        Narrow-lane SD ambiguities fixed; SD wide-lanes available.
    ratio : float
        Ratio test of the accepted subset.
    """

    dx: np.ndarray
    P: np.ndarray
    n_fixed: int
    n_wl: int
    ratio: float


def nl_constants(sv):
    """Narrow-lane wavelength and ``beta`` [m] per satellite (NaN outside :data:`SIGNALS`), shapes (n_sats,)."""
    lam = np.full(len(sv), np.nan)
    beta = np.full(len(sv), np.nan)
    for j, s in enumerate(sv):
        if s[0] in SIGNALS:
            f1, f2 = SIGNALS[s[0]][4:6]
            lam[j], beta[j] = C_MPS / (f1 + f2), C_MPS * f2 / (f1**2 - f2**2)
    return lam, beta


def mw_arc_stats(MW, ok, new_arc):
    """Running mean, sample variance and count of the Melbourne-Wuebbena combination within each arc.

    Parameters
    ----------
    MW : ndarray, shape (n_epochs, n_sats)
        Wide-lane cycles.
    ok, new_arc : ndarray of bool, shape (n_epochs, n_sats)
        Usable epochs; first epoch of each arc.

    Returns
    -------
    mean, var, n : ndarray, shape (n_epochs, n_sats)
        Over the arc's epochs up to and including each one (NaN / 0 where not ``ok``).
    """
    mean = np.full(MW.shape, np.nan)
    var = np.full(MW.shape, np.nan)
    n = np.zeros(MW.shape, int)
    for j in range(MW.shape[1]):
        idx = np.flatnonzero(ok[:, j])
        if not idx.size:
            continue
        arc = np.cumsum(new_arc[idx, j])
        first = np.searchsorted(arc, arc)  # position in idx of each arc's first epoch
        v = MW[idx, j] - MW[idx[first], j]  # centred on the arc's first value: the sums stay small
        s1, s2 = np.cumsum(v), np.cumsum(v * v)
        k = np.arange(idx.size)
        before = first - 1
        s1 = s1 - np.where(before >= 0, s1[before], 0.0)
        s2 = s2 - np.where(before >= 0, s2[before], 0.0)
        cnt = k - first + 1
        m = s1 / cnt
        mean[idx, j] = m + MW[idx[first], j]
        var[idx, j] = np.where(cnt > 1, (s2 - cnt * m * m) / np.maximum(cnt - 1, 1), np.nan)
        n[idx, j] = cnt
    return mean, var, n


def _wide_lanes(js, wl_cyc, se_cyc, sysof, elev, o):
    """Reference per system and the SD wide-lanes of the others.

    Returns
    -------
    ref : ndarray of int, shape (m,)
        The reference satellite of each SD.
    other : ndarray of int, shape (m,)
    n_wl : ndarray, shape (m,)
        Integer SD wide-lanes.
    """
    refs, others, n_wls = [], [], []
    for s in np.unique(sysof[js]):
        cand = js[sysof[js] == s]
        if cand.size < 2:
            continue
        ref = cand[np.argmax(elev[cand])]
        oth = cand[cand != ref]
        sd = wl_cyc[oth] - wl_cyc[ref]
        n = np.round(sd)
        good = (np.abs(sd - n) < o.wl_tol_cyc) & (np.hypot(se_cyc[oth], se_cyc[ref]) < o.wl_se_max_cyc)
        refs.append(np.full(good.sum(), ref))
        others.append(oth[good])
        n_wls.append(n[good])
    if not refs:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    return np.concatenate(refs), np.concatenate(others), np.concatenate(n_wls)


def fix_epoch(x, P, amb0, js, wl_cyc, se_cyc, sysof, elev, lam_nl, beta, o):
    """Wide-lane rounding and narrow-lane LAMBDA on one epoch of the float filter.

    Parameters
    ----------
    x : ndarray, shape (n_x,)
    P : ndarray, shape (n_x, n_x)
        Float state and covariance; the IF ambiguity [m] of satellite ``j`` is
        ``x[amb0 + j]``.
    amb0 : int
    js : ndarray of int, shape (k,)
        Candidate satellites (tracked, above the AR mask, allowed to fix).
    wl_cyc, se_cyc : ndarray, shape (n_sats,)
        Wide-lane ``MW`` arc mean plus the satellite bias, and its standard error [cycles].
    sysof : ndarray of str, shape (n_sats,)
    elev : ndarray, shape (n_sats,)
        Elevations [rad] (the reference is the highest).
    lam_nl, beta : ndarray, shape (n_sats,)
        From :func:`nl_constants`.
    o : ArOptions

    Returns
    -------
    ArFix or None
        None when fewer than ``min_fixed`` SD ambiguities pass.
    """
    ref, oth, n_wl = _wide_lanes(js, wl_cyc, se_cyc, sysof, elev, o)
    if oth.size < o.min_fixed:
        return None
    n_x = len(x)
    H = np.zeros((oth.size, n_x))
    rows = np.arange(oth.size)
    H[rows, amb0 + oth] = 1.0
    H[rows, amb0 + ref] = -1.0
    lam = lam_nl[oth]  # the same within a system: reference and other share it
    a_hat = (H @ x - beta[oth] * n_wl) / lam
    PHt = P @ H.T
    Q = (H @ PHt) / np.outer(lam, lam)
    fixed, n1, ratio = partial_fix(a_hat, Q, ratio_min=o.ratio_min, min_fixed=o.min_fixed,
                                   success_min=o.success_min)
    if not fixed.any():
        return None
    Hf, PHf = H[fixed], PHt[:, fixed]
    z = lam[fixed] * n1[fixed] + beta[oth[fixed]] * n_wl[fixed]
    gain = np.linalg.solve(Hf @ PHf, PHf.T).T  # (n_x, n_fixed)
    dx = gain @ (z - Hf @ x)
    P_fix = P - gain @ PHf.T
    return ArFix(dx=dx, P=0.5 * (P_fix + P_fix.T), n_fixed=int(fixed.sum()), n_wl=int(oth.size), ratio=float(ratio))
