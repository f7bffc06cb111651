"""Observations of the PPP: ionosphere-free, Melbourne-Wuebbena and geometry-free combinations, slips, a first fix.

The signal pairs are those of the IGS / MGEX clock products: GPS C1W/C2W
(C1C when C1W is missing) with L1C/L2W, Galileo C1C/C5Q with L1C/L5Q.
"""

import numpy as np

from ..constants import C_MPS
from ..errors import InputError
from ..frames import rotate_to_later_ecef

__all__ = ["F_L1_HZ", "F_L2_HZ", "F_L5_HZ", "SIGNALS", "detect_slips", "if_observations", "spp_position"]

F_L1_HZ, F_L2_HZ, F_L5_HZ = 1575.42e6, 1227.60e6, 1176.45e6

#: Per system: (first codes in order of preference, second code, first phase, second phase, f1, f2).
SIGNALS = {
    "G": (("C1W", "C1C"), "C2W", "L1C", "L2W", F_L1_HZ, F_L2_HZ),
    "E": (("C1C",), "C5Q", "L1C", "L5Q", F_L1_HZ, F_L5_HZ),
}


def _pick(obs, s, codes):
    for c in codes:
        key = f"{s}:{c}"
        if key in obs.obs and np.isfinite(obs.obs[key]).any():
            return key
    return None


def if_observations(obs, systems):
    """IF code and phase, Melbourne-Wuebbena and geometry-free combinations, loss-of-lock flags.

    Parameters
    ----------
    obs : leosop.gnss.rinex.ObsData
    systems : str
        System letters (keys of :data:`SIGNALS`).

    Returns
    -------
    dict of str -> ndarray, shape (n_epochs, n_sats)
        ``P``, ``L`` ionosphere-free code and phase [m], ``MW`` [wide-lane
        cycles], ``GF`` = L1 - L2 [m], ``lam_nl``, ``lam_wl`` [m], ``lli``
        (bool); NaN for satellites of other systems.
    """
    n_ep, n_sv = len(obs.time_gps), len(obs.sv)
    out = {k: np.full((n_ep, n_sv), np.nan) for k in ("P", "L", "MW", "GF", "lam_nl", "lam_wl")}
    out["lli"] = np.zeros((n_ep, n_sv), bool)
    sysof = np.array([s[0] for s in obs.sv])
    found = False
    for s in systems:
        cols = sysof == s
        if not cols.any():
            continue
        c1s, c2, l1, l2, f1, f2 = SIGNALS[s]
        keys = [_pick(obs, s, c1s), _pick(obs, s, (c2,)), _pick(obs, s, (l1,)), _pick(obs, s, (l2,))]
        if None in keys:
            missing = [n for n, k in zip((f"{'/'.join(c1s)}", c2, l1, l2), keys) if k is None]
            raise InputError(f"{obs.path}: system {s} lacks {', '.join(missing)} for the ionosphere-free "
                             "combination (SYS / # / OBS TYPES)")
        found = True
        P1, P2 = obs.obs[keys[0]][:, cols], obs.obs[keys[1]][:, cols]
        lam1, lam2 = C_MPS / f1, C_MPS / f2
        L1, L2 = obs.obs[keys[2]][:, cols] * lam1, obs.obs[keys[3]][:, cols] * lam2
        g1, g2 = f1**2 / (f1**2 - f2**2), f2**2 / (f1**2 - f2**2)
        out["P"][:, cols] = g1 * P1 - g2 * P2
        out["L"][:, cols] = g1 * L1 - g2 * L2
        lam_wl = C_MPS / (f1 - f2)
        out["MW"][:, cols] = ((f1 * L1 - f2 * L2) / (f1 - f2) - (f1 * P1 + f2 * P2) / (f1 + f2)) / lam_wl
        out["GF"][:, cols] = L1 - L2
        out["lam_nl"][:, cols] = C_MPS / (f1 + f2)
        out["lam_wl"][:, cols] = lam_wl
        out["lli"][:, cols] = ((obs.lli[keys[2]][:, cols] & 1) | (obs.lli[keys[3]][:, cols] & 1)).astype(bool)
    if not found:
        raise InputError(f"{obs.path}: no satellites of systems {systems!r}")
    return out


