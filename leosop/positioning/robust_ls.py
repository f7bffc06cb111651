"""Robust damped least squares, batched over independent problems: the core of the Doppler solvers.

One Levenberg-Marquardt iteration (Gauss-Newton, [Shen 2024] eq. 11-12, with
Marquardt damping on the Jacobi-scaled normal equations, so that a start
1,000 km away converges) runs over many problems at once, with an iteration
cap; convergence is judged on the undamped Gauss-Newton step, per state and
in units of the posterior sigma (:func:`_levenberg_marquardt`). Measurements are weighted by
``1 / sigma**2``; the cofactor ``(J^T W J)^-1`` at the solution is the
covariance.

Outliers: when the weighted residual sum fails the chi-square test at
significance ``alpha``, the measurement with the largest standardised
residual (Baarda's w-test statistic) is excluded and the problem re-solved,
one measurement at a time, while at least two redundant measurements remain.
With groups (a multi-pass fix's passes) each group's largest standardised
residual is tested on its own at every round, also when the sum passes
(data snooping: among a thousand rows one outlier moves the sum too little
to fail it), then at ``alpha / n`` for the largest of the group's ``n``
rows (Bonferroni), so that, while the sum passes, a pass of white rows
loses none but this often and rows whose errors are correlated (their
sigmas scaled only afterwards) are not thinned; once the sum fails every
group is tested at ``alpha``, as without groups. A residual's variance is
``sigma^2 (1 - h)`` with ``h`` the row's whole leverage: a model that
eliminates linear terms (a pass's offsets) adds theirs through its
``leverage`` method, as a row those terms absorb leaves a small residual
however wrong it is.
Failures come back as data in ``status`` (:class:`FixStatus`); a fix that
still fails the test (``INCONSISTENT``) has its covariance scaled by the
a-posteriori variance factor ``chi2 / dof``, so that its sigma reflects the
residuals rather than the sigmas given.
"""

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm as norm_dist

from ..geometry.dop import cofactor

__all__ = ["FixStatus", "BatchFit", "batch_rows", "solve_robust", "XTOL_POS_M", "STEP_SIGMA_TOL", "EQUAL_FIT_SIGMAS"]

#: Step threshold of convergence of a position [m]: 0.1 mm.
XTOL_POS_M = 1e-4
#: A fix has also converged when its Gauss-Newton step is below this fraction of the posterior sigma
#: along it (a weakly determined direction then needs no sub-millimetre steps); the step is then taken,
#: which leaves it ~this squared short.
STEP_SIGMA_TOL = 1e-3
#: Solutions from different starts fit the data equally well when their chi-squares differ by less
#: than this many standard deviations of a chi-square, ``sqrt(2 dof)`` (e.g. a pass's mirror image).
EQUAL_FIT_SIGMAS = 3.0
#: Marquardt damping added to the unit diagonal of the Jacobi-scaled normal equations: its start
#: (nearly Gauss-Newton), the factor it shrinks by after an accepted step and grows by after a
#: rejected one, and its bounds (1e12 makes the step a tiny gradient step).
_DAMPING_START = 1e-3
_DAMPING_FACTOR = 10
_DAMPING_MIN, _DAMPING_MAX = 1e-12, 1e12
#: An accepted step whose cost decrease is below this fraction of the linear model's grows the
#: damping instead of shrinking it ([More 1978]'s trust-region rule): where the Gauss-Newton model
#: misjudges the curvature (large residuals at a false minimum), full steps overshoot and the
#: iteration zig-zags across the valley, ~1 % closer per step.
_GAIN_MIN = 0.25
#: Significance of the chi-square test that retries a problem from its alternative start, when the
#: caller disabled the outlier tests.
_RETRY_ALPHA = 1e-3
#: Floor of a residual's variance relative to its measurement's (a row that alone determines a
#: state has a residual variance of zero up to round-off).
_RESIDUAL_VAR_FLOOR = 1e-12


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


@dataclass(frozen=True, kw_only=True)
class BatchFit:
    """What a batch fix reports beside its states (its subclass documents the shapes).

    Attributes
    ----------
    cov : ndarray
        Covariance of the states.
    gdop : float
    residuals_hz : ndarray, (m,)
    used : ndarray of bool, (m,)
    n_used, iterations : int
    chi2 : float
        Sum of the used rows' squared normalised residuals.
    dof : int
        Its degrees of freedom: used rows (with pseudo-rows of priors and a
        known height) minus states.
    status : FixStatus
    ambiguous : bool
        A mirror solution fits about as well (``mirror_pos_ecef_m``, ``mirror_chi2``).
    mirror_pos_ecef_m : ndarray, (3,) or None
    mirror_chi2 : float
    """

    cov: np.ndarray
    gdop: float
    residuals_hz: np.ndarray
    used: np.ndarray
    n_used: int
    iterations: int
    chi2: float
    dof: int
    status: FixStatus
    ambiguous: bool = False
    mirror_pos_ecef_m: np.ndarray = None
    mirror_chi2: float = np.nan

    @property
    def residual_rms_hz(self):
        """RMS of the used residuals [Hz]."""
        return float(np.sqrt(np.mean(self.residuals_hz[self.used] ** 2))) if self.n_used else np.nan


