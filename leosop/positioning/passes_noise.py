"""The noise of a multi-pass static fix beyond its white sigmas: correlated residuals, passes that disagree.

Used by :func:`~leosop.positioning.static_passes.solve_static_passes` (DopTrack, design note):

- Residuals correlated in time (unmodelled orbit, clock and ionosphere
  terms vary slowly over a pass) carry fewer independent samples than rows,
  so a white-noise sigma makes the posterior too confident by
  ``sqrt(tau)``, ``tau`` the integrated autocorrelation time of the
  residuals in samples. Each pass's ``tau`` is estimated from its residuals
  (:func:`integrated_autocorrelation`); where it is significantly above 1
  the pass's variance is raised to ``tau`` times its residuals' mean square
  (about ``sqrt(tau)`` on the sigma when the sigma came from the residuals;
  never lowered) and the fix solved again from its solution (the effective-sample-size treatment of an AR/Gauss-Markov
  error; white residuals leave the fix unchanged). ``tau`` is the larger of
  the integrated autocorrelation time and the AR(1) one from the lag-1
  correlation (:func:`pass_tau`).
- A bias common to a pass (its element set's radial and cross-track error;
  the time offset takes the along-track part) shows in no residual of that
  pass: the position absorbs it. It shows only as disagreement between
  passes, so the fix tests for it (``pass_offsets``): each pass's satellite
  offset ``b_p`` (radial, cross-track) enters its rows as ``-H_pos . b_p``;
  with the fix's states eliminated, the offsets' score ``g`` (weighted
  residuals on their columns, :func:`pass_offset_blocks`) has covariance ``F``
  (their information with the states eliminated) when there are none, so
  ``T = g^T F^+ g`` is chi-square with ``rank F`` dof (Rao's score test; it
  needs no solve with the offsets). Two random effects explain an excess: the offsets
  ``~ N(0, s^2 I)`` and a factor ``k2`` on the white sigmas (an error slow
  enough to pass for each pass's own terms, which the residuals'
  correlation time underrates); in F's eigenbasis ``E[z_i^2] = k2 lam_i +
  lam_i^2 s^2``. Both are fitted by maximum likelihood (:func:`pass_disagreement`;
  ``s`` capped at :data:`PASS_OFFSET_MAX_M`), ``k2`` then raised to the
  Student-t covariance of a factor estimated on the test's few degrees of
  freedom (``dof / (dof - 2)`` times the fit, never below 1), and the
  covariance of the fix (unchanged) becomes ``k2 N^-1 + s^2 N^-1 G G^T
  N^-1`` (``G`` the offsets' cross information with the states). Passes
  whose disagreement is likeliest without either leave the covariance
  unchanged, bit for bit. Simulated per-pass offsets of 30 m are found as
  such (``s`` 29 m, ``k2`` 1, position NEES 5.8 on 3 dof); on DopTrack the
  disagreement is a factor (all 98 passes: ``k2`` 4.96, ``s`` 0), which fits
  it better than offsets alone (those would have to be 3 km cross-track, 8
  km on low passes, for 1-2 day old element sets) and leaves each day's fix
  within 3 sigma; over the 23 days of 3-6 passes the horizontal NEES has mean
  2.93 (3.79 with the plug-in factor; tools/doptrack_err_sigma.py,
  docs/notes/few-pass-variance-factor.md).
"""

import numpy as np
from scipy import optimize

from ..geometry.doppler import doppler_jacobian

__all__ = ["PASS_OFFSET_MAX_M", "fix_covariance", "integrated_autocorrelation", "pass_disagreement",
           "pass_offset_blocks", "pass_sigma_scale", "pass_tau"]

