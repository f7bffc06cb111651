"""Doppler least squares: snapshot fixes ([Shen 2024] eq. 4-12) and static batch fixes.

Measurement model (the toolkit's Doppler sign, see :mod:`leosop`)::

    doppler_hz = -(f0 / c) * (v_s - v_r) . (r_s - r_r) / |r_s - r_r| + clock terms

Snapshot
    one epoch, state ``[x, y, z, vx, vy, vz, T_u]`` (ECEF m, m/s, receiver
    frequency offset Hz), at least 7 satellites. :func:`solve_snapshots`
    solves many epochs at once, each independently. Rows of several
    constellations (``clock_group``) get one ``T_u`` per constellation:
    ``6 + k`` states and measurements for k constellations.
Static
    a receiver at rest in ECEF observed over many epochs, state
    ``[x, y, z, b0, b1, ...]``: frequency offset ``b0`` [Hz] at the reference
    time, its drift ``b1`` [Hz/s] and optionally higher polynomial terms;
    optionally a known ellipsoidal height as a pseudo-measurement (the
    classic Argos-style fix). A single pass has two solutions, mirror images
    across the ground track; both are returned.

Both run one Levenberg-Marquardt iteration (Gauss-Newton eq. 11-12 with
Marquardt damping on the Jacobi-scaled normal equations, so that a start
1,000 km away converges) batched over independent problems, with an
iteration cap and per-state step thresholds. Measurements are weighted by
``1 / sigma_hz**2``; the covariance is ``(H^T W H)^-1`` at the solution.

Outliers: when the weighted residual sum fails the chi-square test at
significance ``alpha``, the measurement with the largest standardised
residual (Baarda's w-test statistic) is excluded and the problem re-solved,
one measurement at a time, while at least two redundant measurements remain.
Failures come back as data in ``status`` (:class:`FixStatus`).
"""

from dataclasses import dataclass
from enum import IntEnum
from math import comb

import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm as norm_dist

from ..frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef
from ..geometry.dop import cofactor
from ..geometry.doppler import N_DOPPLER_STATES, doppler_jacobian, doppler_rate

__all__ = ["FixStatus", "SnapshotFixes", "StaticFix", "PassesFix", "solve_snapshots", "solve_static",
           "solve_static_passes", "subpoint_centroid_ecef_m", "N_STATIC_STATES",
           "TIME_OFFSET_SIGMA_S", "SAT_OFFSET_SIGMA_HZ"]

#: States of a static batch fix with a linear clock: position, frequency offset, frequency drift.
N_STATIC_STATES = 5
#: Step thresholds of convergence, per state: 0.1 mm, 1 um/s, 10 uHz (0.1 uHz/s; static
#: higher clock terms 0.1 uHz/s divided by powers of the half span).
_XTOL_SNAPSHOT = np.array([1e-4] * 3 + [1e-6] * 3 + [1e-5])
_XTOL_STATIC = np.array([1e-4] * 3 + [1e-5, 1e-7])
#: Cross-track offsets of the default static starts, in units of ``start_offset_m``.
_START_FRACTIONS = np.array([0.0, 1 / 6, -1 / 6, 1 / 3, -1 / 3, 0.6, -0.6, 1.0, -1.0])
#: Earth radius used to place a start on the ground [m].
_R_GROUND_M = 6_371_000.0
#: Default prior standard deviation of a pass's time offset of its satellite states [s]: an element
#: set's along-track error of a few hundred metres to a few km at ~7.5 km/s.
TIME_OFFSET_SIGMA_S = 0.5
#: Default prior standard deviation of a satellite's own frequency offset, clock "common" [Hz]
#: (Starlink: 0-5 Hz, [Shen 2024] Table 1).
SAT_OFFSET_SIGMA_HZ = 5.0
#: Multi-pass fixes also stop when a step is below this fraction of the posterior sigma along it.
_STEP_SIGMA_TOL = 1e-3


class FixStatus(IntEnum):
    """Outcome of one fix."""

    OK = 0
    #: The iteration cap was reached before the step fell below the thresholds.
    NOT_CONVERGED = 1
    #: The geometry cannot determine the state: ``H^T W H`` is rank deficient.
    SINGULAR = 2
    #: Fewer measurements than states.
    TOO_FEW = 3
    #: Residuals fail the chi-square test and no single outlier can be isolated.
    INCONSISTENT = 4


