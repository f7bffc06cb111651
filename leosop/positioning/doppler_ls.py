"""Doppler least squares: snapshot fixes (seed 004 eq. 4-12) and static batch fixes.

Measurement model (the toolkit's Doppler sign, see :mod:`leosop`)::

    doppler_hz = -(f0 / c) * (v_s - v_r) . (r_s - r_r) / |r_s - r_r| + clock terms

Snapshot
    one epoch, state ``[x, y, z, vx, vy, vz, T_u]`` (ECEF m, m/s, receiver
    frequency offset Hz), at least 7 satellites. :func:`solve_snapshots`
    solves many epochs at once, each independently.
Static
    a receiver at rest in ECEF observed over many epochs, state
    ``[x, y, z, b0, b1]``: frequency offset ``b0`` [Hz] at the reference time
    and its drift ``b1`` [Hz/s]; optionally a known ellipsoidal height as a
    pseudo-measurement (the classic Argos-style fix).

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

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef
from .dop import N_DOPPLER_STATES, cofactor, doppler_jacobian

__all__ = ["FixStatus", "SnapshotFixes", "StaticFix", "solve_snapshots", "solve_static",
           "subpoint_centroid_ecef_m", "N_STATIC_STATES"]

#: States of a static batch fix: position, frequency offset, frequency drift.
N_STATIC_STATES = 5
#: Step thresholds of convergence, per state: 0.1 mm, 1 um/s, 10 uHz (uHz/s).
_XTOL_SNAPSHOT = np.array([1e-4] * 3 + [1e-6] * 3 + [1e-5])
_XTOL_STATIC = np.array([1e-4] * 3 + [1e-5, 1e-7])
#: Earth radius used to place a start on the ground [m].
_R_GROUND_M = 6_371_000.0


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
        Receiver frequency offset ``T_u``.
    cov : ndarray, (n_ep, 7, 7)
        Posterior covariance of ``[pos, vel, T_u]`` from the given sigmas.
    gdop, pos_dop, vel_dop : ndarray, (n_ep,)
        Eq. 10 ``sqrt(trace((H^T H)^-1))`` over the used satellites, and the
        square roots of the position and velocity blocks of that trace.
    residuals_hz : ndarray, (n_ep, n_sv)
        Measured minus modelled Doppler at the solution; NaN where masked.
    used : ndarray of bool, (n_ep, n_sv)
        Measurements in the solution (mask minus excluded outliers).
    n_used, iterations : ndarray of int, (n_ep,)
    chi2 : ndarray, (n_ep,)
        Weighted residual sum of squares.
    status : ndarray of int, (n_ep,)
        :class:`FixStatus` values; states are NaN unless OK or INCONSISTENT.
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
    cov : ndarray, (5, 5)
        Posterior covariance of ``[pos, b0, b1]``.
    gdop : float
        ``sqrt(trace((H^T H)^-1))`` of the 5 states over the used Doppler rows
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

    @property
    def residual_rms_hz(self):
        """RMS of the used residuals [Hz]."""
        return float(np.sqrt(np.mean(self.residuals_hz[self.used] ** 2))) if self.n_used else np.nan


def _levenberg_marquardt(model, x0, y, w, xtol, max_iter):
    """Damped Gauss-Newton over independent problems.

    ``model(x, idx)`` gives predictions (k, m) and Jacobians (k, m, n) of the
    problems ``idx`` at states ``x`` (k, n); ``y``, ``w`` (P, m) are the
    measurements and weights (0 drops a row). Returns ``x, iterations,
    converged``.
    """
    n_prob, n = x0.shape
    x = x0.copy()
    pred, J = model(x, np.arange(n_prob))
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
        pt, Jt = model(xt, active)
        rt = np.where(wa > 0, y[active] - pt, 0.0)
        ct = np.einsum("pm,pm->p", wa, rt * rt)
        accept = np.isfinite(ct) & (ct <= cost[active])
        acc = active[accept]
        x[acc], J[acc], r[acc], cost[acc] = xt[accept], Jt[accept], rt[accept], ct[accept]
        lam[active] = np.where(accept, np.maximum(lam[active] / 10, 1e-12), np.minimum(lam[active] * 10, 1e12))
        iterations[active] += 1
        done = np.all(np.abs(dx) <= xtol, axis=-1)
        converged[active[done]] = True
        active = active[~done]
    return x, iterations, converged


def _solve_robust(model, x0, y, sigma, used, n_states, *, xtol, max_iter, alpha, fixed=None, x_alt=None):
    """LM, then chi-square test and w-test exclusions one at a time.

    Returns ``x, residuals, J, Q (weighted cofactor), used, iterations, chi2,
    status``; rows in ``fixed`` (bool, (m,)) are never excluded. Problems
    that do not converge or fail the test from ``x0`` are retried once from
    ``x_alt`` (P, n) and keep the better solution.
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
        sub = lambda xs, i, todo=todo: model(xs, todo[i])  # noqa: E731
        w = np.where(used[todo], w_all[todo], 0.0)
        xs, it, conv = _levenberg_marquardt(sub, x[todo], y[todo], w, xtol, max_iter)
        iterations[todo] += it
        pred, J = model(xs, todo)
        r = np.where(used[todo], y[todo] - pred, 0.0)
        chi2 = np.einsum("pm,pm->p", w, r * r)
        dof = used[todo].sum(-1) - n_states
        if first and x_alt is not None:
            # A start far away can end in a local minimum: retry those that fail the test from x_alt.
            with np.errstate(invalid="ignore"):
                retry = ~conv | (chi2 > chi2_dist.isf(alpha or 1e-3, np.maximum(dof, 1)))
            if retry.any():
                k = np.flatnonzero(retry)
                sub2 = lambda xs, i, p=todo[k]: model(xs, p[i])  # noqa: E731
                xs2, it2, conv2 = _levenberg_marquardt(sub2, x_alt[todo[k]], y[todo[k]], w[k], xtol, max_iter)
                iterations[todo[k]] += it2
                pred2, J2 = model(xs2, todo[k])
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
        used[p, np.argmax(wstat, axis=-1)] = False
        todo = p
    pred, J = model(x, np.arange(n_prob))
    w = np.where(used, w_all, 0.0)
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
                    max_iter=50, alpha=1e-3):
    """Snapshot Doppler fixes of many epochs at once (seed 004 eq. 4-12).

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
    x0 : array_like, (n_ep, 7) or (7,), optional
        Start ``[pos, vel, T_u]``; default the ground point below the
        satellites' mean direction, at rest, no offset.
    max_iter : int
        Iteration cap of each solve.
    alpha : float or None
        Significance of the chi-square outlier test; None disables it.

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
    x_ground = np.zeros((n_ep, N_DOPPLER_STATES))
    x_ground[:, :3] = np.nan_to_num(subpoint_centroid_ecef_m(r_s, m), nan=_R_GROUND_M)
    x0 = x_ground if x0 is None else np.broadcast_to(np.asarray(x0, dtype=float), (n_ep, N_DOPPLER_STATES)).copy()

    def model(x, idx):
        H = doppler_jacobian(r_s[idx], v_s[idx], x[:, :3], x[:, 3:6], f0[idx])
        pred = np.einsum("pmi,pmi->pm", H[..., 3:6], x[:, None, 3:6] - v_s[idx]) + x[:, 6:7]
        return pred, H

    x, res, H, Q, used, iterations, chi2, status = _solve_robust(
        model, x0, y, sigma, m, N_DOPPLER_STATES, xtol=_XTOL_SNAPSHOT, max_iter=max_iter, alpha=alpha,
        x_alt=x_ground)
    good = (status == FixStatus.OK) | (status == FixStatus.INCONSISTENT)
    x[~good] = np.nan
    Q[~good] = np.nan
    Q0 = cofactor(H, used)
    d0 = np.diagonal(Q0, axis1=-2, axis2=-1)
    with np.errstate(invalid="ignore"):
        gdop = np.sqrt(d0.sum(-1))
        pos_dop, vel_dop = np.sqrt(d0[:, :3].sum(-1)), np.sqrt(d0[:, 3:6].sum(-1))
    return SnapshotFixes(
        pos_ecef_m=x[:, :3], vel_ecef_mps=x[:, 3:6], clock_offset_hz=x[:, 6], cov=Q,
        gdop=gdop, pos_dop=pos_dop, vel_dop=vel_dop, residuals_hz=res, used=used,
        n_used=used.sum(-1), iterations=iterations, chi2=chi2, status=status,
    )


def _starts(pos_sv_ecef_m, vel_sv_ecef_mps, pos0_ecef_m, offset_m):
    """Starts of a static solve and their mirror images across the mean ground track.

    Without ``pos0_ecef_m``: the sub-point centroid and ``offset_m`` either side
    of it; with it: ``pos0_ecef_m`` and its reflection.
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
    starts = []
    for side in (0.0, 1.0, -1.0):
        la, lo, _ = ecef_to_geodetic(centre + side * offset_m * across)
        starts.append(geodetic_to_ecef(la, lo, 0.0))
    return np.array(starts)


