"""Static batch Doppler fix from several passes, each with its own clock terms and time offset.

A receiver at rest in ECEF; each pass (one satellite's track) has frequency
terms (its own polynomial, or a satellite offset on a shared receiver clock)
and optionally a time offset of its satellite states. The linear terms are
eliminated exactly (variable projection, :mod:`~leosop.positioning.passes_model`)
inside :func:`~leosop.positioning.robust_ls.solve_robust`'s iteration.

Three safeguards for real passes (DopTrack, design note):

- A solution from which a pass's satellite would be below the horizon
  (:data:`HORIZON_TOL_DEG`) cannot have received it: among the starts, such
  solutions lose to any that see every used row (a single pass otherwise
  fits a receiver thousands of km away about as well).
- Residuals correlated in time carry fewer independent samples than rows:
  each pass's variance is raised to its residuals' correlation time times
  their mean square where that exceeds its sigma, and the fix solved again
  (``decorrelate``; :mod:`~leosop.positioning.passes_noise`).
- A bias common to a pass (its element set's radial and cross-track error)
  shows only as disagreement between passes: a score test and two variance
  components price it into the covariance, the fix unchanged
  (``pass_offsets``; :mod:`~leosop.positioning.passes_noise`).
"""

from dataclasses import dataclass
from math import comb
from typing import Literal

import numpy as np
import numpy.typing as npt

from ..frames import C_e_n, ecef_to_geodetic
from ..geometry.dop import cofactor
from .passes_model import PassesModel, pass_rows
from .passes_noise import fix_covariance, integrated_autocorrelation, pass_sigma_scale
from .robust_ls import XTOL_POS_M, BatchFit, FixStatus, solve_robust
from .starts import grid_starts, subpoint_centroid_ecef_m

__all__ = ["PassesFix", "solve_static_passes", "integrated_autocorrelation", "TIME_OFFSET_SIGMA_S",
           "TIME_OFFSET_MODELS", "SAT_OFFSET_SIGMA_HZ", "HORIZON_TOL_DEG"]

#: Default prior standard deviation of a pass's time offset of its satellite states [s]: an element
#: set's along-track error of a few hundred metres to a few km at ~7.5 km/s.
TIME_OFFSET_SIGMA_S = 0.5
#: What a pass's time offset ``dt`` shifts. ``"inertial"``: the satellite along its inertial orbit, the
#: Earth not turning with it (an element set's along-track error). ``"earth_fixed"``: the satellite's
#: ECEF states, i.e. the Earth turning with it (a receiver's time-tag error). The two differ by
#: ``omega_e |r| / |v|`` ~ 7 % of the shift, eastward (:func:`~leosop.geometry.doppler.doppler_rate`).
TIME_OFFSET_MODELS = ("inertial", "earth_fixed")
#: Default prior standard deviation of a satellite's own frequency offset, clock "common" [Hz]
#: (Starlink: 0-5 Hz, [Shen 2024] Table 1).
SAT_OFFSET_SIGMA_HZ = 5.0
#: A solution sees a used row's satellite if it is above minus this elevation [deg]: refraction at VHF
#: near the horizon is below 1 deg; the margin also covers a station on a mast or a hill.
HORIZON_TOL_DEG = 2.0


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
        without time biases, none of the blocks' common errors (``block_id``:
        marginalised out). Priors are included. With a mirror solution the
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
        Each pass's time offset [s] when modelled: of the satellite's
        inertial orbit (an along-track error of its element set) or of its
        ECEF states (a time-tag error), per ``time_offset_model``.
    time_offset_model : str
        One of :data:`TIME_OFFSET_MODELS`.
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
        Correlation time of each pass's residuals [rows] (:func:`~leosop.positioning.passes_noise.pass_tau`);
        1 where they are white; None with ``decorrelate=False``.
    sigma_scale : ndarray, (n_pass,), or None
        Factor applied to each pass's sigma, ``sqrt(max(1, tau * mean((r /
        sigma)^2)))``: the variance the correlated residuals imply, never
        below the sigma given; None with ``decorrelate=False``.
    pass_offset_sigma_m : float or None
        Standard deviation of each pass's radial and cross-track satellite
        offset estimated from the passes' disagreement (:mod:`~leosop.positioning.passes_noise`) and
        included in ``cov``; 0 when the disagreement needs none; None with
        ``pass_offsets=False``.
    pass_offset_chi2 : float or None
        The disagreement test's statistic, chi-square with ``pass_offset_dof``
        degrees of freedom when the passes agree.
    pass_offset_dof : int or None
    pass_variance_factor : float or None
        Factor (>= 1) on the covariance that the disagreement implies beside
        the offsets: the maximum-likelihood one times ``dof / (dof - 2)``
        (the Student-t covariance of a factor estimated on ``pass_offset_dof``
        degrees of freedom, :func:`~leosop.positioning.passes_noise.pass_disagreement`);
        1 when none; None with ``pass_offsets=False``.
    """

    pos_ecef_m: np.ndarray
    pass_ids: np.ndarray
    t_ref_s: np.ndarray
    clock_poly_hz: np.ndarray
    time_bias_s: np.ndarray | None = None
    time_offset_model: str = "inertial"
    clock: str = "per_pass"
    rx_clock_poly_hz: np.ndarray | None = None
    rx_t_ref_s: float = np.nan
    sat_offset_hz: np.ndarray | None = None
    rx_clock_polys_hz: np.ndarray | None = None
    clock_labels: tuple = ()
    pass_clock: np.ndarray | None = None
    tau: np.ndarray | None = None
    sigma_scale: np.ndarray | None = None
    pass_offset_sigma_m: float | None = None
    pass_offset_chi2: float | None = None
    pass_offset_dof: int | None = None
    pass_variance_factor: float | None = None

    @property
    def clock_offset_hz(self):
        """Each pass's frequency offset at its ``t_ref_s``, ndarray (n_pass,)."""
        return self.clock_poly_hz[:, 0]

    @property
    def clock_drift_hz_per_s(self):
        """Each pass's frequency drift at its ``t_ref_s``, ndarray (n_pass,)."""
        return self.clock_poly_hz[:, 1] if self.clock_poly_hz.shape[1] > 1 else np.zeros(len(self.pass_ids))


