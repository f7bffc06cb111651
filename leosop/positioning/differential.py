"""Differential Doppler fix: a base at a known site removes what it shares with the rover.

A base receiver at a known position and a rover measure the Doppler of the
same satellites (matched by ``sat_id``). The satellite's oscillator offset
and drift are in both measurements alike, and an element-set error moves
both receivers' predicted Doppler almost alike (the difference falls with
the baseline over the range, ~1/100 at 5-10 km). The base's correction of
each row, its measurement minus the Doppler its known position predicts
(:func:`~leosop.geometry.doppler.doppler_jacobian`'s model), holds those
satellite terms and the base clock; interpolated linearly in time to the
rover's epochs and subtracted from the rover's measurement it leaves the
single difference between receivers (rover minus base)::

    z = y_rover - (y_base - D(base)) = D(rover) + (T_rover - T_base) + noise

which is what is fitted: the rover's position (one for all rows, or one per
block of ``block_s`` seconds, the rover at rest within a block) and the
rover-minus-base frequency offset, a polynomial in time (offset and drift by
default). With identical epochs the correction is the base's own row and
``z`` is the plain single difference; between base epochs the linear
interpolation carries a satellite drift exactly (a satellite offset or drift
cancels to round-off) and its variance is that of the weighted base rows.
Rover rows that interpolate the same base row share its noise: the fit
whitens each block's rows with the Cholesky factor of that covariance
(:func:`_whitener`; banded, diagonal when the epochs coincide), so the
chi-square, the w-test and the covariance see independent rows. A row's
exclusion drops its whitened row (the row's innovation given the earlier
rows it is correlated with); rows of different blocks that share a base row
are treated as independent (each block's covariance is right on its own).

Rows of a satellite that only one receiver saw, and rover rows outside the
time span of their satellite's base rows (or in a gap wider than
``max_gap_s``), are left out and counted. The solve is
:func:`~leosop.positioning.robust_ls.solve_robust` (batched over blocks, the
w-test outlier exclusion) and each block's status is
:func:`~leosop.positioning.quality.fix_status` with its satellites as passes.

The element-set error's residual (the differential term above) grows with
the baseline: each common satellite's radial / along / cross-track offset is
a state with a prior in the inertial orbit's RTN frame (an element set's
error; :func:`rtn_frames`), moving its position and, as that frame turns in
ECEF, its velocity. tools/bench_differential.py measures the NEES over the baseline.

Joint fit (``sat_clock_degree``). A single difference sees an offset only
through the baseline (~1 Hz for 300 m along-track at 7.5 km), where over a
short span it looks like the rover's position: from 20 s the offsets, not
the noise, set the fix's sigma (4.9 m against 1.2 m without them). At its
known site the base sees the offset's whole Doppler (tens of Hz), and that
curves over the pass where a satellite's oscillator is an offset and a
drift. Keeping the base's rows instead of differencing them::

    y_base  = D(base)  + G_base d  + s_k(t)
    y_rover = D(rover) + G_rover d + s_k(t) + (T_rover - T_base)(t)

with ``s_k`` satellite k's frequency as the base sees it (its oscillator
plus the base clock), a polynomial of ``sat_clock_degree`` per block, and
``d`` the offsets, the base's rows tell ``d`` apart from the rover's
position (20 s: sigma 2.3 m, the Cramer-Rao bound of this model). No
interpolation, every row its own noise. The price is the assumption on the
oscillators: a curvature the polynomial lacks goes into the fix
(tools/bench_differential.py). A satellite absent from a block's rows gets a
prior row that fixes its polynomial (no information, no redundancy).
"""

from dataclasses import dataclass

import numpy as np

from ..constants import OMEGA_E_RAD_PER_S
from ..errors import InputError
from ..frames import ecef_to_geodetic
from ..geometry.dop import cofactor
from ..timebase import seconds_since
from .differential_base import MAX_GAP_S, TIME_TOL_S, base_corrections, model_hz, sv_states, whitener
from .quality import fix_status
from .robust_ls import XTOL_POS_M, FixStatus, solve_robust

__all__ = ["MOTIONS", "ORBIT_SIGMA_RTN_M", "DifferentialFix", "rtn_frames", "solve_differential"]