#: Largest per-pass satellite offset (radial, cross-track) the passes' disagreement may put into the
#: covariance [m]: element-set radial and cross-track errors of a LEO object are 0.1-0.3 km at epoch
#: (Flohrer et al. 2008, AMOS, TLE accuracy assessment) and grow over the 1-2 days to a pass; the few-pass
#: test cannot tell offsets from other disagreement in its weakly observed directions.
PASS_OFFSET_MAX_M = 1000.0
#: Sokal's window constant: the autocorrelation sum runs to the first lag M >= C tau(M).
_SOKAL_C = 5.0
#: Directions of the pass offsets' information ``F`` kept by the disagreement test, relative to its largest
#: eigenvalue: ``F = M - G^T N^-1 G`` loses ~1e-10 of that to cancellation (negative eigenvalues of
#: -1e-10 on 10 s replays, whose spectrum runs on down to 1e-12), so a cut near it (1e-9 before) kept or
#: dropped a direction on round-off, and a Doppler change of 1e-6 Hz moved ``k2`` by 5 %; 1e-3 of the
#: cut is round-off's reach here.
_RANK_RTOL = 1e-7
#: A pass's sigma is scaled only when its tau exceeds 1 by this many white-noise standard deviations.
_TAU_SIGNIFICANCE = 3.0


def integrated_autocorrelation(residuals, c=_SOKAL_C):
    """Integrated autocorrelation time of a series, with Sokal's automatic window.

    ``tau = 1 + 2 sum_{k=1}^{M} rho_k`` (``rho_k`` the sample autocorrelation
    at lag k, mean removed), M the first lag with ``M >= c tau(M)``: the
    number of rows per independent sample, so that a mean of ``n``
    correlated rows has the variance of ``n / tau`` independent ones. For
    white noise ``tau`` scatters about 1 with standard deviation
    ``2 sqrt(M / n)``.

    Parameters
    ----------
    residuals : array_like, (n,)
        Equally spaced in time (gaps are taken as one step).
    c : float

    Returns
    -------
    tau : float
    M : int
        The window (0 for fewer than 4 values or a constant series: tau 1).
    """
    x = np.asarray(residuals, dtype=float).ravel()
    n = x.size
    x = x - x.mean() if n else x
    if n < 4 or not np.any(x):
        return 1.0, 0
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f), 2 * n)[:n]
    taus = 1.0 + 2.0 * np.cumsum(acf[1:] / acf[0])
    lags = np.arange(1, n)
    reached = lags >= c * taus
    M = int(lags[np.argmax(reached)]) if reached.any() else n - 1
    return float(taus[M - 1]), M


def pass_tau(residuals_hz, used, gi, n_pass):
    """Each pass's residual correlation time [rows], (n_pass,); 1 where the residuals are white.

    The larger of two estimates, each kept only when significantly above 1:
    the integrated autocorrelation time (:func:`integrated_autocorrelation`,
    long-range structure) and that of a first-order Gauss-Markov (AR(1))
    error with the residuals' lag-1 correlation rho, ``(1 + rho) / (1 - rho)``.
    The second matters because the per-pass polynomial absorbs the
    low-frequency part of the noise, which biases the first low (AR(1) with
    tau = 9 on 230 rows: estimated 3-4), while rho is hardly affected.
    """
    tau = np.ones(n_pass)
    for p in range(n_pass):
        r = residuals_hz[(gi == p) & used]
        t, M = integrated_autocorrelation(r)
        if M and t > 1.0 + _TAU_SIGNIFICANCE * 2.0 * np.sqrt(M / r.size):
            tau[p] = t
        x = r - r.mean() if r.size > 3 else np.zeros(1)
        rho = float(x[1:] @ x[:-1] / (x @ x)) if np.any(x) else 0.0
        if rho > _TAU_SIGNIFICANCE / np.sqrt(r.size):
            tau[p] = max(tau[p], (1.0 + rho) / (1.0 - rho))
    return tau