def _shift_poly(coef, shift):
    """Coefficients (..., d + 1) of ``p(s + shift)`` for ``p(s) = sum coef_k s^k``, lowest first."""
    d = coef.shape[-1] - 1
    k = np.arange(d + 1)
    binom = np.array([[comb(j, i) if j >= i else 0 for j in k] for i in k], dtype=float)
    powers = np.asarray(shift, dtype=float)[..., None, None] ** np.maximum(k[None, :] - k[:, None], 0)
    return np.einsum("...j,ij,...ij->...i", coef, binom, powers)


def _sees(pos_ecef_m, pos_sv_ecef_m, used):
    """Whether each solution (k, 3) has every used row's satellite above ``-HORIZON_TOL_DEG``, (k,) bool."""
    lat, lon, _ = ecef_to_geodetic(pos_ecef_m)
    up = C_e_n(lat, lon)[..., 2]
    los = pos_sv_ecef_m[None] - pos_ecef_m[:, None]
    sin_el = np.einsum("kni,ki->kn", los, up) / np.linalg.norm(los, axis=-1)
    return ~((sin_el < np.sin(np.radians(-HORIZON_TOL_DEG))) & used).any(axis=1)


def solve_static_passes(doppler_hz: npt.ArrayLike, sigma_hz: npt.ArrayLike, pos_sv_ecef_m: npt.ArrayLike,
                        vel_sv_ecef_mps: npt.ArrayLike, carrier_hz: npt.ArrayLike, t_s: npt.ArrayLike,
                        pass_id: npt.ArrayLike, *, pos0_ecef_m: npt.ArrayLike | None = None,
                        alt_m: float | None = None, alt_sigma_m: float = 10.0, mask: npt.ArrayLike | None = None,
                        max_iter: int = 4000, alpha: float | None = 1e-3,
                        clock: Literal["per_pass", "common"] = "per_pass", clock_degree: int | None = None,
                        sat_offset_sigma_hz: float = SAT_OFFSET_SIGMA_HZ, time_bias: bool = True,
                        time_bias_sigma_s: float | None = TIME_OFFSET_SIGMA_S, start_offset_m: float = 1.0e6,
                        ambiguity_m: float = 10e3, clock_group: npt.ArrayLike | None = None,
                        decorrelate: bool = True, pass_offsets: bool = True,
                        orbit_sigma_rc_m: npt.ArrayLike | None = None,
                        time_offset_model: Literal["inertial", "earth_fixed"] = "inertial",
                        block_id: npt.ArrayLike | None = None,
                        block_sigma_hz: npt.ArrayLike | None = None) -> PassesFix:
    """Batch Doppler fix of a receiver at rest from several passes (satellites), each with its own frequency terms.

    The position is shared. Each pass ``p`` (one satellite's track) has
    frequency terms and optionally a time offset ``dt_p`` of its satellite's
    states, entering each row through the Doppler rate for such an offset
    (:func:`~leosop.geometry.doppler.doppler_rate`), with a zero-mean prior
    ``time_bias_sigma_s``. By default (``time_offset_model="inertial"``)
    ``dt_p`` stands for the along-track error of the pass's element set: a
    shift along the satellite's inertial orbit, the Earth not turning with
    it. ``"earth_fixed"`` makes it a receiver's time-tag error instead: the
    satellite's ECEF states ``dt_p`` later, the Earth turned with them. The
    two differ by an eastward shift of ``omega_e |r| / |v|`` ~ 7 % of the
    along-track one. On DopTrack's 30 days of real passes (offsets of -2.5
    to +2.2 s) they fit alike: the same residual RMS (median 2.39 Hz), the
    lower chi-square with either model on about half the days, each day's
    fix moved by a median 0.2 km against errors of ~4.5 km (err/sigma median
    0.89 inertial, 0.91 Earth-fixed; all 98 passes 525 m at sigma 553 m
    against 499 m at 505 m; ``tools/real_doppler_position.py
    --time-offset-model both``). The data do not tell them apart, so the
    inertial model, right for the error an element set is known to have,
    stays the default.
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
    position). The iteration stops, after taking it, when the Gauss-Newton
    step is below 0.1 mm or 1e-3 of the posterior sigma along it
    (:func:`~leosop.positioning.robust_ls.solve_robust`). Priors enter as pseudo-rows (never
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
        Per solve: a ceiling, not a budget. A weak geometry (two DopTrack passes, one at 11 deg)
        used to crawl along a flat valley for thousands of iterations; since the damping grows on
        steps that deliver under a quarter of their predicted decrease (``robust_ls``, [More 1978])
        the 30 DopTrack days take 54,378 iterations over all their starts and solves (186,120
        before), none near 4,000.
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
    time_offset_model : {"inertial", "earth_fixed"}
        What ``dt_p`` shifts (:data:`TIME_OFFSET_MODELS`): ``"inertial"``
        the satellite along its inertial orbit (an element set's
        along-track error), ``"earth_fixed"`` its ECEF states (a receiver's
        time-tag error: the satellite is where it was ``dt_p`` later, the
        Earth turned with it).
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
        they imply to the covariance (:mod:`.passes_noise`; the fix itself is
        unchanged).
    orbit_sigma_rc_m : array_like, (2,) or (m, 2), optional
        Radial and cross-track standard deviation of the satellite states'
        error [m] (per row; a pass takes its rows' largest), e.g.
        :func:`~leosop.orbits.accuracy.element_set_sigma_rc_m`: the floor of
        the pass offsets' variance in the covariance (with ``pass_offsets``).
        None: the passes' disagreement alone sets it.
    block_id : array_like, (m,), optional
        Block of each row (any sortable type, e.g. its instant): the rows of
        a block share a frequency error of zero-mean prior sigma
        ``block_sigma_hz``, independent from block to block (a snapshot
        receiver's LO phase noise over the block,
        :func:`~leosop.signal.frontend.wiener_doppler_sigma_hz`). Each block
        gets that state (:mod:`~leosop.positioning.passes_model`): the
        generalised least squares of rows whose covariance within a block is
        ``diag(sigma^2) + q 1 1^T``. The states are marginalised out of
        ``cov``; chi-square and dof count their priors. None: no such states
        (the fix bit-identical to one without the argument).
    block_sigma_hz : array_like, (m,) or scalar, optional
        With ``block_id``: the prior sigma of each row's block [Hz], positive
        (a block takes its largest usable row's).

    Returns
    -------
    PassesFix
    """
    if clock not in ("per_pass", "common"):
        raise ValueError(f"clock {clock!r}: expected 'per_pass' or 'common'")
    if time_offset_model not in TIME_OFFSET_MODELS:
        raise ValueError(f"time_offset_model {time_offset_model!r}: expected one of {TIME_OFFSET_MODELS}")
    common = clock == "common"
    deg = (1 if common else 3) if clock_degree is None else int(clock_degree)
    if deg < 0:
        raise ValueError("clock degree must be non-negative")
    if common and not sat_offset_sigma_hz > 0:
        raise ValueError("sat_offset_sigma_hz must be positive")
    if block_id is not None and not (block_sigma_hz is not None and np.all(np.asarray(block_sigma_hz) > 0)):
        raise ValueError("block_sigma_hz must be positive (and given) with block_id")
    rows = pass_rows(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, pass_id, mask=mask,
                     common=common, deg=deg, time_bias=time_bias, sat_offset_sigma_hz=sat_offset_sigma_hz,
                     time_bias_sigma_s=time_bias_sigma_s, clock_group=clock_group, alt_m=alt_m,
                     alt_sigma_m=alt_sigma_m, time_offset_model=time_offset_model, block_id=block_id,
                     block_sigma_hz=block_sigma_hz)
    model = PassesModel(rows)
    n, m = rows.n, rows.used
    xtol = np.full(3, XTOL_POS_M)

    def solve(x0, used, sigma, alpha_):
        k = len(x0)
        ys, ss, ms = (np.broadcast_to(a, (k, rows.y.size)) for a in (rows.y, sigma, used))
        return solve_robust(model, x0, ys, ss, ms, rows.n_states, xtol=xtol, max_iter=max_iter, alpha=alpha_,
                            fixed=rows.fixed, groups=rows.groups)

    if pos0_ecef_m is not None:
        starts = np.asarray(pos0_ecef_m, dtype=float).reshape(-1, 3)
    elif m[:n].any():
        starts = grid_starts(subpoint_centroid_ecef_m(rows.pos_sv_ecef_m[m[:n]]), start_offset_m)
    else:
        starts = np.zeros((1, 3))
    sigma = rows.sigma
    out = solve(starts, m, sigma, None)
    best, solved, ambiguous, other = _pick_start(out, rows, ambiguity_m)
    x_mirror = out[0][other:other + 1].copy() if other is not None else None
    x, res, J, _, used, iterations, chi2, status = (a[best:best + 1] for a in out)
    if alpha is not None and solved[best]:
        x, res, J, _, used, it, chi2, status = solve(x, used, sigma, alpha)
        iterations = iterations + it
    ok = status[0] in (FixStatus.OK, FixStatus.INCONSISTENT)
    tau, sigma_scale = pass_sigma_scale(rows, res[0, :n], used[0, :n], decorrelate and ok)
    if (sigma_scale > 1.0).any():
        sigma = sigma.copy()  # the solves below and the covariance use the scaled sigmas
        sigma[:n] *= sigma_scale[rows.pass_index]
        x, res, J, _, used, it, chi2, status = solve(x, used, sigma, None)
        iterations = iterations + it
        ok = status[0] in (FixStatus.OK, FixStatus.INCONSISTENT)
    mirror_pos, mirror_chi2 = np.full(3, np.nan), np.nan
    if x_mirror is not None and ok:
        xm, _, _, _, _, _, chi2_m, status_m = solve(x_mirror, used, sigma, None)
        if status_m[0] in (FixStatus.OK, FixStatus.INCONSISTENT):
            mirror_pos, mirror_chi2 = xm[0], float(chi2_m[0])
    w = np.where(used, 1.0 / sigma**2, 0.0)
    cov, offsets, c_g, c_s = fix_covariance(model, x, w, res[0, :n], ok, pass_offsets, orbit_sigma_rc_m)
    if np.isfinite(mirror_chi2):
        # Two solutions: the covariance of the two-point mixture, weights from the chi-square difference.
        w_mirror = 1.0 / (1.0 + np.exp(min(0.5 * (mirror_chi2 - float(chi2[0])), 700.0)))
        d = mirror_pos - x[0]
        cov[:3, :3] += w_mirror * (1.0 - w_mirror) * np.outer(d, d)
    w_rel = np.where(used[0], np.median(sigma[:n][m[:n]]) ** 2 / sigma**2, 0.0) if m[:n].any() \
        else used[0].astype(float)
    gdop = float(np.sqrt(np.trace(cofactor(J[0], w_rel))))
    back = np.empty(n, dtype=int)
    back[rows.order] = np.arange(n)
    fit = {"cov": cov, "gdop": gdop, "residuals_hz": res[0, :n][back], "used": used[0, :n][back],
           "n_used": int(used[0, :n].sum()), "iterations": int(iterations[0]), "chi2": float(chi2[0]),
           "dof": int(used[0].sum()) - rows.n_states, "status": FixStatus(int(status[0])), "ambiguous": ambiguous,
           "mirror_pos_ecef_m": mirror_pos, "mirror_chi2": mirror_chi2, "tau": tau if decorrelate else None,
           "sigma_scale": sigma_scale if decorrelate else None}
    return _passes_fix(rows, x[0], c_g[0], c_s[0], ok, clock, clock_group, offsets, fit)