#: Default prior standard deviation of an element-set offset, radial / along-track / cross-track [m]:
#: along-track as tools/bench_static_time_offset.py (300 m); radial and cross-track smaller, as for any
#: SGP4 fit (assumed, not measured on Starlink).
ORBIT_SIGMA_RTN_M = (30.0, 300.0, 100.0)
#: Convergence threshold of a rover velocity [m/s]: 10 um/s (a 0.1 mm position over 10 s).
_XTOL_VEL_MPS = 1e-5
#: Motion models of the rover within a block.
MOTIONS = ("rest", "constant_velocity")
#: Convergence thresholds of the clock terms: 10 uHz and 0.1 uHz/s (higher terms divided by powers of the
#: half span).
_XTOL_CLOCK = (1e-5, 1e-7)


@dataclass(frozen=True, eq=False)
class DifferentialFix:
    """Differential fixes of the rover, one per block (one block for a static fix).

    Attributes
    ----------
    pos_ecef_m : ndarray, (n_b, 3)
        Rover position of each block (at ``t_ref_s``); NaN where not solved.
    vel_ecef_mps : ndarray, (n_b, 3), or None
        Rover velocity of each block (``motion="constant_velocity"``); None
        for a rover at rest.
    clock_poly_hz : ndarray, (n_b, d + 1)
        Rover-minus-base frequency offset polynomial in ``t - t_ref_s`` [Hz/s^k], lowest first.
    t_ref_s : ndarray, (n_b,)
        Mid-time of each block's rows (the time base of the inputs).
    cov : ndarray, (n_b, k, k)
        Covariance of ``[pos, vel (when estimated), clock terms]`` (times ``chi2 / dof`` when the
        residuals fail their test, see :mod:`~leosop.positioning.robust_ls`).
    gdop : ndarray, (n_b,)
        ``sqrt(trace((H^T W H)^-1))`` over the used rows, weights relative
        to the median.
    solver_status : ndarray of int, (n_b,)
        :class:`~leosop.positioning.robust_ls.FixStatus`.
    status : ndarray of str, (n_b,)
        :func:`~leosop.positioning.quality.fix_status`: ``ok`` when the
        toolkit vouches for the fix.
    chi2, chi2_p : ndarray, (n_b,)
    dof, n_used, n_sats, iterations : ndarray of int, (n_b,)
        ``n_used``: rows used (the base's too in the joint fit); ``n_sats``:
        satellites with a used rover row.
    block : ndarray of int, (m,)
        Block of each rover row; -1 where the row had no base correction.
    z_hz, sigma_hz, residuals_hz : ndarray, (m,)
        Per rover row: single difference, its sigma (rover and interpolated
        base), residual (NaN where not used); in the joint fit the rover's
        Doppler and sigma.
    used : ndarray of bool, (m,)
    rover_only_sats, base_only_sats : tuple of str
        Satellites seen by one receiver only (left out).
    n_unmatched_rows : int
        Rover rows of common satellites outside their base span or in a gap.
    """

    pos_ecef_m: np.ndarray
    vel_ecef_mps: np.ndarray | None
    clock_poly_hz: np.ndarray
    t_ref_s: np.ndarray
    cov: np.ndarray
    gdop: np.ndarray
    solver_status: np.ndarray
    status: np.ndarray
    chi2: np.ndarray
    chi2_p: np.ndarray
    dof: np.ndarray
    n_used: np.ndarray
    n_sats: np.ndarray
    iterations: np.ndarray
    block: np.ndarray
    z_hz: np.ndarray
    sigma_hz: np.ndarray
    residuals_hz: np.ndarray
    used: np.ndarray
    rover_only_sats: tuple
    base_only_sats: tuple
    n_unmatched_rows: int