@dataclass(frozen=True)
class SnapshotFixes:
    """Snapshot fixes of ``n_ep`` epochs with up to ``n_sv`` satellites each.

    Attributes
    ----------
    pos_ecef_m, vel_ecef_mps : ndarray, (n_ep, 3)
    clock_offset_hz : ndarray, (n_ep,)
        Receiver frequency offset ``T_u`` (several clocks: that of the first
        clock present at the epoch, in the order of ``clock_labels``).
    cov : ndarray, (n_ep, 6 + k, 6 + k)
        Posterior covariance of ``[pos, vel, T_u...]`` from the given sigmas
        (k = 1 without clock groups); NaN rows and columns for a clock absent
        at the epoch.
    gdop, pos_dop, vel_dop : ndarray, (n_ep,)
        Eq. 10 ``sqrt(trace((H^T H)^-1))`` over the used satellites, and the
        square roots of the position and velocity blocks of that trace. The
        trace covers position [m^2/Hz^2], velocity [(m/s)^2/Hz^2] and every
        clock present at the epoch [Hz^2/Hz^2, i.e. 1] with unit weights, as
        eq. 10 adds them: one number of mixed units, so a mixed set's GDOP
        counts one clock term per constellation.
    residuals_hz : ndarray, (n_ep, n_sv)
        Measured minus modelled Doppler at the solution; NaN where masked.
    used : ndarray of bool, (n_ep, n_sv)
        Measurements in the solution (mask minus excluded outliers).
    n_used, iterations : ndarray of int, (n_ep,)
    chi2 : ndarray, (n_ep,)
        Weighted residual sum of squares.
    status : ndarray of int, (n_ep,)
        :class:`FixStatus` values; states are NaN unless OK or INCONSISTENT.
    clock_offsets_hz : ndarray, (n_ep, k)
        Each receiver clock's frequency offset, NaN where absent.
    clock_labels : tuple, (k,)
        The ``clock_group`` value of each clock; ``()`` without groups.
    """

    pos_ecef_m: np.ndarray
    vel_ecef_mps: np.ndarray
    clock_offset_hz: np.ndarray
    cov: np.ndarray
    gdop: np.ndarray
    pos_dop: np.ndarray
    vel_dop: np.ndarray
    residuals_hz: np.ndarray
    used: np.ndarray
    n_used: np.ndarray
    iterations: np.ndarray
    chi2: np.ndarray
    status: np.ndarray
    clock_offsets_hz: np.ndarray = None
    clock_labels: tuple = ()

    @property
    def residual_rms_hz(self):
        """RMS of the used residuals per epoch, ndarray (n_ep,)."""
        r2 = np.where(self.used, np.nan_to_num(self.residuals_hz) ** 2, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(r2.sum(-1) / self.n_used)


@dataclass(frozen=True)
class StaticFix:
    """Batch fix of a receiver at rest.

    Attributes
    ----------
    pos_ecef_m : ndarray, (3,)
    clock_offset_hz, clock_drift_hz_per_s : float
        Frequency offset at ``t_ref_s`` and its rate.
    t_ref_s : float
    cov : ndarray, (4 + d, 4 + d)
        Posterior covariance of ``[pos, clock polynomial]`` (d the clock
        degree; 5 x 5 for offset and drift).
    gdop : float
        ``sqrt(trace((H^T H)^-1))`` of the states over the used Doppler rows
        (the height constraint enters with its weight relative to the median
        Doppler weight).
    residuals_hz : ndarray, (m,)
    used : ndarray of bool, (m,)
    n_used, iterations : int
    chi2 : float
    status : FixStatus
    ambiguous : bool
        Another start reached a different solution (beyond ``ambiguity_m``)
        that fits the data as well: typically the mirror image across the
        ground track of a single pass.
    clock_poly_hz : ndarray, (d + 1,)
        Frequency offset polynomial in ``t - t_ref`` [Hz/s^k], lowest first
        (``clock_offset_hz``, ``clock_drift_hz_per_s``, ...).
    mirror_pos_ecef_m : ndarray, (3,)
        The best solution further than ``ambiguity_m`` from ``pos_ecef_m``
        (with a single pass: the other side of the ground track), refined like
        the fix; NaN when no start reached one.
    mirror_chi2 : float
        Its weighted residual sum over the rows the fix used: compare with
        ``chi2``.
    clock_polys_hz : ndarray, (k, d + 1)
        Each receiver clock's polynomial (k clock groups; row 0 is
        ``clock_poly_hz``); the covariance is of ``[pos, clock 0 terms,
        clock 1 terms, ...]``.
    clock_labels : tuple, (k,)
        The ``clock_group`` value of each clock; ``()`` without groups.
    """

    pos_ecef_m: np.ndarray
    clock_offset_hz: float
    clock_drift_hz_per_s: float
    t_ref_s: float
    cov: np.ndarray
    gdop: float
    residuals_hz: np.ndarray
    used: np.ndarray
    n_used: int
    iterations: int
    chi2: float
    status: FixStatus
    ambiguous: bool = False
    clock_poly_hz: np.ndarray = None
    mirror_pos_ecef_m: np.ndarray = None
    mirror_chi2: float = np.nan
    clock_polys_hz: np.ndarray = None
    clock_labels: tuple = ()

    @property
    def residual_rms_hz(self):
        """RMS of the used residuals [Hz]."""
        return float(np.sqrt(np.mean(self.residuals_hz[self.used] ** 2))) if self.n_used else np.nan


def _levenberg_marquardt(model, x0, y, w, xtol, max_iter, step_sigma_tol=None):
    """Damped Gauss-Newton over independent problems.

    ``model(x, idx, w)`` gives predictions (k, m) and Jacobians (k, m, n) of
    the problems ``idx`` at states ``x`` (k, n) with row weights ``w`` (k, m)
    (a model that eliminates linear states needs them); ``y``, ``w`` (P, m)
    are the measurements and weights (0 drops a row). A problem has
    converged when its step is below ``xtol`` (n,) in every state, or, with
    ``step_sigma_tol``, when an accepted step's length in units of the
    posterior sigma, ``sqrt(dx^T J^T W J dx)``, is below it (a weakly
    determined direction then needs no sub-millimetre steps). Returns ``x,
    iterations, converged``.
    """
    n_prob, n = x0.shape
    x = x0.copy()
    pred, J = model(x, np.arange(n_prob), w)
    r = np.where(w > 0, y - pred, 0.0)
    cost = np.einsum("pm,pm->p", w, r * r)
    lam = np.full(n_prob, 1e-3)
    iterations = np.zeros(n_prob, dtype=int)
    converged = np.zeros(n_prob, dtype=bool)
    active = np.flatnonzero(np.isfinite(cost))
    eye = np.eye(n)
    for _ in range(max_iter):
        if active.size == 0:
            break
        Ja, wa, ra = J[active], w[active], r[active]
        N = np.einsum("pmi,pm,pmj->pij", Ja, wa, Ja)
        g = np.einsum("pmi,pm->pi", Ja, wa * ra)
        d = np.sqrt(np.diagonal(N, axis1=-2, axis2=-1))
        d = np.where(d > 0, d, 1.0)
        Ns = N / (d[:, :, None] * d[:, None, :]) + lam[active, None, None] * eye
        dx = np.linalg.solve(Ns, (g / d)[..., None])[..., 0] / d
        xt = x[active] + dx
        pt, Jt = model(xt, active, wa)
        rt = np.where(wa > 0, y[active] - pt, 0.0)
        ct = np.einsum("pm,pm->p", wa, rt * rt)
        accept = np.isfinite(ct) & (ct <= cost[active])
        acc = active[accept]
        x[acc], J[acc], r[acc], cost[acc] = xt[accept], Jt[accept], rt[accept], ct[accept]
        lam[active] = np.where(accept, np.maximum(lam[active] / 10, 1e-12), np.minimum(lam[active] * 10, 1e12))
        iterations[active] += 1
        done = np.all(np.abs(dx) <= xtol, axis=-1)
        if step_sigma_tol is not None:
            done |= accept & (np.einsum("pi,pij,pj->p", dx, N, dx) <= step_sigma_tol**2)
        converged[active[done]] = True
        active = active[~done]
    return x, iterations, converged


def _group_argmax(values, groups):
    """Index of the largest of ``values`` (k, m) within each group of ``groups`` (m,), -1 for an empty group.

    Rows of group -1 belong to none. Returns (k, n_groups).
    """
    n_groups = int(groups.max()) + 1 if groups.size else 0
    out = np.full((values.shape[0], n_groups), -1)
    for g in range(n_groups):
        rows = np.flatnonzero(groups == g)
        if rows.size:
            best = rows[np.argmax(values[:, rows], axis=-1)]
            out[:, g] = np.where(np.isfinite(values[np.arange(len(values)), best]), best, -1)
    return out


def _solve_robust(model, x0, y, sigma, used, n_states, *, xtol, max_iter, alpha, fixed=None, x_alt=None,
                  groups=None, step_sigma_tol=None):
    """LM, then chi-square test and w-test exclusions one at a time.

    Returns ``x, residuals, J, Q (weighted cofactor), used, iterations, chi2,
    status``; rows in ``fixed`` (bool, (m,)) are never excluded. Problems
    that do not converge or fail the test from ``x0`` are retried once from
    ``x_alt`` (P, n) and keep the better solution. With ``groups`` (int,
    (m,), e.g. the pass of each row) each round excludes the largest
    standardised residual of every group whose largest one exceeds the
    two-sided normal critical value at ``alpha`` (one row per pass at a time
    instead of one in all), and stops when none does. ``step_sigma_tol``: see
    :func:`_levenberg_marquardt`.
    """
    n_prob = x0.shape[0]
    used = used.copy()
    fixed = np.zeros(y.shape[-1], dtype=bool) if fixed is None else fixed
    w_all = 1.0 / sigma**2
    n_rows = used.sum(-1)
    status = np.where(n_rows < n_states, FixStatus.TOO_FEW, FixStatus.OK).astype(int)
    todo = np.flatnonzero(status == FixStatus.OK)
    x = x0.copy()
    iterations = np.zeros(n_prob, dtype=int)
    converged = np.zeros(n_prob, dtype=bool)
    first = True
    while todo.size:
        sub = lambda xs, i, w_, todo=todo: model(xs, todo[i], w_)  # noqa: E731
        w = np.where(used[todo], w_all[todo], 0.0)
        xs, it, conv = _levenberg_marquardt(sub, x[todo], y[todo], w, xtol, max_iter, step_sigma_tol)
        iterations[todo] += it
        pred, J = model(xs, todo, w)
        r = np.where(used[todo], y[todo] - pred, 0.0)
        chi2 = np.einsum("pm,pm->p", w, r * r)
        dof = used[todo].sum(-1) - n_states
        if first and x_alt is not None:
            # A start far away can end in a local minimum: retry those that fail the test from x_alt.
            with np.errstate(invalid="ignore"):
                retry = ~conv | (chi2 > chi2_dist.isf(alpha or 1e-3, np.maximum(dof, 1)))
            if retry.any():
                k = np.flatnonzero(retry)
                sub2 = lambda xs, i, w_, p=todo[k]: model(xs, p[i], w_)  # noqa: E731
                xs2, it2, conv2 = _levenberg_marquardt(sub2, x_alt[todo[k]], y[todo[k]], w[k], xtol,
                                                                 max_iter, step_sigma_tol)
                iterations[todo[k]] += it2
                pred2, J2 = model(xs2, todo[k], w[k])
                r2 = np.where(used[todo[k]], y[todo[k]] - pred2, 0.0)
                chi2_2 = np.einsum("pm,pm->p", w[k], r2 * r2)
                better = conv2 & (~conv[k] | (chi2_2 < chi2[k]))
                kb = k[better]
                xs[kb], conv[kb], pred[kb], J[kb], r[kb], chi2[kb] = (
                    xs2[better], True, pred2[better], J2[better], r2[better], chi2_2[better])
        first = False
        x[todo], converged[todo] = xs, conv
        if alpha is None:
            break
        Q = cofactor(J, w)
        ok = conv & np.isfinite(Q[:, 0, 0])
        with np.errstate(invalid="ignore"):
            fail = ok & (dof >= 1) & (chi2 > chi2_dist.isf(alpha, np.maximum(dof, 1)))
        can = fail & (dof >= 2)
        if not can.any():
            break
        p, Jp, Qp = todo[can], J[can], Q[can]
        var_r = sigma[p] ** 2 - np.einsum("pmi,pij,pmj->pm", Jp, Qp, Jp)
        wstat = np.abs(r[can]) / np.sqrt(np.maximum(var_r, 1e-12 * sigma[p] ** 2))
        wstat = np.where(used[p] & ~fixed, wstat, -np.inf)
        if groups is None:
            used[p, np.argmax(wstat, axis=-1)] = False
        else:
            worst = _group_argmax(wstat, groups)
            take = np.take_along_axis(wstat, np.maximum(worst, 0), -1) > norm_dist.isf(alpha / 2)
            pi, gi = np.nonzero(take & (worst >= 0))
            used[p[pi], worst[pi, gi]] = False
            p = p[take.any(-1)]
        todo = p
    w = np.where(used, w_all, 0.0)
    pred, J = model(x, np.arange(n_prob), w)
    residuals = np.where(used, y - pred, np.nan)
    chi2 = np.einsum("pm,pm->p", w, np.nan_to_num(residuals) ** 2)
    Q = cofactor(J, w)
    run = status == FixStatus.OK
    status[run & ~converged] = FixStatus.NOT_CONVERGED
    status[run & converged & ~np.isfinite(Q[:, 0, 0])] = FixStatus.SINGULAR
    if alpha is not None:
        dof = used.sum(-1) - n_states
        with np.errstate(invalid="ignore"):
            bad = (dof >= 1) & (chi2 > chi2_dist.isf(alpha, np.maximum(dof, 1)))
        status[(status == FixStatus.OK) & bad] = FixStatus.INCONSISTENT
    return x, residuals, J, Q, used, iterations, chi2, status


def subpoint_centroid_ecef_m(pos_sv_ecef_m, mask=None):
    """Ground point below the mean direction of the satellites, a start for the solvers.

    Parameters
    ----------
    pos_sv_ecef_m : array_like, (..., n_sv, 3)
    mask : array_like of bool, (..., n_sv), optional

    Returns
    -------
    pos_ecef_m : ndarray, (..., 3)
        On the ellipsoid (height 0); NaN where no satellite is unmasked.
    """
    r = np.asarray(pos_sv_ecef_m, dtype=float)
    m = np.isfinite(r).all(-1) if mask is None else np.asarray(mask, bool) & np.isfinite(r).all(-1)
    u = np.where(m[..., None], r / np.linalg.norm(np.where(m[..., None], r, 1.0), axis=-1, keepdims=True), 0.0)
    with np.errstate(invalid="ignore"):
        mean = u.sum(-2) / np.linalg.norm(u.sum(-2), axis=-1, keepdims=True)
    lat, lon, _ = ecef_to_geodetic(np.nan_to_num(mean, nan=1.0) * _R_GROUND_M)
    pos = geodetic_to_ecef(lat, lon, 0.0)
    return np.where(m.any(-1)[..., None], pos, np.nan)


def solve_snapshots(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, mask=None, x0=None, *,
                    max_iter=50, alpha=1e-3, clock_group=None):
    """Snapshot Doppler fixes of many epochs at once ([Shen 2024] eq. 4-12).

    Parameters
    ----------
    doppler_hz : array_like, (n_ep, n_sv)
    sigma_hz : float or array_like, broadcastable to (n_ep, n_sv)
        Standard deviation of each measurement.
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (n_ep, n_sv, 3)
        Satellite states (at transmit time, in the ECEF frame of reception).
    carrier_hz : float or array_like, broadcastable to (n_ep, n_sv)
    mask : array_like of bool, (n_ep, n_sv), optional
        False drops a measurement (padding, below the mask, ...); non-finite
        inputs are dropped too.
    x0 : array_like, (n_ep, 6 + k) or (6 + k,), optional
        Start ``[pos, vel, T_u...]`` (k receiver clocks; a 7-column start
        gives every clock its offset); default the ground point below the
        satellites' mean direction, at rest, no offset.
    max_iter : int
        Iteration cap of each solve.
    alpha : float or None
        Significance of the chi-square outlier test; None disables it.
    clock_group : array_like of int, broadcastable to (n_ep, n_sv), optional
        Receiver clock of each measurement (e.g. its constellation): each
        distinct value among the unmasked rows gets its own frequency offset
        state ``T_u[g]`` (the k clocks sorted by value). An epoch estimates
        ``6 + k_e`` states, ``k_e`` the clocks present among its rows, and
        needs as many measurements; an absent clock's state is held at its
        start by a pseudo-row that is never excluded (outlier tests, degrees
        of freedom and GDOP are those of the ``6 + k_e`` states). None: one
        clock ([Shen 2024]'s 7 states).

    Returns
    -------
    SnapshotFixes
    """
    y = np.atleast_2d(np.asarray(doppler_hz, dtype=float))
    n_ep, n_sv = y.shape
    r_s = np.asarray(pos_sv_ecef_m, dtype=float).reshape(n_ep, n_sv, 3)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(n_ep, n_sv, 3)
    sigma = np.broadcast_to(np.asarray(sigma_hz, dtype=float), y.shape)
    f0 = np.broadcast_to(np.asarray(carrier_hz, dtype=float), y.shape)
    m = np.ones(y.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), y.shape)
    m = m & np.isfinite(y) & np.isfinite(r_s).all(-1) & np.isfinite(v_s).all(-1) & (sigma > 0) & (f0 > 0)
    # Finite placeholders where masked, so that nothing NaN enters the algebra.
    y = np.where(m, y, 0.0)
    sigma = np.where(m, sigma, 1.0)
    f0 = np.where(m, f0, 1.0)
    r_s = np.where(m[..., None], r_s, [2e7, 0.0, 0.0])
    v_s = np.where(m[..., None], v_s, 0.0)
    # Receiver clocks: one offset state per distinct group among the unmasked rows.
    groups = np.zeros(y.shape, int) if clock_group is None else np.broadcast_to(np.asarray(clock_group), y.shape)
    clock_labels, g_idx = np.unique(groups[m], return_inverse=True)
    n_clk = max(len(clock_labels), 1)
    n_states = 6 + n_clk
    gi = np.zeros(y.shape, int)
    gi[m] = g_idx.ravel()
    onehot = (gi[..., None] == np.arange(n_clk)) & m[..., None]
    present = onehot.any(-2) if n_clk > 1 else np.ones((n_ep, 1), bool)
    x_ground = np.zeros((n_ep, n_states))
    x_ground[:, :3] = np.nan_to_num(subpoint_centroid_ecef_m(r_s, m), nan=_R_GROUND_M)
    if x0 is None:
        x0 = x_ground
    else:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape[-1] == N_DOPPLER_STATES and n_clk > 1:
            x0 = np.concatenate([x0[..., :6], np.repeat(x0[..., 6:], n_clk, -1)], -1)
        x0 = np.broadcast_to(x0, (n_ep, n_states)).copy()
    fixed = None
    if n_clk > 1:
        # Pseudo-rows "clock g = start" for the clocks absent at an epoch (measured 0, weight 1, never excluded).
        x0[:, 6:] = np.where(present, x0[:, 6:], 0.0)
        y = np.concatenate([y, np.zeros((n_ep, n_clk))], -1)
        sigma = np.concatenate([sigma, np.ones((n_ep, n_clk))], -1)
        m = np.concatenate([m, ~present], -1)
        fixed = np.arange(n_sv + n_clk) >= n_sv
        pseudo = np.eye(n_states)[6:]
        clk_cols = onehot.astype(float)

    def model(x, idx, w):
        H = doppler_jacobian(r_s[idx], v_s[idx], x[:, :3], x[:, 3:6], f0[idx])
        pred = np.einsum("pmi,pmi->pm", H[..., 3:6], x[:, None, 3:6] - v_s[idx])
        if n_clk == 1:
            return pred + x[:, 6:7], H
        pred = np.concatenate([pred + np.einsum("pmk,pk->pm", clk_cols[idx], x[:, 6:]), x[:, 6:]], -1)
        J = np.concatenate([np.concatenate([H[..., :6], clk_cols[idx]], -1),
                            np.broadcast_to(pseudo, (len(x),) + pseudo.shape)], 1)
        return pred, J

    x, res, H, Q, used, iterations, chi2, status = _solve_robust(
        model, x0, y, sigma, m, n_states, xtol=_xtol_snapshot(n_clk), max_iter=max_iter, alpha=alpha,
        x_alt=x_ground, fixed=fixed)
    good = (status == FixStatus.OK) | (status == FixStatus.INCONSISTENT)
    x[~good] = np.nan
    Q[~good] = np.nan
    Q0 = cofactor(H, used)
    d0 = np.diagonal(Q0, axis1=-2, axis2=-1)
    clocks = x[:, 6:]
    if n_clk > 1:
        # Absent clocks are no states of their epoch: no offset, no covariance, outside the GDOP's trace.
        keep = np.concatenate([np.ones((n_ep, 6), bool), present], -1)
        Q = np.where(keep[:, :, None] & keep[:, None, :], Q, np.nan)
        d0 = np.where(keep, d0, 0.0)
        clocks = np.where(present, clocks, np.nan)
        res, used = res[:, :n_sv], used[:, :n_sv]
    with np.errstate(invalid="ignore"):
        gdop = np.sqrt(d0.sum(-1))
        pos_dop, vel_dop = np.sqrt(d0[:, :3].sum(-1)), np.sqrt(d0[:, 3:6].sum(-1))
    first = np.argmax(present, axis=-1)
    return SnapshotFixes(
        pos_ecef_m=x[:, :3], vel_ecef_mps=x[:, 3:6], clock_offset_hz=clocks[np.arange(n_ep), first], cov=Q,
        gdop=gdop, pos_dop=pos_dop, vel_dop=vel_dop, residuals_hz=res, used=used,
        n_used=used.sum(-1), iterations=iterations, chi2=chi2, status=status, clock_offsets_hz=clocks,
        clock_labels=tuple(clock_labels.tolist()) if clock_group is not None else (),
    )