def batch_rows(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, mask=None):
    """The rows of a batch fix as flat float arrays, and which of them are usable.

    Returns ``(y, sigma, f0, t, r_s, v_s, m)``: Doppler, sigma and carrier
    [Hz] and time [s], each (m,); satellite position [m] and velocity [m/s],
    (m, 3); and ``m`` (m,) bool, the rows of ``mask`` (all when None) whose
    values are all finite with positive sigma and carrier.
    """
    y = np.asarray(doppler_hz, dtype=float).ravel()
    n = y.size
    r_s = np.asarray(pos_sv_ecef_m, dtype=float).reshape(n, 3)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(n, 3)
    sigma = np.broadcast_to(np.asarray(sigma_hz, dtype=float), y.shape)
    f0 = np.broadcast_to(np.asarray(carrier_hz, dtype=float), y.shape)
    t = np.asarray(t_s, dtype=float).ravel()
    m = np.ones(n, bool) if mask is None else np.asarray(mask, bool).ravel()
    m = m & np.isfinite(y) & np.isfinite(r_s).all(-1) & np.isfinite(v_s).all(-1) & (sigma > 0) & (f0 > 0)
    m &= np.isfinite(t)
    return y, sigma, f0, t, r_s, v_s, m


def _levenberg_marquardt(model, x0, y, w, xtol, max_iter):
    """Damped Gauss-Newton over independent problems.

    ``model(x, idx, w)`` gives predictions (k, m) and Jacobians (k, m, n) of
    the problems ``idx`` at states ``x`` (k, n) with row weights ``w`` (k, m)
    (a model that eliminates linear states needs them); ``y``, ``w`` (P, m)
    are the measurements and weights (0 drops a row).

    Convergence is judged at the current iterate on its undamped
    Gauss-Newton step ``dx = N^-1 g`` (``N = J^T W J``, ``g = J^T W r``),
    never on a damped or rejected trial step: a problem has converged when
    that step is below ``xtol`` (n,) in every state, or when its length in
    units of the posterior sigma, ``sqrt(dx^T N dx) = sqrt(g^T N^-1 g)``
    (the linear model's whole chi-square decrease, square-rooted), is below
    :data:`STEP_SIGMA_TOL`. It then takes that step without the cost test (its
    decrease is at the cost's round-off), so that the solution is the
    minimum to second order whatever path led there. A trial step's cost
    test is at the mercy of round-off near the minimum: judged on the
    damped steps, a run of rejections shrank the step below ``xtol`` and
    stopped a weak geometry (GDOP ~200) up to ~1e-3 of its sigma short,
    wherever the path happened to be. A problem whose damping reaches its
    bound on a rejected step has stalled and stops unconverged. Returns
    ``x, iterations, converged``.
    """
    n_prob, n = x0.shape
    x = x0.copy()
    pred, J = model(x, np.arange(n_prob), w)
    r = np.where(w > 0, y - pred, 0.0)
    cost = np.einsum("pm,pm->p", w, r * r)
    lam = np.full(n_prob, _DAMPING_START)
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
        Ns = N / (d[:, :, None] * d[:, None, :])
        gs = (g / d)[..., None]
        iterations[active] += 1
        # The Gauss-Newton step (damping at its floor only to keep a singular N solvable) and the test.
        dx_gn = np.linalg.solve(Ns + _DAMPING_MIN * eye, gs)[..., 0] / d
        done = np.all(np.abs(dx_gn) <= xtol, axis=-1) | (np.einsum("pi,pi->p", g, dx_gn) <= STEP_SIGMA_TOL**2)
        done &= np.isfinite(dx_gn).all(-1)
        x[active[done]] += dx_gn[done]
        converged[active[done]] = True
        active, Ns, gs, N, g = active[~done], Ns[~done], gs[~done], N[~done], g[~done]
        if active.size == 0:
            break
        dx = np.linalg.solve(Ns + lam[active, None, None] * eye, gs)[..., 0] / d[~done]
        xt = x[active] + dx
        wa = w[active]
        pt, Jt = model(xt, active, wa)
        rt = np.where(wa > 0, y[active] - pt, 0.0)
        ct = np.einsum("pm,pm->p", wa, rt * rt)
        accept = np.isfinite(ct) & (ct <= cost[active])
        # Gain ratio: the cost's actual decrease over the linear model's, 2 g.dx - dx^T N dx (> 0).
        predicted = np.einsum("pi,pi->p", dx, 2.0 * g - np.einsum("pij,pj->pi", N, dx))
        with np.errstate(invalid="ignore", divide="ignore"):
            good = accept & ((cost[active] - ct) >= _GAIN_MIN * predicted)
        acc = active[accept]
        x[acc], J[acc], r[acc], cost[acc] = xt[accept], Jt[accept], rt[accept], ct[accept]
        stalled = ~accept & (lam[active] >= _DAMPING_MAX)
        lam[active] = np.where(good, np.maximum(lam[active] / _DAMPING_FACTOR, _DAMPING_MIN),
                               np.minimum(lam[active] * _DAMPING_FACTOR, _DAMPING_MAX))
        active = active[~stalled]
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