def pass_offset_blocks(pos_sv_ecef_m, vel_sv_ecef_mps, pos_ecef_m, carrier_hz, w, D, B_glob, A, seg, residuals_hz):
    """Information blocks of each pass's (radial, cross-track) satellite offset at the solution.

    A satellite offset ``db`` (ECEF) changes a row's Doppler by ``-H_pos . db``
    (the range rate depends on the difference of the positions), ``H_pos`` the
    receiver position derivative; radial is along the satellite position,
    cross-track along ``r x v`` (ECEF velocity: within a few degrees of the
    orbit normal, enough for a variance). Returns the cross information with
    the fix's states ``G`` (n_states, 2 n_pass; state order of the normal
    matrix: position, global terms, per-pass terms pass-major), the offsets'
    own block ``M`` (2 n_pass, 2 n_pass, block diagonal) and their score
    ``g`` (2 n_pass,), the weighted residuals projected on their columns.
    """
    n_pass = len(seg)
    H = doppler_jacobian(pos_sv_ecef_m, vel_sv_ecef_mps, pos_ecef_m[None], np.zeros((1, 3)), carrier_hz)[0, :, :3]
    e_r = pos_sv_ecef_m / np.linalg.norm(pos_sv_ecef_m, axis=-1, keepdims=True)
    h = np.cross(pos_sv_ecef_m, vel_sv_ecef_mps)
    norm_h = np.linalg.norm(h, axis=-1, keepdims=True)
    e_c = np.divide(h, norm_h, out=np.zeros_like(h), where=norm_h > 0)
    q = -np.stack([np.einsum("mi,mi->m", H, e_r), np.einsum("mi,mi->m", H, e_c)], -1)  # (m, 2)
    wq = w[:, None] * q
    blocks = [np.add.reduceat(a[:, :, None] * wq[:, None, :], seg, axis=0) for a in (D, B_glob, A)]
    n_glob, n_loc = B_glob.shape[1], A.shape[1]
    G = np.zeros((3 + n_glob + n_pass * n_loc, n_pass, 2))
    G[:3] = blocks[0].transpose(1, 0, 2)
    G[3:3 + n_glob] = blocks[1].transpose(1, 0, 2)
    for p in range(n_pass):
        G[3 + n_glob + p * n_loc:3 + n_glob + (p + 1) * n_loc, p] = blocks[2][p]
    M = np.zeros((n_pass, 2, n_pass, 2))
    M[np.arange(n_pass), :, np.arange(n_pass)] = np.add.reduceat(q[:, :, None] * wq[:, None, :], seg, axis=0)
    g = np.add.reduceat(np.where(w[:, None] > 0, wq * residuals_hz[:, None], 0.0), seg, axis=0)
    return G.reshape(-1, 2 * n_pass), M.reshape(2 * n_pass, 2 * n_pass), g.ravel()