def solve_static(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, *, pos0_ecef_m=None,
                 alt_m=None, alt_sigma_m=10.0, mask=None, max_iter=50, alpha=1e-3, start_offset_m=1.0e6,
                 ambiguity_m=10e3):
    """Batch Doppler fix of a receiver at rest in ECEF.

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
        ``start_offset_m`` either side of it across the track; the lowest
        chi-square wins.
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

    Returns
    -------
    StaticFix
    """
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
    has_alt = alt_m is not None
    if has_alt:
        y = np.append(y, alt_m)
        sigma = np.append(sigma, alt_sigma_m)
        m = np.append(m, True)
    fixed = np.zeros(y.size, bool)
    fixed[n_rows:] = True

    def model(x, idx):
        H = doppler_jacobian(r_s, v_s, x[:, :3], np.zeros((len(x), 3)), f0)
        pred = np.einsum("pmi,mi->pm", H[..., 3:6], -v_s) + x[:, 3:4] + x[:, 4:5] * dt
        J = np.concatenate([H[..., :3], np.ones_like(pred)[..., None], np.broadcast_to(dt, pred.shape)[..., None]],
                           axis=-1)
        if has_alt:
            lat, lon, h = ecef_to_geodetic(x[:, :3])
            up = C_e_n(lat, lon)[..., 2]
            pred = np.concatenate([pred, h[:, None]], axis=-1)
            J = np.concatenate([J, np.concatenate([up, np.zeros((len(x), 2))], -1)[:, None, :]], axis=1)
        return pred, J

    if m[:n_rows].any():
        starts = _starts(r_s[m[:n_rows]], v_s[m[:n_rows]], pos0_ecef_m, start_offset_m)
    else:
        starts = np.zeros((1, 3)) if pos0_ecef_m is None else np.reshape(pos0_ecef_m, (1, 3))
    x0 = np.zeros((len(starts), N_STATIC_STATES))
    x0[:, :3] = starts
    ys, ss, ms = (np.broadcast_to(a, (len(starts), y.size)) for a in (y, sigma, m))
    # Choose among the starts' solutions on the same rows (before any exclusion), then clean outliers.
    x, res, J, Q, used, iterations, chi2, status = _solve_robust(
        model, x0, ys, ss, ms, N_STATIC_STATES, xtol=_XTOL_STATIC, max_iter=max_iter, alpha=None, fixed=fixed)
    solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    cost = np.where(solved, chi2, np.inf)
    best = int(np.argmin(cost))
    # Solutions whose chi-square is within 3 standard deviations of the best one fit the data
    # equally well (a single pass's mirror image): the start given decides between them.
    dof = max(int(used[best].sum()) - N_STATIC_STATES, 1)
    fits = solved & (cost <= cost[best] + 3.0 * np.sqrt(2.0 * dof))
    if pos0_ecef_m is not None and fits.sum() > 1:
        best = int(np.argmin(np.where(fits, np.linalg.norm(x[:, :3] - starts[0], axis=-1), np.inf)))
    spread = np.linalg.norm(x[fits, :3] - x[best, :3], axis=-1)
    ambiguous = bool((spread > ambiguity_m).any())
    if alpha is not None and solved[best]:
        x, res, J, Q, used, it, chi2, status = _solve_robust(
            model, x[best:best + 1], y[None], sigma[None], m[None], N_STATIC_STATES, xtol=_XTOL_STATIC,
            max_iter=max_iter, alpha=alpha, fixed=fixed)
        iterations = iterations[best:best + 1] + it
        best = 0
        solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    w_rel = np.where(used[best], np.median(sigma[:n_rows][m[:n_rows]]) ** 2 / sigma**2, 0.0) if m[:n_rows].any() \
        else used[best].astype(float)
    gdop = float(np.sqrt(np.trace(cofactor(J[best], w_rel))))
    xb = x[best] if solved[best] else np.full(N_STATIC_STATES, np.nan)
    return StaticFix(
        pos_ecef_m=xb[:3], clock_offset_hz=float(xb[3]), clock_drift_hz_per_s=float(xb[4]), t_ref_s=float(t_ref),
        cov=Q[best] if solved[best] else np.full((5, 5), np.nan), gdop=gdop,
        residuals_hz=res[best, :n_rows], used=used[best, :n_rows], n_used=int(used[best, :n_rows].sum()),
        iterations=int(iterations[best]), chi2=float(chi2[best]), status=FixStatus(int(status[best])),
        ambiguous=ambiguous,
    )