def solve_robust(model, x0, y, sigma, used, n_states, *, xtol, max_iter, alpha, fixed=None, x_alt=None,
                  groups=None):
    """LM, then chi-square test and w-test exclusions one at a time.

    Returns ``x, residuals, J, Q (weighted cofactor; times ``chi2 / dof`` for an
    INCONSISTENT problem), used, iterations, chi2, status``; rows in ``fixed`` (bool, (m,)) are never excluded. Problems
    that do not converge or fail the test from ``x0`` are retried once from
    ``x_alt`` (P, n) and keep the better solution. With ``groups`` (int,
    (m,), e.g. the pass of each row) each round excludes the largest
    standardised residual of every group whose largest one exceeds the
    two-sided normal critical value at ``alpha`` (one row per pass at a time
    instead of one in all), also when the chi-square test passes (then at
    ``alpha / n`` for a group of ``n`` rows), and stops when none does. A
    model with a ``leverage(x, idx, w)`` method (k, m) adds the leverage of
    the linear terms it eliminates to the residuals' variance (module
    docstring). Convergence: see
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
        xs, it, conv = _levenberg_marquardt(sub, x[todo], y[todo], w, xtol, max_iter)
        iterations[todo] += it
        pred, J = model(xs, todo, w)
        r = np.where(used[todo], y[todo] - pred, 0.0)
        chi2 = np.einsum("pm,pm->p", w, r * r)
        dof = used[todo].sum(-1) - n_states
        if first and x_alt is not None:
            # A start far away can end in a local minimum: retry those that fail the test from x_alt.
            with np.errstate(invalid="ignore"):
                retry = ~conv | (chi2 > chi2_dist.isf(alpha or _RETRY_ALPHA, np.maximum(dof, 1)))
            if retry.any():
                k = np.flatnonzero(retry)
                sub2 = lambda xs, i, w_, p=todo[k]: model(xs, p[i], w_)  # noqa: E731
                xs2, it2, conv2 = _levenberg_marquardt(sub2, x_alt[todo[k]], y[todo[k]], w[k], xtol, max_iter)
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
        # Ungrouped: exclude only when the sum fails; grouped: test each group's largest row (module docstring).
        can = (fail if groups is None else ok) & (dof >= 2)
        if not can.any():
            break
        p, Jp, Qp = todo[can], J[can], Q[can]
        h_lin = model.leverage(x[p], p, w[can]) if hasattr(model, "leverage") else 0.0
        var_r = sigma[p] ** 2 * (1.0 - h_lin) - np.einsum("pmi,pij,pmj->pm", Jp, Qp, Jp)
        wstat = np.abs(r[can]) / np.sqrt(np.maximum(var_r, _RESIDUAL_VAR_FLOOR * sigma[p] ** 2))
        wstat = np.where(used[p] & ~fixed, wstat, -np.inf)
        if groups is None:
            used[p, np.argmax(wstat, axis=-1)] = False
        else:
            worst = _group_argmax(wstat, groups)
            # A group's largest of n statistics: while the sum passes, tested at alpha / n (Bonferroni).
            n_tested = np.stack([np.isfinite(wstat[:, groups == g]).sum(-1) for g in range(worst.shape[-1])], -1)
            crit = norm_dist.isf(alpha / 2 / np.where(fail[can][:, None], 1, np.maximum(n_tested, 1)))
            take = np.take_along_axis(wstat, np.maximum(worst, 0), -1) > crit
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
        bad &= status == FixStatus.OK
        status[bad] = FixStatus.INCONSISTENT
        # The sigmas do not explain the residuals: scale the covariance by the a-posteriori variance factor.
        Q[bad] *= (chi2[bad] / dof[bad])[:, None, None]
    return x, residuals, J, Q, used, iterations, chi2, status