def pass_disagreement(F, g):
    """Score test of the passes' disagreement and its two variance components.

    ``F`` is the pass offsets' information with the fix's states eliminated
    (the covariance of their score ``g`` at the fix when the passes agree):
    ``T = g^T F^+ g`` is then chi-square with ``rank F`` degrees of freedom.
    In F's eigenbasis (``z = V^T g``) two departures make ``E[z_i^2] = k2 lam_i
    + s^2 lam_i^2``: white sigmas too small by a factor ``k2`` (an error slow
    enough to pass for each pass's own terms: its variance shows in every
    direction alike) and per-pass radial and cross-track satellite offsets
    ``~ N(0, s^2 I)`` (weighted by ``lam_i`` once more: they show most where
    the passes see them best). Both are fitted by maximum likelihood, ``z``
    Gaussian, ``0 <= s <= PASS_OFFSET_MAX_M``: on a grid, then refined.

    ``z`` is free of the fix's states (a restricted likelihood: REML would
    give the same), so the fitted ``k2`` is not biased low (simulated: within
    7 %); but it rests on ``dof`` values only (6 for three passes), and a
    factor estimated on ``dof`` degrees of freedom makes the fix's error
    Student-t rather than Gaussian: plugged in (a factor alone), the
    horizontal NEES is ``2 F(2, dof)``, mean ``2 dof / (dof - 2)`` (3 at 6
    dof) instead of 2. The factor returned is therefore the fitted one times
    ``dof / (dof - 2)``, the t's covariance (the posterior mean of ``k2``
    under the scale-invariant prior); it is fitted with ``k2 >= (dof - 2) /
    dof`` so that the factor returned is >= 1 (a sigma is never lowered, as
    the Particle Data Group's scale factor) and leaves 1 continuously. At 2
    dof or fewer (one pass) the t has no covariance and the fitted factor is
    returned as it is. Returns ``(k2, s, T, dof)``; ``(1, 0, T, dof)`` when
    the passes agree (their likelihood is largest with ``k2`` at its floor
    and no offsets).
    """
    lam, V = np.linalg.eigh(0.5 * (F + F.T))
    keep = lam > _RANK_RTOL * max(lam[-1], 0.0) if lam.size and lam[-1] > 0 else np.zeros(lam.size, bool)
    lam, z2 = lam[keep], (V[:, keep].T @ g) ** 2
    dof = int(keep.sum())
    if not dof:
        return 1.0, 0.0, 0.0, 0
    T = float(np.sum(z2 / lam))
    t_factor = dof / (dof - 2.0) if dof > 2 else 1.0

    def nll(k2, s):
        v = np.multiply.outer(k2, lam) + np.multiply.outer(s**2, lam**2)
        return 0.5 * np.sum(np.log(v) + z2 / v, axis=-1)

    k2_grid = np.concatenate([[1.0], np.logspace(0.0, 4.0, 161)[1:]]) / t_factor
    s_grid = np.concatenate([[0.0], np.logspace(-1.0, np.log10(PASS_OFFSET_MAX_M), 81)])
    cost = nll(k2_grid[:, None], s_grid[None, :])
    i, j = np.unravel_index(np.argmin(cost), cost.shape)
    if i == 0 and j == 0:
        return 1.0, 0.0, T, dof
    start = [np.log(k2_grid[i]), s_grid[j] / PASS_OFFSET_MAX_M]
    res = optimize.minimize(lambda p: nll(*_disagreement_params(p, k2_grid[0])), start, method="Nelder-Mead",
                            options={"xatol": 1e-4, "fatol": 1e-9})
    k2, s_m = _disagreement_params(res.x, k2_grid[0])
    if nll(k2, s_m) > cost[i, j]:
        k2, s_m = k2_grid[i], s_grid[j]
    return (float(t_factor * k2) if k2 > k2_grid[0] else 1.0), float(s_m), T, dof


def _disagreement_params(p, k2_min):
    """``(k2, s)`` of :func:`pass_disagreement` from its search variables ``(log k2, s / cap)``, inside the bounds."""
    return np.exp(p[0]) if p[0] > np.log(k2_min) else k2_min, min(max(p[1], 0.0), 1.0) * PASS_OFFSET_MAX_M


def pass_sigma_scale(rows, residuals_hz, used, decorrelate):
    """Each pass's correlation time and the factor on its sigma, (n_pass,) each.

    Each correlated pass's variance is raised to tau x its whitened
    residuals' mean square, never lowered: a sigma already above the
    residuals (noise-free or conservative input) is kept, and a pass with
    white residuals (tau = 1) keeps its sigma (its chi-square scatter is no
    evidence). ``decorrelate`` False: tau 1 and no scaling.
    """
    gi, n_pass, n = rows.pass_index, rows.n_pass, rows.n
    tau = pass_tau(residuals_hz, used, gi, n_pass) if decorrelate else np.ones(n_pass)
    z2 = np.bincount(gi, np.where(used, (residuals_hz / rows.sigma[:n]) ** 2, 0.0), n_pass) / \
        np.maximum(np.bincount(gi, used, n_pass), 1)
    return tau, np.where(tau > 1.0, np.sqrt(np.maximum(tau * z2, 1.0)), 1.0)


