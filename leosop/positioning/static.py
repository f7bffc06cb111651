"""Static batch Doppler fix: a receiver at rest in ECEF observed over many epochs, one clock polynomial.

State ``[x, y, z, b0, b1, ...]``: frequency offset ``b0`` [Hz] at the
reference time, its drift ``b1`` [Hz/s] and optionally higher polynomial
terms (one polynomial per receiver clock); optionally a known ellipsoidal
height as a pseudo-measurement (the classic Argos-style fix). A single pass
has two solutions, mirror images across the ground track; both are returned.
Solved by :func:`~leosop.positioning.robust_ls.solve_robust` from several
starts across the track.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ..frames import C_e_n, ecef_to_geodetic
from ..geometry.dop import cofactor
from ..geometry.doppler import doppler_jacobian
from .robust_ls import EQUAL_FIT_SIGMAS, XTOL_POS_M, BatchFit, FixStatus, batch_rows, solve_robust
from .starts import track_starts

__all__ = ["StaticFix", "solve_static"]

#: Step thresholds of convergence: 0.1 mm, 10 uHz, 0.1 uHz/s (higher clock terms 0.1 uHz/s divided by
#: powers of the half span).
_XTOL_STATIC = np.array([XTOL_POS_M] * 3 + [1e-5, 1e-7])
#: Cross-track offsets of the default starts, in units of ``start_offset_m``.
_START_FRACTIONS = np.array([0.0, 1 / 6, -1 / 6, 1 / 3, -1 / 3, 0.6, -0.6, 1.0, -1.0])


@dataclass(frozen=True)
class StaticFix(BatchFit):
    """Batch fix of a receiver at rest.

    Attributes
    ----------
    pos_ecef_m : ndarray, (3,)
    clock_offset_hz, clock_drift_hz_per_s : float
        Frequency offset at ``t_ref_s`` and its rate.
    t_ref_s : float
    cov : ndarray, (4 + d, 4 + d)
        Posterior covariance of ``[pos, clock polynomial]`` (d the clock
        degree; 5 x 5 for offset and drift), times ``chi2 / dof`` when
        INCONSISTENT.
    gdop : float
        ``sqrt(trace((H^T H)^-1))`` of the states over the used Doppler rows
        (the height constraint enters with its weight relative to the median
        Doppler weight).
    residuals_hz : ndarray, (m,)
    used : ndarray of bool, (m,)
    n_used, iterations : int
    chi2 : float
    dof : int
        Used rows (and the height pseudo-row) minus states.
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
    # Always set by solve_static; keyword-only so that they need no default after BatchFit's defaults.
    clock_poly_hz: np.ndarray = field(kw_only=True)
    clock_polys_hz: np.ndarray = field(kw_only=True)
    clock_labels: tuple = ()


def solve_static(doppler_hz: npt.ArrayLike, sigma_hz: npt.ArrayLike, pos_sv_ecef_m: npt.ArrayLike,
                 vel_sv_ecef_mps: npt.ArrayLike, carrier_hz: npt.ArrayLike, t_s: npt.ArrayLike, *,
                 pos0_ecef_m: npt.ArrayLike | None = None, alt_m: float | None = None, alt_sigma_m: float = 10.0,
                 mask: npt.ArrayLike | None = None, max_iter: int = 200, alpha: float | None = 1e-3,
                 start_offset_m: float = 1.5e6, ambiguity_m: float = 10e3, clock_degree: int | Sequence[int] = 1,
                 side_clock_degree: int | None = None, clock_group: npt.ArrayLike | None = None) -> StaticFix:
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
    y, sigma, f0, t, r_s, v_s, m = batch_rows(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s,
                                              mask)
    n_rows = y.size
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
    if alt_m is not None:
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
        return solve_robust(model, x0, ys, ss, ms, n_states, xtol=xtol, max_iter=max_iter, alpha=alpha_,
                             fixed=fixed)

    if m[:n_rows].any():
        starts = track_starts(r_s[m[:n_rows]], v_s[m[:n_rows]], pos0_ecef_m, start_offset_m * _START_FRACTIONS)
    else:
        starts = np.zeros((1, 3)) if pos0_ecef_m is None else np.reshape(pos0_ecef_m, (1, 3))
    x0 = np.zeros((len(starts), 3 + n_clk * (1 + deg_side)))
    x0[:, :3] = starts
    # Choose among the starts' solutions on the same rows (before any exclusion), then clean outliers.
    x, res, J, Q, used, iterations, chi2, status = solve(deg_side, x0, None)
    solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    cost = np.where(solved, chi2, np.inf)
    best = int(np.argmin(cost))
    # Solutions that fit as well as the best one (a single pass's mirror image): the start given decides.
    dof = max(int(used[best].sum()) - 3 - n_clk * (1 + deg_side), 1)
    fits = solved & (cost <= cost[best] + EQUAL_FIT_SIGMAS * np.sqrt(2.0 * dof))
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
        xm, _, _, _, _, _, chi2_m, status_m = solve_robust(
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
        iterations=int(iterations[best]), chi2=float(chi2[best]), dof=int(used[best].sum()) - n_states,
        status=FixStatus(int(status[best])),
        ambiguous=ambiguous, clock_poly_hz=polys[0].copy(), mirror_pos_ecef_m=mirror_pos, mirror_chi2=mirror_chi2,
        clock_polys_hz=polys.copy(), clock_labels=tuple(clock_labels.tolist()) if clock_group is not None else (),
    )
