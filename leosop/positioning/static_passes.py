"""Static batch Doppler fix from several passes, each with its own clock terms and time offset.

A receiver at rest in ECEF; each pass (one satellite's track) has frequency
terms (its own polynomial, or a satellite offset on a shared receiver clock)
and optionally a time offset of its satellite states. The linear terms are
eliminated exactly (variable projection) inside
:func:`~leosop.positioning.robust_ls.solve_robust`'s iteration.

Two safeguards for real passes (DopTrack, design note):

- A solution from which a pass's satellite would be below the horizon
  (:data:`HORIZON_TOL_DEG`) cannot have received it: among the starts, such
  solutions lose to any that see every used row (a single pass otherwise
  fits a receiver thousands of km away about as well).
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
  correlation (:func:`_pass_tau`).
- A bias common to a pass (its element set's radial and cross-track error;
  the time offset takes the along-track part) shows in no residual of that
  pass: the position absorbs it. It shows only as disagreement between
  passes, so the fix tests for it (``pass_offsets``): each pass's satellite
  offset ``b_p`` (radial, cross-track) enters its rows as ``-H_pos . b_p``;
  with the fix's states eliminated, the offsets' score ``g`` (weighted
  residuals on their columns) has covariance ``F`` (their information with
  the states eliminated) when there are none, so ``T = g^T F^+ g`` is
  chi-square with ``rank F`` dof (Rao's score test; it needs no solve with
  the offsets). Two random effects explain an excess: the offsets
  ``~ N(0, s^2 I)`` and a factor ``k2`` on the white sigmas (an error slow
  enough to pass for each pass's own terms, which the residuals'
  correlation time underrates); in F's eigenbasis ``E[z_i^2] = k2 lam_i +
  lam_i^2 s^2``. Both are fitted by maximum likelihood (:func:`_pass_disagreement`;
  ``k2 >= 1``, ``s`` capped at :data:`PASS_OFFSET_MAX_M`) and the
  covariance of the fix (unchanged) becomes ``k2 N^-1 + s^2 N^-1 G G^T
  N^-1`` (``G`` the offsets' cross information with the states). Passes
  whose disagreement is likeliest without either leave the covariance
  unchanged, bit for bit. Simulated per-pass offsets of 30 m are found as
  such (``s`` 29 m, ``k2`` 1, position NEES 5.9 on 3 dof); on DopTrack the
  disagreement is a factor (all 98 passes: ``k2`` 4.7, ``s`` 0), which fits
  it better than offsets alone (those would have to be 3 km cross-track, 8
  km on low passes, for 1-2 day old element sets) and leaves each day's fix
  within 3 sigma (tools/doptrack_err_sigma.py).
"""

from dataclasses import dataclass
from math import comb

import numpy as np
from scipy import optimize

from ..frames import C_e_n, ecef_to_geodetic
from ..geometry.dop import cofactor
from ..geometry.doppler import doppler_jacobian, doppler_rate
from .robust_ls import XTOL_POS_M, BatchFit, FixStatus, batch_rows, solve_robust
from .starts import grid_starts, subpoint_centroid_ecef_m

__all__ = ["PassesFix", "solve_static_passes", "integrated_autocorrelation", "TIME_OFFSET_SIGMA_S",
           "SAT_OFFSET_SIGMA_HZ", "HORIZON_TOL_DEG"]

#: Default prior standard deviation of a pass's time offset of its satellite states [s]: an element
#: set's along-track error of a few hundred metres to a few km at ~7.5 km/s.
TIME_OFFSET_SIGMA_S = 0.5
#: Default prior standard deviation of a satellite's own frequency offset, clock "common" [Hz]
#: (Starlink: 0-5 Hz, [Shen 2024] Table 1).
SAT_OFFSET_SIGMA_HZ = 5.0
#: Fixes also stop when a step is below this fraction of the posterior sigma along it.
_STEP_SIGMA_TOL = 1e-3
#: A solution sees a used row's satellite if it is above minus this elevation [deg]: refraction at VHF
#: near the horizon is below 1 deg; the margin also covers a station on a mast or a hill.
HORIZON_TOL_DEG = 2.0
#: Largest per-pass satellite offset (radial, cross-track) the passes' disagreement may put into the
#: covariance [m]: element-set radial and cross-track errors of a LEO object are 0.1-0.3 km at epoch
#: (Flohrer et al. 2008, AMOS, TLE accuracy assessment) and grow over the 1-2 days to a pass; the few-pass
#: test cannot tell offsets from other disagreement in its weakly observed directions.
PASS_OFFSET_MAX_M = 1000.0
#: Sokal's window constant: the autocorrelation sum runs to the first lag M >= C tau(M).
_SOKAL_C = 5.0
#: A pass's sigma is scaled only when its tau exceeds 1 by this many white-noise standard deviations.
_TAU_SIGNIFICANCE = 3.0