def _xtol_snapshot(n_clk):
    """Step thresholds of a snapshot state with ``n_clk`` receiver clocks."""
    return _XTOL_SNAPSHOT if n_clk == 1 else np.concatenate([_XTOL_SNAPSHOT, np.repeat(_XTOL_SNAPSHOT[6:], n_clk - 1)])


def _starts(pos_sv_ecef_m, vel_sv_ecef_mps, pos0_ecef_m, offsets_m):
    """Starts of a static solve across the mean ground track.

    Without ``pos0_ecef_m``: ground points at ``offsets_m`` across the track
    from the sub-point centroid; with it: ``pos0_ecef_m`` and its reflection.
    """
    centre = subpoint_centroid_ecef_m(pos_sv_ecef_m)
    lat, lon, _ = ecef_to_geodetic(centre)
    C = C_e_n(lat, lon)
    v_enu = np.mean(vel_sv_ecef_mps, axis=0) @ C
    track = np.array([v_enu[0], v_enu[1], 0.0])
    across = C @ np.cross([0.0, 0.0, 1.0], track / np.linalg.norm(track))
    if pos0_ecef_m is not None:
        p0 = np.asarray(pos0_ecef_m, dtype=float).reshape(3)
        return np.array([p0, p0 - 2.0 * ((p0 - centre) @ across) * across])
    la, lo, _ = ecef_to_geodetic(centre + np.multiply.outer(offsets_m, across))
    return geodetic_to_ecef(la, lo, 0.0)