def _pick_start(out, rows, ambiguity_m):
    """The best of the starts' solutions and whether another fits as well far from it.

    Solutions that see every used row's satellite (:func:`_sees`) win over
    those that do not. Returns ``(best, solved, ambiguous, other)``:
    ``solved`` (k,) bool, ``other`` the best solution beyond ``ambiguity_m``
    (None when none).
    """
    x, _, _, _, used, _, chi2, status = out
    solved = np.isin(status, (FixStatus.OK, FixStatus.INCONSISTENT))
    sees = solved & _sees(x, rows.pos_sv_ecef_m, used[:, :rows.n])
    candidate = sees if sees.any() else solved  # below the horizon only when nothing else converged
    cost = np.where(candidate, chi2, np.inf)
    best = int(np.argmin(cost))
    dof = max(int(used[best].sum()) - rows.n_states, 1)
    fits = candidate & (cost <= cost[best] + 3.0 * np.sqrt(2.0 * dof))
    apart = candidate & (np.linalg.norm(x - x[best], axis=-1) > ambiguity_m)
    ambiguous = bool((fits & apart).any())
    other = int(np.argmin(np.where(apart, cost, np.inf))) if apart.any() else None
    return best, solved, ambiguous, other


def _passes_fix(rows, pos_ecef_m, c_g, c_s, ok, clock, clock_group, offsets, fit):
    """The :class:`PassesFix` from the solution's linear terms (scaled time) and the fit's other fields."""
    common, tb, n_pass = rows.common, rows.time_bias, rows.n_pass
    nan_unless = (lambda a: a if ok else np.full_like(a, np.nan))  # noqa: E731
    scale_glob, scale_loc = rows.scale
    c_loc = c_s * scale_loc
    rx_polys = (c_g * scale_glob).reshape(rows.n_clk, -1)
    rx_poly = rx_polys[0]
    pass_clk = rows.pass_clock
    if common:
        # Each pass's effective polynomial: its receiver clock's about the pass's mid-time, plus its satellite's offset.
        poly = _shift_poly(rx_polys[pass_clk] if rows.n_clk > 1 else np.broadcast_to(rx_poly, (n_pass, rows.deg + 1)),
                           rows.t_ref_s - rows.rx_t_ref_s)
        poly[:, 0] += c_loc[:, 0]
    else:
        poly = c_loc[:, :rows.deg + 1]
    variance_factor, offset_sigma_m, offset_chi2, offset_dof = offsets
    return PassesFix(
        pos_ecef_m=nan_unless(pos_ecef_m), pass_ids=rows.labels, t_ref_s=rows.t_ref_s, clock_poly_hz=nan_unless(poly),
        time_bias_s=nan_unless(c_loc[:, -1].copy()) if tb else None, time_offset_model=rows.time_offset_model,
        clock=clock,
        rx_clock_poly_hz=nan_unless(rx_poly) if common else None,
        rx_t_ref_s=float(rows.rx_t_ref_s) if common else np.nan,
        sat_offset_hz=nan_unless(c_loc[:, 0].copy()) if common else None,
        rx_clock_polys_hz=nan_unless(rx_polys.copy()) if common else None,
        clock_labels=tuple(rows.clock_labels.tolist()) if common and clock_group is not None else (),
        pass_clock=pass_clk.copy() if common else None, pass_offset_sigma_m=offset_sigma_m,
        pass_offset_chi2=offset_chi2, pass_offset_dof=offset_dof, pass_variance_factor=variance_factor, **fit,
    )