def rtn_frames(pos_sv_ecef_m, vel_sv_ecef_mps):
    """Radial / along-track / cross-track axes of the inertial orbit (columns of C, (..., 3, 3)) in ECEF
    axes, and their rate W = dC/dt (..., 3, 3) in the ECEF frame.

    An element set's error is an offset of the satellite on its inertial
    orbit (its along-track part a time offset of that orbit, as the static
    fix and the generator model it: :func:`~leosop.geometry.doppler.doppler_rate`
    with ``inertial``): radial along ``r``, cross-track along
    ``h = r x (v + w x r)`` (the inertial velocity, ``w`` the Earth's rate),
    along-track ``n x r``, so an along-track offset ``d`` is, to first order, a
    time offset of ``d / |v + w x r|``. Axes built from the ECEF velocity
    instead tilt by up to ``w |r| / |v|`` ~ 4 deg, 7 % of an along-track offset
    put across the track. An offset ``C d`` fixed in that frame moves in ECEF
    with velocity ``W d``: the radial axis turns with ``r``, the inertial
    orbit plane (fixed in space but for the oblateness, ~1e-6 rad/s, left out)
    turns in ECEF at ``-w``: ``dn/dt = -w x n``, ~7e-5 rad/s, which moves a
    300 m along-track offset by 2 cm/s, ~1 Hz at Ku band, which the rover and
    the base see the more differently the longer the baseline.
    """
    r, v = np.asarray(pos_sv_ecef_m, float), np.asarray(vel_sv_ecef_mps, float)
    omega = np.array([0.0, 0.0, OMEGA_E_RAD_PER_S])
    norm_r = np.linalg.norm(r, axis=-1, keepdims=True)
    radial = r / norm_r
    h = np.cross(r, v + np.cross(omega, r))
    normal = h / np.linalg.norm(h, axis=-1, keepdims=True)
    d_normal = -np.cross(omega, normal)
    d_radial = (v - radial * np.sum(radial * v, axis=-1, keepdims=True)) / norm_r
    along = np.cross(normal, radial)
    d_along = np.cross(d_normal, radial) + np.cross(normal, d_radial)
    return np.stack([radial, along, normal], axis=-1), np.stack([d_radial, d_along, d_normal], axis=-1)