def solve_static(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, *, pos0_ecef_m=None,
                 alt_m=None, alt_sigma_m=10.0, mask=None, max_iter=200, alpha=1e-3, start_offset_m=1.5e6,
                 ambiguity_m=10e3, clock_degree=1, side_clock_degree=None, clock_group=None):
    """Batch Doppler fix of a receiver at rest in ECEF.

    The frequency offset is a polynomial of degree ``clock_degree`` in
    ``t - t_ref``. The solve runs in two stages: every start is solved with a
    polynomial of degree ``side_clock_degree`` and the solutions compete on
    chi-square; the winner (and the best solution beyond ``ambiguity_m`` from
    it, the mirror) is then refined with ``clock_degree``. Choosing
    the side with a low degree keeps the small asymmetry between a pass's two
    mirror solutions (the Earth turns under the pass) from being absorbed by
    the higher clock terms; the refinement then absorbs a transmitter drift
    that is not linear (DopTrack: thermal, ~0.1-1 mHz/s^2).

    Parameters
    ----------
    doppler_hz, sigma_hz, carrier_hz, t_s : array_like, (m,)
        Measurements, their standard deviations, carriers and times [s].
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (m, 3)
    pos0_ecef_m : array_like, (3,), optional
        Start position. A single pass has a mirror solution on the other
        side of the ground track, so the solve also starts from the mirror
        image of ``pos0_ecef_m`` across the mean ground track; of the
        solutions that fit equally well (chi-square within 3 standard
        deviations of the best) the one nearest ``pos0_ecef_m`` is kept.
        Default: the ground point below the satellites' mean direction and
        points 1/6, 1/3, 0.6 and 1 times ``start_offset_m`` either side of it
        across the track (a pass's cost has local minima between its mirror
        solutions); the lowest chi-square wins.
    alt_m : float, optional
        Known height above the ellipsoid, added as a pseudo-measurement with
        standard deviation ``alt_sigma_m``.
    mask : array_like of bool, (m,), optional
    max_iter : int
    alpha : float or None
        Significance of the chi-square outlier test; None disables it.
    start_offset_m : float
    ambiguity_m : float
        Equally good solutions further apart than this flag the fix ``ambiguous``.
    clock_degree : int or sequence of int
        Degree of the frequency-offset polynomial (1: offset and drift), or
        candidate degrees: each refines the chosen solution and its mirror,
        and the lowest Bayesian information criterion
        ``chi2 + n_states * ln(n_used)`` wins (degrees that leave the
        states undetermined, e.g. a cubic over three epochs, drop out).
    side_clock_degree : int, optional
        Degree used to choose among the starts; default the lowest of
        ``clock_degree``.
    clock_group : array_like of int, (m,), optional
        Receiver clock of each row (e.g. its constellation): each distinct
        value among the unmasked rows gets its own polynomial (offset and
        drift at degree 1), so the state has ``3 + k (d + 1)`` terms for k
        clocks. None: one clock.

    Returns
    -------
    StaticFix
    """
    degrees = sorted({int(d) for d in np.atleast_1d(clock_degree)})
    deg_side = degrees[0] if side_clock_degree is None else int(side_clock_degree)
    if degrees[0] < 0 or deg_side < 0:
        raise ValueError("clock degrees must be non-negative")
    deg = deg_side
    y = np.asarray(doppler_hz, dtype=float).ravel()
    n_rows = y.size
    r_s = np.asarray(pos_sv_ecef_m, dtype=float).reshape(n_rows, 3)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(n_rows, 3)
    sigma = np.broadcast_to(np.asarray(sigma_hz, dtype=float), y.shape)
    f0 = np.broadcast_to(np.asarray(carrier_hz, dtype=float), y.shape)
    t = np.asarray(t_s, dtype=float).ravel()
    m = np.ones(n_rows, bool) if mask is None else np.asarray(mask, bool).ravel()
    m = m & np.isfinite(y) & np.isfinite(r_s).all(-1) & np.isfinite(v_s).all(-1) & (sigma > 0) & (f0 > 0)
    m &= np.isfinite(t)
    y, sigma, f0, t = (np.where(m, a, fill) for a, fill in ((y, 0.0), (sigma, 1.0), (f0, 1.0), (t, 0.0)))
    r_s = np.where(m[:, None], r_s, [2e7, 0.0, 0.0])
    v_s = np.where(m[:, None], v_s, 0.0)
    t_ref = 0.5 * (t[m].min() + t[m].max()) if m.any() else 0.0
    dt = t - t_ref
    half_span_s = max(0.5 * np.ptp(t[m]) if m.any() else 0.0, 1.0)
    groups = np.zeros(n_rows, int) if clock_group is None else np.broadcast_to(np.asarray(clock_group), (n_rows,))
    clock_labels, g_idx = np.unique(groups[m], return_inverse=True)
    n_clk = max(len(clock_labels), 1)
    gi = np.zeros(n_rows, int)
    gi[m] = g_idx.ravel()
    onehot = (gi[:, None] == np.arange(n_clk)).astype(float)
    has_alt = alt_m is not None
    if has_alt:
        y = np.append(y, alt_m)
        sigma = np.append(sigma, alt_sigma_m)
        m = np.append(m, True)
    fixed = np.zeros(y.size, bool)
    fixed[n_rows:] = True

    def make_model(degree):
        powers = dt[:, None] ** np.arange(degree + 1)
        if n_clk > 1:
            # Each clock's polynomial on its own rows: columns [clock 0 terms, clock 1 terms, ...].
            powers = (onehot[:, :, None] * powers[:, None, :]).reshape(n_rows, n_clk * (degree + 1))
        n_poly = powers.shape[1]

        def model(x, idx, w):
            H = doppler_jacobian(r_s, v_s, x[:, :3], np.zeros((len(x), 3)), f0)
            pred = np.einsum("pmi,mi->pm", H[..., 3:6], -v_s) + x[:, 3:] @ powers.T
            J = np.concatenate([H[..., :3], np.broadcast_to(powers, pred.shape + (n_poly,))], axis=-1)
            if has_alt:
                lat, lon, h = ecef_to_geodetic(x[:, :3])
                up = C_e_n(lat, lon)[..., 2]
                pred = np.concatenate([pred, h[:, None]], axis=-1)
                J = np.concatenate([J, np.concatenate([up, np.zeros((len(x), n_poly))], -1)[:, None, :]], axis=1)
            return pred, J

        xtol = np.concatenate([_XTOL_STATIC[:4], _XTOL_STATIC[4] / half_span_s ** np.arange(degree)])[:degree + 4]
        xtol = np.concatenate([xtol[:3], np.tile(xtol[3:], n_clk)])
        return model, xtol, 3 + n_poly

    def solve(degree, x0, alpha_):
        model, xtol, n_states = make_model(degree)
        k = len(x0)
        ys, ss, ms = (np.broadcast_to(a, (k, y.size)) for a in (y, sigma, m))
        return _solve_robust(model, x0, ys, ss, ms, n_states, xtol=xtol, max_iter=max_iter, alpha=alpha_,
                             fixed=fixed)

    if m[:n_rows].any():
        starts = _starts(r_s[m[:n_rows]], v_s[m[:n_rows]], pos0_ecef_m, start_offset_m * _START_FRACTIONS)
    else:
        starts = np.zeros((1, 3)) if pos0_ecef_m is None else np.reshape(pos0_ecef_m, (1, 3))
    x0 = np.zeros((len(starts), 3 + n_clk * (1 + deg_side)))
    x0[:, :3] = starts
    # Choose among the starts' solutions on the same rows (before any exclusion), then clean outliers.
    x, res, J, Q, used, iterations, chi2, status = solve(deg_side, x0, None)
    solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    cost = np.where(solved, chi2, np.inf)
    best = int(np.argmin(cost))
    # Solutions whose chi-square is within 3 standard deviations of the best one fit the data
    # equally well (a single pass's mirror image): the start given decides between them.
    dof = max(int(used[best].sum()) - 3 - n_clk * (1 + deg_side), 1)
    fits = solved & (cost <= cost[best] + 3.0 * np.sqrt(2.0 * dof))
    if pos0_ecef_m is not None and fits.sum() > 1:
        best = int(np.argmin(np.where(fits, np.linalg.norm(x[:, :3] - starts[0], axis=-1), np.inf)))
    apart = solved & (np.linalg.norm(x[:, :3] - x[best, :3], axis=-1) > ambiguity_m)
    ambiguous = bool((fits & apart).any())
    other = int(np.argmin(np.where(apart, cost, np.inf))) if apart.any() else None
    pair = [best] + ([other] if other is not None else [])
    if degrees != [deg_side]:
        # Refine the pair with each candidate degree; the Bayesian information criterion picks one.
        refined = []
        for degree in degrees:
            x1 = np.zeros((len(pair), 3 + n_clk * (1 + degree)))
            x1[:, :3] = x[pair, :3]
            low = min(degree, deg_side) + 1
            x1[:, 3:].reshape(len(pair), n_clk, 1 + degree)[..., :low] = \
                x[pair, 3:].reshape(len(pair), n_clk, 1 + deg_side)[..., :low]
            out = solve(degree, x1, None)
            if out[-1][0] in (FixStatus.OK, FixStatus.INCONSISTENT):
                n_st = 3 + n_clk * (1 + degree)
                refined.append((out[6][0] + n_st * np.log(max(out[4][0].sum(), 1)), degree, out))
        if refined:
            _, deg, (x, res, J, Q, used, it, chi2, status) = min(refined, key=lambda r: r[0])
            iterations = iterations[pair] + it
            pair = list(range(len(pair)))
            best = 0
            solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
        else:
            deg = deg_side
    x_mirror = x[pair[1]:pair[1] + 1].copy() if other is not None and solved[pair[1]] else None
    if alpha is not None and solved[best]:
        x, res, J, Q, used, it, chi2, status = solve(deg, x[best:best + 1], alpha)
        iterations = iterations[best:best + 1] + it
        best = 0
        solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    mirror_pos, mirror_chi2 = np.full(3, np.nan), np.nan
    if x_mirror is not None and solved[best]:
        # The mirror on the rows the fix kept, so that the two chi-squares compare.
        model, xtol, n_states = make_model(deg)
        xm, _, _, _, _, _, chi2_m, status_m = _solve_robust(
            model, x_mirror, y[None], sigma[None], used[best:best + 1], n_states, xtol=xtol, max_iter=max_iter,
            alpha=None)
        if status_m[0] in (FixStatus.OK, FixStatus.INCONSISTENT):
            mirror_pos, mirror_chi2 = xm[0, :3], float(chi2_m[0])
    w_rel = np.where(used[best], np.median(sigma[:n_rows][m[:n_rows]]) ** 2 / sigma**2, 0.0) if m[:n_rows].any() \
        else used[best].astype(float)
    gdop = float(np.sqrt(np.trace(cofactor(J[best], w_rel))))
    n_states = 3 + n_clk * (1 + deg)
    xb = x[best] if solved[best] else np.full(n_states, np.nan)
    polys = xb[3:].reshape(n_clk, 1 + deg)
    return StaticFix(
        pos_ecef_m=xb[:3], clock_offset_hz=float(xb[3]), clock_drift_hz_per_s=float(xb[4]) if deg >= 1 else 0.0,
        t_ref_s=float(t_ref), cov=Q[best] if solved[best] else np.full((n_states, n_states), np.nan), gdop=gdop,
        residuals_hz=res[best, :n_rows], used=used[best, :n_rows], n_used=int(used[best, :n_rows].sum()),
        iterations=int(iterations[best]), chi2=float(chi2[best]), status=FixStatus(int(status[best])),
        ambiguous=ambiguous, clock_poly_hz=polys[0].copy(), mirror_pos_ecef_m=mirror_pos, mirror_chi2=mirror_chi2,
        clock_polys_hz=polys.copy(), clock_labels=tuple(clock_labels.tolist()) if clock_group is not None else (),
    )