@dataclass(frozen=True)
class PassesFix(BatchFit):
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
        without time biases. Priors are included. With a mirror solution the
        position block is that of the two-point mixture, ``+ w (1 - w) d d^T``
        (``d`` from the fix to the mirror, ``w = 1 / (1 + exp(dchi2 / 2))``):
        a mirror that fits as well (a short low pass) puts the distance
        between the two into the sigma; one that fits far worse adds nothing.
    gdop : float
        ``sqrt(trace((H^T W H)^-1))`` of the position with the clocks
        eliminated, weights relative to the median Doppler weight.
    residuals_hz : ndarray, (m,)
    used : ndarray of bool, (m,)
    n_used, iterations : int
    chi2 : float
        Weighted residual sum of the Doppler rows and the priors' pseudo-rows.
    dof : int
        Used rows and pseudo-rows minus states.
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
    tau : ndarray, (n_pass,), or None
        Correlation time of each pass's residuals [rows] (:func:`_pass_tau`);
        1 where they are white; None with ``decorrelate=False``.
    sigma_scale : ndarray, (n_pass,), or None
        Factor applied to each pass's sigma, ``sqrt(max(1, tau * mean((r /
        sigma)^2)))``: the variance the correlated residuals imply, never
        below the sigma given; None with ``decorrelate=False``.
    pass_offset_sigma_m : float or None
        Standard deviation of each pass's radial and cross-track satellite
        offset estimated from the passes' disagreement (module docstring) and
        included in ``cov``; 0 when the disagreement needs none; None with
        ``pass_offsets=False``.
    pass_offset_chi2 : float or None
        The disagreement test's statistic, chi-square with ``pass_offset_dof``
        degrees of freedom when the passes agree.
    pass_offset_dof : int or None
    pass_variance_factor : float or None
        Factor (>= 1) on the covariance that the disagreement implies beside
        the offsets; 1 when none; None with ``pass_offsets=False``.
    """

    pos_ecef_m: np.ndarray
    pass_ids: np.ndarray
    t_ref_s: np.ndarray
    clock_poly_hz: np.ndarray
    time_bias_s: np.ndarray = None
    clock: str = "per_pass"
    rx_clock_poly_hz: np.ndarray = None
    rx_t_ref_s: float = np.nan
    sat_offset_hz: np.ndarray = None
    rx_clock_polys_hz: np.ndarray = None
    clock_labels: tuple = ()
    pass_clock: np.ndarray = None
    tau: np.ndarray = None
    sigma_scale: np.ndarray = None
    pass_offset_sigma_m: float = None
    pass_offset_chi2: float = None
    pass_offset_dof: int = None
    pass_variance_factor: float = None

    @property
    def clock_offset_hz(self):
        """Each pass's frequency offset at its ``t_ref_s``, ndarray (n_pass,)."""
        return self.clock_poly_hz[:, 0]

    @property
    def clock_drift_hz_per_s(self):
        """Each pass's frequency drift at its ``t_ref_s``, ndarray (n_pass,)."""
        return self.clock_poly_hz[:, 1] if self.clock_poly_hz.shape[1] > 1 else np.zeros(len(self.pass_ids))


def _inverse_or_nan(N, rcond=1e-12):
    """Inverse of a symmetric positive semi-definite matrix, judged on its unit-diagonal scaling; NaN if singular."""
    diag = np.diagonal(N)
    d = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    lam, V = np.linalg.eigh(N * d[:, None] * d[None, :])
    if not (diag > 0).all() or lam[0] <= rcond * abs(lam[-1]):
        return np.full(N.shape, np.nan)
    return (V / lam) @ V.T * d[:, None] * d[None, :]