def detect_slips(t_s, MW, GF, lli, ok, opt):
    """New-arc flags: a long gap, the loss-of-lock flag, a Melbourne-Wuebbena or a geometry-free jump.

    The MW combination (wide-lane phase minus narrow-lane code, in wide-lane
    cycles) is compared with its running arc mean: a slip changing ``N1 -
    N2`` moves it by whole cycles, beyond ``opt.mw_slip_cycles`` standard
    deviations of the arc (at least 1 cycle). The geometry-free phase ``L1 -
    L2`` [m] catches the slips MW cannot see (``dN1 = dN2``, 5.4 cm per
    cycle on GPS L1/L2): a jump beyond ``opt.gf_slip_m`` from its value
    predicted with the arc's slope over the last ``opt.gf_rate_window_s``
    (the ionosphere's drift). So an arc survives a gap in the data (a link
    or logging outage, up to ``opt.max_gap_s``) when both tests pass, the
    idea of [Geng 2010]'s rapid re-convergence; on ESBC00DNK the
    prediction over 330 s is within 5 cm at 99 % of the satellites above
    20 deg (6 cm above 10 deg). A receiver that lost lock flags it and
    starts new arcs.

    Parameters
    ----------
    t_s : ndarray, shape (n_epochs,)
    MW, GF : ndarray, shape (n_epochs, n_sats)
    lli, ok : ndarray of bool, shape (n_epochs, n_sats)
    opt : PppOptions
        ``max_gap_s``, ``mw_slip_cycles``, ``gf_slip_m``, ``gf_rate_window_s``.

    Returns
    -------
    ndarray of bool, shape (n_epochs, n_sats)
        True at the first epoch of every arc.
    """
    n_ep, n_sv = MW.shape
    new_arc = np.zeros((n_ep, n_sv), bool)
    for j in range(n_sv):
        idx = np.flatnonzero(ok[:, j])
        last_t, mean, var, n, last_gf, rate, base = -np.inf, 0.0, 0.0, 0, np.nan, 0.0, 0
        for k, i in enumerate(idx):
            mw, gf = MW[i, j], GF[i, j]
            slip = (t_s[i] - last_t > opt.max_gap_s) or lli[i, j]
            if not slip and n >= 1:
                sd = max(np.sqrt(var / n) if n > 1 else 0.0, 1.0)
                slip = (abs(mw - mean) > opt.mw_slip_cycles * sd
                        or abs(gf - last_gf - rate * (t_s[i] - last_t)) > opt.gf_slip_m)
            if slip:
                new_arc[i, j] = True
                mean, var, n, base = mw, 0.0, 1, k
            else:
                n += 1
                d = mw - mean
                mean += d / n
                var += d * (mw - mean)
                while t_s[i] - t_s[idx[base]] > opt.gf_rate_window_s:
                    base += 1
                i0 = idx[base]
                rate = (gf - GF[i0, j]) / (t_s[i] - t_s[i0]) if i0 != i else 0.0
            last_t, last_gf = t_s[i], gf
    return new_arc


def spp_position(pos_sv_ecef_m, p_corr_m, *, iterations=8):
    """Code-only least-squares position of one epoch (a priori for the models).

    Parameters
    ----------
    pos_sv_ecef_m : ndarray, shape (m, 3)
        Satellite positions (Sagnac applied or not: the metre level is enough).
    p_corr_m : ndarray, shape (m,)
        IF code plus satellite clock ``c dt_sv``.

    Returns
    -------
    ndarray, shape (3,)
    """
    x = np.zeros(4)
    for _ in range(iterations):
        rs = rotate_to_later_ecef(pos_sv_ecef_m, np.linalg.norm(pos_sv_ecef_m - x[:3], axis=1) / C_MPS)
        rho = np.linalg.norm(rs - x[:3], axis=1)
        H = np.hstack([(x[:3] - rs) / rho[:, None], np.ones((len(rho), 1))])
        dx = np.linalg.lstsq(H, p_corr_m - rho - x[3], rcond=None)[0]
        x += dx
    return x[:3]