@dataclass(frozen=True)
class PassesFix:
    """Batch fix of a receiver at rest from several passes (satellites), each with its own frequency terms.

    Attributes
    ----------
    pos_ecef_m : ndarray, (3,)
    pass_ids : ndarray, (n_pass,)
        The passes solved (those with enough usable rows), in the order of
        the clock rows.
    t_ref_s : ndarray, (n_pass,)
        Mid-time of each pass, the origin of its polynomial.
    clock_poly_hz : ndarray, (n_pass, d + 1)
        Each pass's frequency offset polynomial in ``t - t_ref`` [Hz/s^k],
        lowest first (clock ``"common"``: the receiver's polynomial moved to
        the pass's ``t_ref`` plus the satellite's constant offset).
    cov : ndarray, (n_states, n_states)
        Posterior covariance of ``[pos, clock_poly_hz.ravel(), time_bias_s]``
        (clock ``"per_pass"``) or ``[pos, rx_clock_poly_hz, sat_offset_hz,
        time_bias_s]`` (clock ``"common"``); no ``time_bias_s`` states
        without time biases. Priors are included.
    gdop : float
        ``sqrt(trace((H^T W H)^-1))`` of the position with the clocks
        eliminated, weights relative to the median Doppler weight.
    residuals_hz : ndarray, (m,)
    used : ndarray of bool, (m,)
    n_used, iterations : int
    chi2 : float
        Weighted residual sum of the Doppler rows and the priors' pseudo-rows.
    status : FixStatus
    ambiguous : bool
        Another start reached a solution beyond ``ambiguity_m`` that fits as
        well (e.g. passes all on one side of the station).
    mirror_pos_ecef_m : ndarray, (3,)
        The best such solution, NaN when none; ``mirror_chi2`` its chi-square
        on the rows the fix used.
    mirror_chi2 : float
    time_bias_s : ndarray, (n_pass,), or None
        Each pass's time offset of the satellite states (first order: an
        along-track error of its element set) when modelled.
    clock : str
        ``"per_pass"`` or ``"common"``.
    rx_clock_poly_hz : ndarray, (d + 1,), or None
        Clock ``"common"``: the receiver's frequency offset polynomial in
        ``t - rx_t_ref_s`` [Hz/s^k].
    rx_t_ref_s : float
    sat_offset_hz : ndarray, (n_pass,), or None
        Clock ``"common"``: each satellite's constant frequency offset [Hz].
    rx_clock_polys_hz : ndarray, (k, d + 1), or None
        Clock ``"common"``: each receiver clock's polynomial (k clock
        groups, row 0 is ``rx_clock_poly_hz``); the covariance's receiver
        block is ``[clock 0 terms, clock 1 terms, ...]``.
    clock_labels : tuple, (k,)
        The ``clock_group`` value of each receiver clock; ``()`` without.
    pass_clock : ndarray of int, (n_pass,), or None
        Index of each pass's receiver clock.
    """

    pos_ecef_m: np.ndarray
    pass_ids: np.ndarray
    t_ref_s: np.ndarray
    clock_poly_hz: np.ndarray
    cov: np.ndarray
    gdop: float
    residuals_hz: np.ndarray
    used: np.ndarray
    n_used: int
    iterations: int
    chi2: float
    status: FixStatus
    ambiguous: bool
    mirror_pos_ecef_m: np.ndarray
    mirror_chi2: float
    time_bias_s: np.ndarray = None
    clock: str = "per_pass"
    rx_clock_poly_hz: np.ndarray = None
    rx_t_ref_s: float = np.nan
    sat_offset_hz: np.ndarray = None
    rx_clock_polys_hz: np.ndarray = None
    clock_labels: tuple = ()
    pass_clock: np.ndarray = None

    @property
    def clock_offset_hz(self):
        """Each pass's frequency offset at its ``t_ref_s``, ndarray (n_pass,)."""
        return self.clock_poly_hz[:, 0]

    @property
    def clock_drift_hz_per_s(self):
        """Each pass's frequency drift at its ``t_ref_s``, ndarray (n_pass,)."""
        return self.clock_poly_hz[:, 1] if self.clock_poly_hz.shape[1] > 1 else np.zeros(len(self.pass_ids))

    @property
    def residual_rms_hz(self):
        """RMS of the used residuals [Hz]."""
        return float(np.sqrt(np.mean(self.residuals_hz[self.used] ** 2))) if self.n_used else np.nan