def solve_differential(rover, base, base_pos_ecef_m, *, pos0_ecef_m=None, block_s=None, motion="rest",
                       clock_degree=1, sat_clock_degree=None, orbit_sigma_rtn_m=ORBIT_SIGMA_RTN_M,
                       max_gap_s=MAX_GAP_S, max_iter=200, alpha=1e-3):
    """Differential Doppler fix of a rover at rest or moving (per block) against a base at a known site.

    Parameters
    ----------
    rover, base : Measurements
        Each with satellite states (light time for its own position) and
        ``sigma_hz``. Times: both with ``time_utc``, or ``t_s`` on one time
        base. A satellite's carrier must be the same in both.
    base_pos_ecef_m : array_like, (3,)
    pos0_ecef_m : array_like, (3,), optional
        Start of the rover's position; default the base's.
    block_s : float, optional
        Length of the blocks, each with its own rover position and clock
        terms (from the first rover row); None: one static fix.
    motion : {"rest", "constant_velocity"}
        The rover within a block: at rest, or moving at a constant ECEF
        velocity (three more states; position ``p + v (t - t_ref)``, its
        Doppler with the rover's velocity). A car's blocks of a few seconds
        are nearly straight; the velocity trades against the position
        (1 m of position moves the Doppler like ~1 cm/s), so a moving
        block's fix is much weaker than a static one of the same length.
    clock_degree : int
        Degree of the rover-minus-base frequency-offset polynomial of each block.
    sat_clock_degree : int, optional
        None (default): single differences with the base interpolated to
        the rover's rows. An integer: the joint fit (module notes), each
        satellite's frequency as the base sees it (its oscillator plus the
        base clock) a polynomial of this degree over each block; the
        base's rows then also tell the element-set offsets apart from the
        rover's position. Right only while the satellites' oscillators
        follow that polynomial (tools/bench_differential.py: degree 1
        over 20 s).
    orbit_sigma_rtn_m : array_like, (3,), or None
        Prior standard deviation of each common satellite's element-set
        offset, radial / along-track / cross-track [m]: the offsets are
        states of each block (zero-mean prior rows, never excluded), so the
        covariance carries what the baseline leaves of them. None: no
        offset states (the covariance then ignores them).
    max_gap_s : float
        Widest gap between base rows interpolated across (single differences only).
    max_iter : int
    alpha : float or None
        Significance of the chi-square and w-tests (outlier exclusion and status).

    Returns
    -------
    DifferentialFix
    """
    if motion not in MOTIONS:
        raise ValueError(f"{motion=} must be one of {MOTIONS}")
    if clock_degree < 0:
        raise ValueError(f"{clock_degree=} must be >= 0")
    if sat_clock_degree is not None and sat_clock_degree < 0:
        raise ValueError(f"{sat_clock_degree=} must be None or >= 0")
    if block_s is not None and not block_s > 0:
        raise ValueError(f"{block_s=} must be > 0")
    base_pos = np.asarray(base_pos_ecef_m, dtype=float).reshape(3)
    r_s, v_s = sv_states(rover, "rover")
    if rover.time_utc is not None and base.time_utc is not None:
        epoch = min(rover.time_utc.min(), base.time_utc.min())
        t, tb = seconds_since(rover.time_utc, epoch), seconds_since(base.time_utc, epoch)
    else:
        t, tb = np.asarray(rover.t_s, float), np.asarray(base.t_s, float)
    common = np.intersect1d(rover.sat_id, base.sat_id)
    for sid in common:
        fr, fb = np.unique(rover.carrier_hz[rover.sat_id == sid]), np.unique(base.carrier_hz[base.sat_id == sid])
        if fr.size != 1 or fb.size != 1 or fr[0] != fb[0]:
            raise InputError(f"satellite {sid}: carrier {fr[0]:.10g} Hz at the rover, {fb[0]:.10g} Hz at the base "
                             "(different bands cannot be differenced)")
    m = len(rover.doppler_hz)
    var_r = np.asarray(rover.sigma_hz, float) ** 2
    states_ok = np.isfinite(r_s).all(-1) & np.isfinite(v_s).all(-1)
    if sat_clock_degree is None:
        corr, var_b, base_rows, base_w = base_corrections(base, base_pos, rover.sat_id, t, t_base_s=tb,
                                                          max_gap_s=max_gap_s)
        z = rover.doppler_hz - corr
        sigma = np.sqrt(var_r + var_b)
        usable = np.isfinite(z) & (sigma > 0) & states_ok
        y_all, s_all, t_all, sat_all, f_all = z, sigma, t, rover.sat_id, rover.carrier_hz
        rs_all, vs_all, is_base = r_s, v_s, np.zeros(m, bool)
    else:
        # Joint: the base's own rows join the rover's, each satellite's frequency (its oscillator and the
        # base clock) a polynomial of the block; nothing interpolated, every row's noise its own.
        z, sigma = np.asarray(rover.doppler_hz, float), np.sqrt(var_r)
        usable = np.isin(rover.sat_id, common) & np.isfinite(z) & (sigma > 0) & states_ok
        rb_s, vb_s = sv_states(base, "base")
        y_all, s_all = np.concatenate([z, base.doppler_hz]), np.concatenate([sigma, base.sigma_hz])
        t_all, sat_all = np.concatenate([t, tb]), np.concatenate([rover.sat_id, base.sat_id]).astype(str)
        f_all = np.concatenate([rover.carrier_hz, base.carrier_hz])
        rs_all, vs_all = np.concatenate([r_s, rb_s]), np.concatenate([v_s, vb_s])
        is_base = np.arange(len(y_all)) >= m
        usable = np.concatenate([usable, np.isin(base.sat_id, common) & np.isfinite(base.doppler_hz)
                                 & (np.asarray(base.sigma_hz, float) > 0) & np.isfinite(rb_s).all(-1)
                                 & np.isfinite(vb_s).all(-1)])
    n_unmatched = int((np.isin(rover.sat_id, common) & ~usable[:m]).sum())

    # Blocks from the rover's rows; a base row joins the block of its time (joint fit) or is dropped.
    block = np.full(len(y_all), -1)
    on_rover = usable & ~is_base
    if on_rover.any():
        raw = np.zeros(len(y_all), int) if block_s is None else \
            np.floor((t_all - t_all[on_rover].min()) / block_s + TIME_TOL_S).astype(int)
        labels = np.unique(raw[on_rover])
        j = np.clip(np.searchsorted(labels, raw), 0, len(labels) - 1)
        usable &= labels[j] == raw
        block[usable] = j[usable]
    else:
        usable[:] = False
    n_b = max(int(block.max()) + 1, 1)
    counts = np.bincount(block[usable], minlength=n_b)
    width = max(int(counts.max()), 1)
    slots = np.full((n_b, width), -1)
    rows_sorted = np.flatnonzero(usable)[np.argsort(block[usable], kind="stable")]
    slot = np.arange(rows_sorted.size) - np.repeat(np.cumsum(counts) - counts, counts)
    slots[block[rows_sorted], slot] = rows_sorted
    pad = slots < 0
    take = np.where(pad, 0, slots)
    base_b = is_base[take] & ~pad
    rover_b = (~pad & ~base_b).astype(float)
    y_b, s_b = np.where(pad, 0.0, y_all[take]), np.where(pad, 1.0, s_all[take])
    f_b = np.where(pad, 1.0, f_all[take])
    rs_b = np.where(pad[..., None], [2e7, 0.0, 0.0], rs_all[take])
    vs_b = np.where(pad[..., None], [0.0, 7e3, 0.0], vs_all[take])
    t_b = t_all[take]
    if sat_clock_degree is None:
        whiten = whitener(var_r[take], base_rows[take], base_w[take], np.asarray(base.sigma_hz, float) ** 2, pad)
    else:
        def whiten(v, idx):
            return v / (s_b[idx][..., None] if v.ndim == 3 else s_b[idx])
    empty = pad.all(-1)
    at_rover = pad | base_b
    lo, hi = np.where(at_rover, np.inf, t_b).min(-1), np.where(at_rover, -np.inf, t_b).max(-1)
    t_ref = np.where(empty, 0.0, 0.5 * (np.where(empty, 0.0, lo) + np.where(empty, 0.0, hi)))
    dt = np.where(pad, 0.0, t_b - t_ref[:, None])
    half_span = np.maximum(np.max(np.abs(dt), axis=-1).max(), 1.0)
    powers = dt[..., None] ** np.arange(clock_degree + 1)
    n_vel = 3 if motion == "constant_velocity" else 0
    n_lin = 4 + n_vel + clock_degree
    sat_b = np.where(pad, "", sat_all[take])
    sats_all = np.unique(sat_b[~pad])
    # Joint fit: each satellite's frequency polynomial of each block (a prior row keeps a satellite absent
    # from a block determined; it is no information and no redundancy).
    n_poly = 0 if sat_clock_degree is None else sat_clock_degree + 1
    n_sc = n_poly * len(sats_all)
    onehot_all = (sat_b[..., None] == sats_all).astype(float)
    present = np.repeat((onehot_all > 0).any(axis=1), n_poly, axis=-1)  # (n_b, n_sc)
    sat_powers = (onehot_all[..., :, None] * dt[..., None, None] ** np.arange(n_poly)).reshape(pad.shape + (n_sc,))
    # Element-set offsets: one radial / along / cross-track offset per common satellite, with a prior.
    sats = sats_all if orbit_sigma_rtn_m is not None else []
    n_orb = 3 * len(sats)
    onehot = onehot_all if n_orb else onehot_all[..., :0]
    C_rtn, W_rtn = rtn_frames(rs_b, vs_b)
    # Difference: an offset moves z by rover minus base; joint: each row by its own receiver's view.
    H_sub = model_hz(rs_b, vs_b, base_pos, f_b)[1] if sat_clock_degree is None else np.zeros(rs_b.shape[:2] + (7,))
    n_free = n_lin + n_sc
    n_states = n_free + n_orb
    prior_sigma = np.concatenate([np.ones(n_sc), np.tile(np.asarray(orbit_sigma_rtn_m if n_orb else [], float),
                                                         len(sats))])

    def model_raw(x, idx):
        at_base = base_b[idx][..., None]
        vel = np.where(at_base, 0.0, x[:, None, 3:3 + n_vel]) if n_vel else 0.0
        pos = x[:, None, :3] + (vel * dt[idx][..., None] if n_vel else 0.0)
        pos = np.where(at_base, base_pos, pos)
        pred, H = model_hz(rs_b[idx], vs_b[idx], pos, f_b[idx], vel)
        r = rover_b[idx][..., None]
        pred = pred + np.einsum("pmk,pk->pm", powers[idx] * r, x[:, 3 + n_vel:n_lin])
        d_vel = [H[..., 3:6] + H[..., :3] * dt[idx][..., None]] if n_vel else []
        J = np.concatenate([H[..., :3], *d_vel, powers[idx]], axis=-1) * r
        pred = pred + np.einsum("pmk,pk->pm", sat_powers[idx], x[:, n_lin:n_free])
        J = np.concatenate([J, sat_powers[idx]], axis=-1)
        if not n_orb:
            return pred, J
        # d(row)/d(offset): the satellite moved by C r and its velocity by W r.
        dH = H - H_sub[idx]
        g = -(np.einsum("pmi,pmij->pmj", dH[..., :3], C_rtn[idx])
              + np.einsum("pmi,pmij->pmj", dH[..., 3:6], W_rtn[idx]))
        G = (onehot[idx][..., :, None] * g[..., None, :]).reshape(g.shape[:2] + (n_orb,))
        return pred + np.einsum("pmk,pk->pm", G, x[:, n_free:]), np.concatenate([J, G], axis=-1)

    def model(x, idx, w):
        # Whitened rows, then the prior rows (satellite frequencies, orbit offsets).
        pred, J = model_raw(x, idx)
        pred = np.concatenate([whiten(pred, idx), x[:, n_lin:]], axis=-1)
        J = np.concatenate([whiten(J, idx),
                            np.broadcast_to(np.eye(n_states)[n_lin:], (len(x), n_states - n_lin, n_states))],
                           axis=1)
        return pred, J

    clock_tol = np.concatenate([[_XTOL_CLOCK[0]], _XTOL_CLOCK[1] / half_span ** np.arange(max(clock_degree,
                                                                                               n_poly - 1))])
    xtol = np.concatenate([[XTOL_POS_M] * 3, [_XTOL_VEL_MPS] * n_vel, clock_tol[:clock_degree + 1],
                           np.tile(clock_tol[:n_poly], len(sats_all)), np.full(n_orb, XTOL_POS_M)])
    x0 = np.zeros((n_b, n_states))
    x0[:, :3] = base_pos if pos0_ecef_m is None else np.asarray(pos0_ecef_m, float).reshape(3)
    n_prior = n_sc + n_orb
    y_all = np.concatenate([whiten(y_b, np.arange(n_b)), np.zeros((n_b, n_prior))], axis=-1)
    s_all = np.concatenate([np.ones((n_b, width)), np.broadcast_to(prior_sigma, (n_b, n_prior))], axis=-1)
    m_all = np.concatenate([~pad, ~present, np.ones((n_b, n_orb), bool)], axis=-1)
    fixed = np.arange(width + n_prior) >= width
    x, res, J, Q, used_all, iterations, chi2, solver_status = solve_robust(
        model, x0, y_all, s_all, m_all, n_states, xtol=xtol, max_iter=max_iter, alpha=alpha, fixed=fixed)
    used_b = used_all[:, :width]
    solved = np.isin(solver_status, (FixStatus.OK, FixStatus.INCONSISTENT))
    x = np.where(solved[:, None], x, np.nan)
    Q = np.where(solved[:, None, None], Q, np.nan)
    med = np.array([np.median(s_b[k][~pad[k]]) if (~pad[k]).any() else 1.0 for k in range(n_b)])
    w_rel = np.where(used_b, med[:, None] ** 2, 0.0)
    gdop = np.sqrt(np.trace(cofactor(J[:, :width, :n_lin], w_rel), axis1=-2, axis2=-1))
    n_used = used_b.sum(-1)
    dof = n_used - n_lin - present.sum(-1)
    n_sats = np.array([np.unique(sat_b[k][used_b[k] & (rover_b[k] > 0)]).size for k in range(n_b)])
    _, _, alt = ecef_to_geodetic(np.nan_to_num(x[:, :3]))
    status, chi2_p = fix_status(solver_status, dof, chi2, np.where(solved, alt, np.nan), n_passes=n_sats, alpha=alpha)

    res = np.where(used_b, y_b - model_raw(x, np.arange(n_b))[0], np.nan)
    at_r = ~pad & (rover_b > 0)
    used = np.zeros(m, bool)
    residuals = np.full(m, np.nan)
    used[slots[at_r]] = used_b[at_r]
    residuals[slots[at_r]] = res[at_r]
    block = block[:m]
    return DifferentialFix(
        pos_ecef_m=x[:, :3], vel_ecef_mps=x[:, 3:6] if n_vel else None, clock_poly_hz=x[:, 3 + n_vel:n_lin],
        t_ref_s=t_ref, cov=Q[:, :n_lin, :n_lin], gdop=gdop, solver_status=solver_status,
        status=status, chi2=chi2, chi2_p=chi2_p, dof=dof, n_used=n_used, n_sats=n_sats, iterations=iterations,
        block=block, z_hz=z, sigma_hz=sigma, residuals_hz=residuals, used=used,
        rover_only_sats=tuple(np.setdiff1d(rover.sat_id, base.sat_id).tolist()),
        base_only_sats=tuple(np.setdiff1d(base.sat_id, rover.sat_id).tolist()), n_unmatched_rows=n_unmatched)