def fix_covariance(model, x, w, residuals_hz, ok, pass_offsets, orbit_sigma_rc_m):
    """Covariance of ``[pos, global terms, per-pass polynomials or offsets, time biases]`` at the solution.

    The inverse full normal matrix, with the passes' disagreement priced in
    (``pass_offsets``, :func:`pass_disagreement`; ``orbit_sigma_rc_m`` its
    floor), in [Hz/s^k]; the blocks' states marginalised out. Returns ``(cov,
    (variance_factor, offset_sigma_m, offset_chi2, offset_dof), c_g, c_s)``,
    the last two the linear terms at ``x`` in scaled time (``c_g`` the
    receiver clocks' alone).
    """
    rows = model.rows
    n_glob, n_pass, n_loc, n_states = rows.n_glob, rows.n_pass, rows.n_loc, rows.n_states
    n_g = n_glob + rows.n_block
    N, D, A, c_g, c_s = model.normal_matrix(x, w)
    scale_glob, scale_loc = rows.scale
    scale = np.concatenate([np.ones(3), scale_glob, np.ones(rows.n_block), scale_loc.ravel()])
    N_inv = _inverse_or_nan(N) if ok else np.full((n_states, n_states), np.nan)
    offsets = (1.0, 0.0, 0.0, 0) if pass_offsets else (None,) * 4
    if pass_offsets and n_pass and np.isfinite(N_inv).all():
        # Each pass's satellite offset (radial, cross-track) as a random effect the fix does not estimate:
        # its score test, variance component and sandwich term on the covariance (passes_noise).
        G, M_b, g_b = pass_offset_blocks(rows.pos_sv_ecef_m, rows.vel_sv_ecef_mps, x[0], rows.carrier_hz,
                                         w[0, :rows.n], D, rows.B_all, A, rows.seg, residuals_hz)
        offsets = pass_disagreement(M_b - G.T @ N_inv @ G, g_b)
        variance_factor, offset_sigma_m = offsets[:2]
        var_b = np.full((n_pass, 2), offset_sigma_m**2)
        if orbit_sigma_rc_m is not None:
            # The element sets' own accuracy is the floor: the disagreement may show more, never less.
            n = rows.n
            sig_rows = np.broadcast_to(np.asarray(orbit_sigma_rc_m, dtype=float), (n, 2))[rows.order]
            var_b = np.maximum(var_b, np.maximum.reduceat(np.where(rows.used[:n, None], sig_rows, 0.0), rows.seg,
                                                          axis=0) ** 2)
        if variance_factor > 1.0 or var_b.any():
            NG = N_inv @ G
            N_inv = variance_factor * N_inv + (NG * var_b.ravel()) @ NG.T
    cov = N_inv * scale[:, None] * scale[None, :]
    # Reorder to [pos, global terms, per-pass polynomials or offsets, time biases]; the blocks' states dropped.
    loc = 3 + n_g + np.arange(n_pass * n_loc).reshape(n_pass, n_loc)
    n_poly_loc = n_loc - rows.time_bias
    perm = np.concatenate([np.arange(3 + n_glob), loc[:, :n_poly_loc].ravel(), loc[:, n_poly_loc:].ravel()])
    return cov[np.ix_(perm, perm)], offsets, c_g[:, :n_glob], c_s


def _inverse_or_nan(N, rcond=1e-12):
    """Inverse of a symmetric positive semi-definite matrix, judged on its unit-diagonal scaling; NaN if singular."""
    diag = np.diagonal(N)
    d = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    lam, V = np.linalg.eigh(N * d[:, None] * d[None, :])
    if not (diag > 0).all() or lam[0] <= rcond * abs(lam[-1]):
        return np.full(N.shape, np.nan)
    return (V / lam) @ V.T * d[:, None] * d[None, :]