def _inverse_or_nan(N, rcond=1e-12):
    """Inverse of a symmetric positive semi-definite matrix, judged on its unit-diagonal scaling; NaN if singular."""
    diag = np.diagonal(N)
    d = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    lam, V = np.linalg.eigh(N * d[:, None] * d[None, :])
    if not (diag > 0).all() or lam[0] <= rcond * abs(lam[-1]):
        return np.full(N.shape, np.nan)
    return (V / lam) @ V.T * d[:, None] * d[None, :]


def _grid_starts(centre_ecef_m, offset_m):
    """Ground points at ``centre`` and on a 5 x 5 east/north grid of half-width ``offset_m`` around it, (25, 3)."""
    lat, lon, _ = ecef_to_geodetic(centre_ecef_m)
    e, n = np.meshgrid(offset_m * np.array([0.0, -1.0, -1 / 3, 1 / 3, 1.0]),
                       offset_m * np.array([0.0, -1.0, -1 / 3, 1 / 3, 1.0]))
    enu = np.stack([e.ravel(), n.ravel(), np.zeros(e.size)], -1)
    la, lo, _ = ecef_to_geodetic(centre_ecef_m + enu @ C_e_n(lat, lon).T)
    return geodetic_to_ecef(la, lo, 0.0)


def _shift_poly(coef, shift):
    """Coefficients (..., d + 1) of ``p(s + shift)`` for ``p(s) = sum coef_k s^k``, lowest first."""
    d = coef.shape[-1] - 1
    k = np.arange(d + 1)
    binom = np.array([[comb(j, i) if j >= i else 0 for j in k] for i in k], dtype=float)
    powers = np.asarray(shift, dtype=float)[..., None, None] ** np.maximum(k[None, :] - k[:, None], 0)
    return np.einsum("...j,ij,...ij->...i", coef, binom, powers)