def _shift_poly(coef, shift):
    """Coefficients (..., d + 1) of ``p(s + shift)`` for ``p(s) = sum coef_k s^k``, lowest first."""
    d = coef.shape[-1] - 1
    k = np.arange(d + 1)
    binom = np.array([[comb(j, i) if j >= i else 0 for j in k] for i in k], dtype=float)
    powers = np.asarray(shift, dtype=float)[..., None, None] ** np.maximum(k[None, :] - k[:, None], 0)
    return np.einsum("...j,ij,...ij->...i", coef, binom, powers)


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


def _pass_tau(residuals_hz, used, gi, n_pass):
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


def _offset_blocks(pos_sv_ecef_m, vel_sv_ecef_mps, pos_ecef_m, carrier_hz, w, D, B_glob, A, seg, residuals_hz):
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


def _pass_disagreement(F, g):
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
    Gaussian, with ``k2 >= 1`` (a sigma is never lowered, as the Particle Data
    Group's scale factor) and ``0 <= s <= PASS_OFFSET_MAX_M``: on a grid, then
    refined. Returns ``(k2, s, T, dof)``; ``(1, 0, T, dof)`` when the passes
    agree (their likelihood is largest without either).
    """
    lam, V = np.linalg.eigh(0.5 * (F + F.T))
    keep = lam > 1e-9 * max(lam[-1], 0.0) if lam.size and lam[-1] > 0 else np.zeros(lam.size, bool)
    lam, z2 = lam[keep], (V[:, keep].T @ g) ** 2
    dof = int(keep.sum())
    if not dof:
        return 1.0, 0.0, 0.0, 0
    T = float(np.sum(z2 / lam))

    def nll(k2, s):
        v = np.multiply.outer(k2, lam) + np.multiply.outer(s**2, lam**2)
        return 0.5 * np.sum(np.log(v) + z2 / v, axis=-1)

    k2_grid = np.concatenate([[1.0], np.logspace(0.0, 4.0, 161)[1:]])
    s_grid = np.concatenate([[0.0], np.logspace(-1.0, np.log10(PASS_OFFSET_MAX_M), 81)])
    cost = nll(k2_grid[:, None], s_grid[None, :])
    i, j = np.unravel_index(np.argmin(cost), cost.shape)
    if i == 0 and j == 0:
        return 1.0, 0.0, T, dof
    start = [np.log(k2_grid[i]), s_grid[j] / PASS_OFFSET_MAX_M]
    res = optimize.minimize(lambda p: nll(*_disagreement_params(p)), start, method="Nelder-Mead",
                            options={"xatol": 1e-4, "fatol": 1e-9})
    k2, s_m = _disagreement_params(res.x)
    if nll(k2, s_m) > cost[i, j]:
        k2, s_m = k2_grid[i], s_grid[j]
    return float(k2), float(s_m), T, dof


def _disagreement_params(p):
    """``(k2, s)`` of :func:`_pass_disagreement` from its search variables ``(log k2, s / cap)``, inside the bounds."""
    return np.exp(max(p[0], 0.0)), min(max(p[1], 0.0), 1.0) * PASS_OFFSET_MAX_M


def _sees(pos_ecef_m, pos_sv_ecef_m, used):
    """Whether each solution (k, 3) has every used row's satellite above ``-HORIZON_TOL_DEG``, (k,) bool."""
    lat, lon, _ = ecef_to_geodetic(pos_ecef_m)
    up = C_e_n(lat, lon)[..., 2]
    los = pos_sv_ecef_m[None] - pos_ecef_m[:, None]
    sin_el = np.einsum("kni,ki->kn", los, up) / np.linalg.norm(los, axis=-1)
    return ~((sin_el < np.sin(np.radians(-HORIZON_TOL_DEG))) & used).any(axis=1)


def solve_static_passes(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, pass_id, *,
                        pos0_ecef_m=None, alt_m=None, alt_sigma_m=10.0, mask=None, max_iter=4000, alpha=1e-3,
                        clock="per_pass", clock_degree=None, sat_offset_sigma_hz=SAT_OFFSET_SIGMA_HZ,
                        time_bias=True, time_bias_sigma_s=TIME_OFFSET_SIGMA_S, start_offset_m=1.0e6,
                        ambiguity_m=10e3, clock_group=None, decorrelate=True, pass_offsets=True,
                        orbit_sigma_rc_m=None):
    """Batch Doppler fix of a receiver at rest from several passes (satellites), each with its own frequency terms.

    The position is shared. Each pass ``p`` (one satellite's track) has
    frequency terms and optionally a time offset ``dt_p`` of its satellite
    states (to first order the along-track error of its element set, or a
    time-tag offset), entering each row through the Doppler rate
    (:func:`~leosop.geometry.doppler.doppler_rate`), with a zero-mean prior
    ``time_bias_sigma_s``.
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
    excluded one row per pass at a time (see
    :func:`~leosop.positioning.robust_ls.solve_robust`).

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
        Per solve. A weak geometry (two DopTrack passes, one at 11 deg) crawls
        along a flat valley: 2020-04-02 takes ~1,800 iterations over its solves (with 1,000 it
        ended NOT_CONVERGED; 2,259 in all with 4,000).
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
    decorrelate : bool
        Raise each pass's variance to its residuals' correlation time times
        their mean square where that exceeds the sigma given (module
        docstring), and solve again.
    pass_offsets : bool
        Test the passes for a common offset of each one's satellite states
        (radial and cross-track, the element-set errors the time offsets do
        not take up) and, where the test is significant, add the variance
        they imply to the covariance (module docstring; the fix itself is
        unchanged).
    orbit_sigma_rc_m : array_like, (2,) or (m, 2), optional
        Radial and cross-track standard deviation of the satellite states'
        error [m] (per row; a pass takes its rows' largest), e.g.
        :func:`~leosop.orbits.accuracy.element_set_sigma_rc_m`: the floor of
        the pass offsets' variance in the covariance (with ``pass_offsets``).
        None: the passes' disagreement alone sets it.

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
    y, sigma, f0, t, r_s, v_s, m = batch_rows(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s,
                                              mask)
    n = y.size
    labels, gi = np.unique(np.asarray(pass_id).ravel(), return_inverse=True)
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
    xtol = np.full(3, XTOL_POS_M)

    def solve(x0, used, alpha_):
        k = len(x0)
        ys, ss, ms = (np.broadcast_to(a, (k, y.size)) for a in (y, sigma, used))
        return solve_robust(model, x0, ys, ss, ms, n_states, xtol=xtol, max_iter=max_iter, alpha=alpha_,
                             fixed=fixed, groups=groups, step_sigma_tol=_STEP_SIGMA_TOL)

    if pos0_ecef_m is not None:
        starts = np.asarray(pos0_ecef_m, dtype=float).reshape(-1, 3)
    elif m[:n].any():
        starts = grid_starts(subpoint_centroid_ecef_m(r_s[m[:n]]), start_offset_m)
    else:
        starts = np.zeros((1, 3))
    x, res, J, Q, used, iterations, chi2, status = solve(starts, m, None)
    solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    sees = solved & _sees(x, r_s, used[:, :n])
    candidate = sees if sees.any() else solved  # below the horizon only when nothing else converged
    cost = np.where(candidate, chi2, np.inf)
    best = int(np.argmin(cost))
    dof = max(int(used[best].sum()) - n_states, 1)
    fits = candidate & (cost <= cost[best] + 3.0 * np.sqrt(2.0 * dof))
    apart = candidate & (np.linalg.norm(x - x[best], axis=-1) > ambiguity_m)
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
    tau = _pass_tau(res[0, :n], used[0, :n], gi, n_pass) if decorrelate and ok else np.ones(n_pass)
    # Each correlated pass's variance raised to tau x its whitened residuals' mean square, never
    # lowered: a sigma already above the residuals (noise-free or conservative input) is kept, and
    # a pass with white residuals (tau = 1) keeps its sigma (its chi-square scatter is no evidence).
    z2 = np.bincount(gi, np.where(used[0, :n], (res[0, :n] / sigma[:n]) ** 2, 0.0), n_pass) / \
        np.maximum(np.bincount(gi, used[0, :n], n_pass), 1)
    sigma_scale = np.where(tau > 1.0, np.sqrt(np.maximum(tau * z2, 1.0)), 1.0)
    if (sigma_scale > 1.0).any():
        sigma = sigma.copy()  # the solves below and the covariance use the scaled sigmas
        sigma[:n] *= sigma_scale[gi]
        x, res, J, Q, used, it, chi2, status = solve(x, used, None)
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
    N_inv = _inverse_or_nan(N) if ok else np.full((n_states, n_states), np.nan)
    variance_factor, offset_sigma_m, offset_chi2, offset_dof = (1.0, 0.0, 0.0, 0) if pass_offsets else (None,) * 4
    if pass_offsets and n_pass and np.isfinite(N_inv).all():
        # Each pass's satellite offset (radial, cross-track) as a random effect the fix does not estimate:
        # its score test, variance component and sandwich term on the covariance (module docstring).
        G, M_b, g_b = _offset_blocks(r_s, v_s, x[0], f0, wd, D, B_glob, A, seg, res[0, :n])
        variance_factor, offset_sigma_m, offset_chi2, offset_dof = _pass_disagreement(M_b - G.T @ N_inv @ G, g_b)
        var_b = np.full((n_pass, 2), offset_sigma_m**2)
        if orbit_sigma_rc_m is not None:
            # The element sets' own accuracy is the floor: the disagreement may show more, never less.
            sig_rows = np.broadcast_to(np.asarray(orbit_sigma_rc_m, dtype=float), (n, 2))[order]
            var_b = np.maximum(var_b, np.maximum.reduceat(np.where(m[:n, None], sig_rows, 0.0), seg, axis=0) ** 2)
        if variance_factor > 1.0 or var_b.any():
            NG = N_inv @ G
            N_inv = variance_factor * N_inv + (NG * var_b.ravel()) @ NG.T
    cov = N_inv * scale[:, None] * scale[None, :]
    # Reorder to [pos, global terms, per-pass polynomials or offsets, time biases].
    loc = 3 + n_glob + np.arange(n_pass * n_loc).reshape(n_pass, n_loc)
    n_poly_loc = n_loc - tb
    perm = np.concatenate([np.arange(3 + n_glob), loc[:, :n_poly_loc].ravel(), loc[:, n_poly_loc:].ravel()])
    cov = cov[np.ix_(perm, perm)]
    if np.isfinite(mirror_chi2):
        # Two solutions: the covariance of the two-point mixture, weights from the chi-square difference.
        w_mirror = 1.0 / (1.0 + np.exp(min(0.5 * (mirror_chi2 - float(chi2[0])), 700.0)))
        d = mirror_pos - x[0]
        cov[:3, :3] += w_mirror * (1.0 - w_mirror) * np.outer(d, d)
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
        iterations=int(iterations[0]), chi2=float(chi2[0]), dof=int(used[0].sum()) - n_states,
        status=FixStatus(int(status[0])),
        ambiguous=ambiguous, mirror_pos_ecef_m=mirror_pos, mirror_chi2=mirror_chi2,
        time_bias_s=nan_unless(c_loc[:, -1].copy()) if tb else None, clock=clock,
        rx_clock_poly_hz=nan_unless(rx_poly) if common else None, rx_t_ref_s=float(t_rx) if common else np.nan,
        sat_offset_hz=nan_unless(c_loc[:, 0].copy()) if common else None,
        rx_clock_polys_hz=nan_unless(rx_polys.copy()) if common else None,
        clock_labels=tuple(clock_labels.tolist()) if common and clock_group is not None else (),
        pass_clock=pass_clk.copy() if common else None, tau=tau if decorrelate else None,
        sigma_scale=sigma_scale if decorrelate else None, pass_offset_sigma_m=offset_sigma_m,
        pass_offset_chi2=offset_chi2, pass_offset_dof=offset_dof, pass_variance_factor=variance_factor,
    )