def solve_static_passes(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, pass_id, *,
                        pos0_ecef_m=None, alt_m=None, alt_sigma_m=10.0, mask=None, max_iter=200, alpha=1e-3,
                        clock="per_pass", clock_degree=None, sat_offset_sigma_hz=SAT_OFFSET_SIGMA_HZ,
                        time_bias=True, time_bias_sigma_s=TIME_OFFSET_SIGMA_S, start_offset_m=1.0e6,
                        ambiguity_m=10e3, clock_group=None):
    """Batch Doppler fix of a receiver at rest from several passes (satellites), each with its own frequency terms.

    The position is shared. Each pass ``p`` (one satellite's track) has
    frequency terms and optionally a time offset ``dt_p`` of its satellite
    states (to first order the along-track error of its element set, or a
    time-tag offset), entering each row through the Doppler rate
    (:func:`doppler_rate`), with a zero-mean prior ``time_bias_sigma_s``.
    Clock models:

    ``"per_pass"``
        each pass its own frequency polynomial of degree ``clock_degree``
        (default 3) in ``t - t_ref[p]`` (the pass's mid-time): one receiver
        seeing one transmitter at a time (DopTrack), or an unknown drift per
        transmitter.
    ``"common"``
        one receiver clock, a polynomial of degree ``clock_degree`` (default
        1: offset and drift) in ``t - rx_t_ref_s`` shared by all passes, plus
        each satellite's constant frequency offset with a zero-mean prior
        ``sat_offset_sigma_hz`` (Starlink satellites' own offsets are 0-5 Hz,
        [Shen 2024] Table 1): a multi-satellite receiver, which keeps the
        geometry a free polynomial per pass would absorb.

    All these terms enter linearly and are eliminated exactly (variable
    projection): each LM step solves the weighted linear fit of them to the
    residuals (block-diagonal per pass, the shared clock by its Schur
    complement) and iterates on the position alone with the projected
    Jacobian ``(I - A K) D``, ``D`` the position derivative at fixed linear
    terms (the exact gradient even though the rate column depends on the
    position). The iteration stops when a step is below 0.1 mm or 1e-3 of
    the posterior sigma along it. Priors enter as pseudo-rows (never
    excluded), so chi-square and degrees of freedom count them. The
    covariance is that of the full state. Passes on opposite sides of the
    station resolve the mirror ambiguity of a single pass. Outliers are
    excluded one row per pass at a time (see :func:`solve_static`).

    Parameters
    ----------
    doppler_hz, sigma_hz, carrier_hz, t_s : array_like, (m,)
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (m, 3)
    pass_id : array_like, (m,)
        Label of each row's pass (any sortable type). Passes with fewer than
        one more usable row than per-pass terms are left out.
    pos0_ecef_m : array_like, (3,) or (k, 3), optional
        Start(s); the lowest chi-square wins. Default the ground point below
        the satellites' mean direction and a 5 x 5 grid of
        ``start_offset_m`` half-width around it.
    alt_m : float, optional
        Known height above the ellipsoid, standard deviation ``alt_sigma_m``.
    mask : array_like of bool, (m,), optional
    max_iter : int
    alpha : float or None
        Significance of the chi-square outlier test; None disables it.
    clock : {"per_pass", "common"}
    clock_degree : int, optional
    sat_offset_sigma_hz : float
        Clock ``"common"``: prior standard deviation of each satellite's offset [Hz].
    time_bias : bool
        Estimate each pass's time offset ``dt_p`` [s].
    time_bias_sigma_s : float or None
        Zero-mean prior standard deviation of each ``dt_p``; None: no prior.
    start_offset_m, ambiguity_m : float
    clock_group : array_like of int, (m,), optional
        Clock ``"common"``: receiver clock of each row (e.g. its
        constellation); each distinct value among the unmasked rows gets its
        own receiver polynomial (a pass takes the clock of its first row).
        Ignored by ``"per_pass"`` (every pass has its own terms already).

    Returns
    -------
    PassesFix
    """
    if clock not in ("per_pass", "common"):
        raise ValueError(f"clock {clock!r}: expected 'per_pass' or 'common'")
    common = clock == "common"
    deg = (1 if common else 3) if clock_degree is None else int(clock_degree)
    if deg < 0:
        raise ValueError("clock degree must be non-negative")
    if common and not sat_offset_sigma_hz > 0:
        raise ValueError("sat_offset_sigma_hz must be positive")
    tb = int(bool(time_bias))
    n_glob = deg + 1 if common else 0
    n_loc = (1 if common else deg + 1) + tb
    # Prior weights of the per-pass terms: [satellite offset | polynomial..., time offset].
    prior = np.zeros(n_loc)
    if common:
        prior[0] = 1.0 / float(sat_offset_sigma_hz) ** 2
    if tb and time_bias_sigma_s is not None:
        prior[-1] = 1.0 / float(time_bias_sigma_s) ** 2
    prior_cols = np.flatnonzero(prior > 0)
    y = np.asarray(doppler_hz, dtype=float).ravel()
    n = y.size
    r_s = np.asarray(pos_sv_ecef_m, dtype=float).reshape(n, 3)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(n, 3)
    sigma = np.broadcast_to(np.asarray(sigma_hz, dtype=float), y.shape)
    f0 = np.broadcast_to(np.asarray(carrier_hz, dtype=float), y.shape)
    t = np.asarray(t_s, dtype=float).ravel()
    labels, gi = np.unique(np.asarray(pass_id).ravel(), return_inverse=True)
    m = np.ones(n, bool) if mask is None else np.asarray(mask, bool).ravel()
    m = m & np.isfinite(y) & np.isfinite(r_s).all(-1) & np.isfinite(v_s).all(-1) & (sigma > 0) & (f0 > 0)
    m &= np.isfinite(t)
    keep = np.bincount(gi[m], minlength=len(labels)) >= n_loc + 1 - len(prior_cols)
    m &= keep[gi]
    labels, gi = labels[keep], np.cumsum(keep)[gi] - 1
    gi[~m] = np.maximum(gi[~m], 0)
    # Receiver clocks (clock "common"): one polynomial per distinct group among the rows kept.
    grp = np.zeros(n, int) if clock_group is None or not common else np.broadcast_to(np.asarray(clock_group), (n,))
    clock_labels, g_idx = np.unique(grp[m], return_inverse=True)
    n_clk = max(len(clock_labels), 1)
    clk = np.zeros(n, int)
    clk[m] = g_idx.ravel()
    n_glob *= n_clk
    n_pass = len(labels)
    # Rows in pass order internally (contiguous segments for the per-pass sums).
    order = np.argsort(gi, kind="stable")
    y, sigma, f0, t, m, gi, r_s, v_s, clk = (a[order] for a in (y, sigma, f0, t, m, gi, r_s, v_s, clk))
    pass_clk = np.zeros(len(labels), int)
    pass_clk[gi[m]] = clk[m]
    y, sigma, f0, t = (np.where(m, a, fill) for a, fill in ((y, 0.0), (sigma, 1.0), (f0, 1.0), (t, 0.0)))
    r_s = np.where(m[:, None], r_s, [2e7, 0.0, 0.0])
    v_s = np.where(m[:, None], v_s, 0.0)
    seg = np.searchsorted(gi, np.arange(n_pass))
    t_lo = np.array([t[gi == p][m[gi == p]].min() for p in range(n_pass)]) if n_pass else np.zeros(0)
    t_hi = np.array([t[gi == p][m[gi == p]].max() for p in range(n_pass)]) if n_pass else np.zeros(0)
    t_ref = 0.5 * (t_lo + t_hi)
    half_span_s = np.maximum(0.5 * (t_hi - t_lo), 1.0)
    t_rx = 0.5 * (t_lo.min() + t_hi.max()) if n_pass else 0.0
    half_rx_s = max(0.5 * (t_hi.max() - t_lo.min()), 1.0) if n_pass else 1.0
    # Polynomial bases in scaled time (|u| <= 1) for conditioning: the shared clock's and the per-pass ones.
    B_glob = ((t - t_rx) / half_rx_s)[:, None] ** np.arange(n_glob // n_clk)
    if n_clk > 1:
        B_glob = ((clk[:, None] == np.arange(n_clk))[:, :, None] * B_glob[:, None, :]).reshape(n, n_glob)
    basis = np.ones((n, 1)) if common else ((t - t_ref[gi]) / half_span_s[gi])[:, None] ** np.arange(deg + 1)
    # Priors: per prior'd per-pass term a pseudo-row per pass (measured 0), after the Doppler rows.
    n_extra = n_pass * len(prior_cols)
    sig_prior = np.repeat(1.0 / np.sqrt(prior[prior_cols]), n_pass)
    y, sigma, m = np.append(y, np.zeros(n_extra)), np.append(sigma, sig_prior), np.append(m, np.ones(n_extra, bool))
    has_alt = alt_m is not None
    if has_alt:
        y, sigma, m = np.append(y, alt_m), np.append(sigma, alt_sigma_m), np.append(m, True)
    fixed = np.zeros(y.size, bool)
    fixed[n:] = True
    groups = np.concatenate([gi, [-1] * (n_extra + has_alt)])

    def normal(x, w):
        """Geometry (h, D, rate grad), the per-pass basis A and the linear normal matrix's blocks and solver."""
        H = doppler_jacobian(r_s, v_s, x, np.zeros((len(x), 3)), f0)
        h, D = np.einsum("pmi,mi->pm", H[..., 3:6], -v_s), H[..., :3]
        A = np.broadcast_to(basis, (len(x),) + basis.shape)
        grad = None
        if tb:
            rate, grad = doppler_rate(r_s, v_s, x, f0)
            A = np.concatenate([A, rate[..., None]], -1)
        wd = w[:, :n]
        wA = wd[..., None] * A
        G_ss = np.add.reduceat(wA[..., :, None] * A[..., None, :], seg, axis=1) + np.diag(prior)
        Gi_ss = np.linalg.pinv(G_ss, hermitian=True)
        G_gg = np.einsum("mi,pm,mj->pij", B_glob, wd, B_glob)
        G_sg = np.add.reduceat(wA[..., :, None] * B_glob[None, :, None, :], seg, axis=1)  # (k, P, l, g)
        S = G_gg - np.einsum("pqli,pqlj->pij", G_sg, Gi_ss @ G_sg)
        Si = np.linalg.pinv(S, hermitian=True) if n_glob else S

        def lin(rhs):
            """Linear terms (global (k, g, q), per pass (k, P, l, q)) fitting rows ``rhs`` (k, n, q)."""
            b_s = np.add.reduceat(wA[..., :, None] * rhs[..., None, :], seg, axis=1)
            z_s = Gi_ss @ b_s
            b_g = np.einsum("mi,pm,pmq->piq", B_glob, wd, rhs)
            c_g = Si @ (b_g - np.einsum("pqli,pqlk->pik", G_sg, z_s))
            return c_g, z_s - Gi_ss @ (G_sg @ c_g[:, None])

        def fitted(c_g, c_s):
            """Rows (k, n, q) of the linear terms."""
            return np.einsum("mi,piq->pmq", B_glob, c_g) + np.einsum("pmi,pmiq->pmq", A, c_s[:, gi])

        return h, D, grad, A, lin, fitted, (G_gg, G_sg, G_ss)

    def pieces(x, w):
        """Prediction, projected position Jacobian and the linear terms (global, per pass) at ``x``."""
        h, D, grad, A, lin, fitted, blocks = normal(x, w)
        c_g, c_s = lin((y[:n] - h)[..., None])
        if tb:
            D = D + c_s[:, gi, -1, 0, None] * grad
        K_g, K_s = lin(D)
        pred = h + fitted(c_g, c_s)[..., 0]
        J = D - fitted(K_g, K_s)
        return pred, J, D, A, c_g[..., 0], c_s[..., 0], K_s, blocks

    def model(x, idx, w):
        pred, J, _, _, _, c_s, K_s, _ = pieces(x, w)
        pred = np.concatenate([pred] + [c_s[:, :, j] for j in prior_cols], -1)
        J = np.concatenate([J] + [-K_s[:, :, j] for j in prior_cols], axis=1)
        if has_alt:
            lat, lon, alt = ecef_to_geodetic(x)
            pred = np.concatenate([pred, alt[:, None]], -1)
            J = np.concatenate([J, C_e_n(lat, lon)[..., 2][:, None, :]], axis=1)
        return pred, J

    n_states = 3 + n_glob + n_pass * n_loc
    xtol = _XTOL_STATIC[:3]

    def solve(x0, used, alpha_):
        k = len(x0)
        ys, ss, ms = (np.broadcast_to(a, (k, y.size)) for a in (y, sigma, used))
        return _solve_robust(model, x0, ys, ss, ms, n_states, xtol=xtol, max_iter=max_iter, alpha=alpha_,
                             fixed=fixed, groups=groups, step_sigma_tol=_STEP_SIGMA_TOL)

    if pos0_ecef_m is not None:
        starts = np.asarray(pos0_ecef_m, dtype=float).reshape(-1, 3)
    elif m[:n].any():
        starts = _grid_starts(subpoint_centroid_ecef_m(r_s[m[:n]]), start_offset_m)
    else:
        starts = np.zeros((1, 3))
    x, res, J, Q, used, iterations, chi2, status = solve(starts, m, None)
    solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    cost = np.where(solved, chi2, np.inf)
    best = int(np.argmin(cost))
    dof = max(int(used[best].sum()) - n_states, 1)
    fits = solved & (cost <= cost[best] + 3.0 * np.sqrt(2.0 * dof))
    apart = solved & (np.linalg.norm(x - x[best], axis=-1) > ambiguity_m)
    ambiguous = bool((fits & apart).any())
    other = int(np.argmin(np.where(apart, cost, np.inf))) if apart.any() else None
    x_mirror = x[other:other + 1].copy() if other is not None else None
    iterations = iterations[best:best + 1]
    x, res, J, Q, used, chi2, status = x[best:best + 1], res[best:best + 1], J[best:best + 1], Q[best:best + 1], \
        used[best:best + 1], chi2[best:best + 1], status[best:best + 1]
    if alpha is not None and solved[best]:
        x, res, J, Q, used, it, chi2, status = solve(x, used, alpha)
        iterations = iterations + it
    ok = status[0] in (FixStatus.OK, FixStatus.INCONSISTENT)
    mirror_pos, mirror_chi2 = np.full(3, np.nan), np.nan
    if x_mirror is not None and ok:
        xm, _, _, _, _, _, chi2_m, status_m = solve(x_mirror, used, None)
        if status_m[0] in (FixStatus.OK, FixStatus.INCONSISTENT):
            mirror_pos, mirror_chi2 = xm[0], float(chi2_m[0])
    # Full normal matrix of [pos, global terms, per-pass terms (pass-major)] at the solution, inverted.
    w = np.where(used, 1.0 / sigma**2, 0.0)
    _, _, D, A, c_g, c_s, _, (G_gg, G_sg, G_ss) = pieces(x, w)
    wd, D, A = w[0, :n], D[0], A[0]
    N = np.zeros((n_states, n_states))
    N[:3, :3] = np.einsum("mi,m,mj->ij", D, wd, D)
    if has_alt:
        lat, lon, _ = ecef_to_geodetic(x[0])
        up = C_e_n(lat, lon)[:, 2]
        N[:3, :3] += np.outer(up, up) * w[0, -1]
    g = slice(3, 3 + n_glob)
    N[g, :3] = np.einsum("mi,m,mj->ij", B_glob, wd, D)
    N[g, g] = G_gg[0]
    N[3 + n_glob:, :3] = np.add.reduceat((wd[:, None] * A)[:, :, None] * D[:, None, :], seg, axis=0).reshape(-1, 3)
    N[3 + n_glob:, g] = G_sg[0].reshape(n_pass * n_loc, n_glob)
    for p in range(n_pass):
        sl = slice(3 + n_glob + p * n_loc, 3 + n_glob + (p + 1) * n_loc)
        N[sl, sl] = G_ss[0, p]
    N = np.tril(N) + np.tril(N, -1).T
    scale_glob = np.tile(1.0 / half_rx_s ** np.arange(n_glob // n_clk), n_clk)
    scale_loc = np.ones((n_pass, n_loc)) if common else \
        np.concatenate([1.0 / half_span_s[:, None] ** np.arange(deg + 1), np.ones((n_pass, tb))], -1)
    scale = np.concatenate([np.ones(3), scale_glob, scale_loc.ravel()])
    cov = _inverse_or_nan(N) * scale[:, None] * scale[None, :] if ok else np.full((n_states, n_states), np.nan)
    # Reorder to [pos, global terms, per-pass polynomials or offsets, time biases].
    loc = 3 + n_glob + np.arange(n_pass * n_loc).reshape(n_pass, n_loc)
    n_poly_loc = n_loc - tb
    perm = np.concatenate([np.arange(3 + n_glob), loc[:, :n_poly_loc].ravel(), loc[:, n_poly_loc:].ravel()])
    cov = cov[np.ix_(perm, perm)]
    w_rel = np.where(used[0], np.median(sigma[:n][m[:n]]) ** 2 / sigma**2, 0.0) if m[:n].any() \
        else used[0].astype(float)
    gdop = float(np.sqrt(np.trace(cofactor(J[0], w_rel))))
    back = np.empty(n, dtype=int)
    back[order] = np.arange(n)
    nan_unless = (lambda a: a if ok else np.full_like(a, np.nan))  # noqa: E731
    c_loc = c_s[0] * scale_loc
    rx_polys = (c_g[0] * scale_glob).reshape(n_clk, -1)
    rx_poly = rx_polys[0]
    if common:
        # Each pass's effective polynomial: its receiver clock's about the pass's mid-time, plus its satellite's offset.
        poly = _shift_poly(rx_polys[pass_clk] if n_clk > 1 else np.broadcast_to(rx_poly, (n_pass, deg + 1)),
                           t_ref - t_rx)
        poly[:, 0] += c_loc[:, 0]
    else:
        poly = c_loc[:, :deg + 1]
    return PassesFix(
        pos_ecef_m=nan_unless(x[0]), pass_ids=labels, t_ref_s=t_ref, clock_poly_hz=nan_unless(poly),
        cov=cov, gdop=gdop, residuals_hz=res[0, :n][back], used=used[0, :n][back], n_used=int(used[0, :n].sum()),
        iterations=int(iterations[0]), chi2=float(chi2[0]), status=FixStatus(int(status[0])),
        ambiguous=ambiguous, mirror_pos_ecef_m=mirror_pos, mirror_chi2=mirror_chi2,
        time_bias_s=nan_unless(c_loc[:, -1].copy()) if tb else None, clock=clock,
        rx_clock_poly_hz=nan_unless(rx_poly) if common else None, rx_t_ref_s=float(t_rx) if common else np.nan,
        sat_offset_hz=nan_unless(c_loc[:, 0].copy()) if common else None,
        rx_clock_polys_hz=nan_unless(rx_polys.copy()) if common else None,
        clock_labels=tuple(clock_labels.tolist()) if common and clock_group is not None else (),
        pass_clock=pass_clk.copy() if common else None,
    )
