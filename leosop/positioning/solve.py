"""From a measurement table to fixes: satellite states, grouping, sigmas, solving.

What ``leosop position`` does, as functions:

1. satellite states from the table's state columns, or from element sets
   with light time (:func:`~leosop.positioning.measurements.sv_states_from_tle`)
   computed for the start position and again for the solution;
2. rows grouped into epochs (snapshot) or taken together (static);
3. rows without ``sigma_hz`` get the caller's sigma, or one estimated from
   the data: a first solve with unit weights, then the robust (MAD) scale of
   its residuals, corrected for the states the fit absorbs;
4. :func:`~leosop.positioning.snapshot.solve_snapshots` or
   :func:`~leosop.positioning.static.solve_static`, with one receiver
   clock per constellation (:func:`~leosop.positioning.measurements.clock_groups`:
   the satellite's family, else its carrier): a snapshot epoch needs
   ``6 + k`` satellites for the k constellations it sees.

Rows that cannot be used and epochs that cannot be solved are reported,
never silently dropped; the rest is still solved.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import InputError
from ..geometry.doppler import N_DOPPLER_STATES
from ..orbits.accuracy import element_set_sigma_rc_m
from ..orbits.constellation import Constellation
from .measurements import Measurements, clock_groups, sv_states_from_tle
from .snapshot import solve_snapshots
from .starts import subpoint_centroid_ecef_m
from .static import solve_static
from .static_passes import SAT_OFFSET_SIGMA_HZ, TIME_OFFSET_SIGMA_S, solve_static_passes

__all__ = ["PositionResult", "position_snapshots", "position_static", "position_static_passes", "satellite_states"]

#: MAD to standard deviation for Gaussian residuals.
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True, eq=False)
class PositionResult:
    """Fixes with the bookkeeping that relates them to the table.

    Attributes
    ----------
    fixes : SnapshotFixes or StaticFix
    t_s : ndarray, (n_ep,)
        Epoch times (snapshot) or the reference time (static, one value).
    time_utc : ndarray of datetime64[ns], (n_ep,), or None
    n_sats : ndarray of int, (n_ep,)
        Satellites with a usable measurement at each epoch (static: distinct
        satellites in the batch).
    rows : ndarray of int, (n_ep, n_sv) or (m,)
        Index into the measurements of each slot of the solver arrays, -1 for padding.
    rejected : list of (int, str)
        Line numbers and reasons of unusable rows (reading and states).
    unsolved : list of (float, datetime64 or None, str)
        Epochs (snapshot) without a fix and why.
    sigma_hz_default : float
        Sigma given to rows without one (estimated when not supplied; with
        several passes the median of the passes' sigmas).
    sv_states : str
        ``"csv"`` or ``"tle"``.
    sigma_hz_pass : ndarray, (n_pass,), or None
        Several passes: the sigma given to each pass's rows without one, in
        the order of ``fixes.pass_ids``.
    clock_labels : tuple of str
        Receiver clocks (constellations) in the order of the fixes' clock
        states (see :func:`~leosop.positioning.measurements.clock_groups`).
    n_need : ndarray of int, (n_ep,), or None
        Snapshot: satellites an epoch needs, ``6 +`` its constellations.
    """

    fixes: object
    t_s: np.ndarray
    time_utc: np.ndarray | None
    n_sats: np.ndarray
    rows: np.ndarray
    rejected: list
    unsolved: list
    sigma_hz_default: float
    sv_states: str
    sigma_hz_pass: np.ndarray | None = None
    clock_labels: tuple = ()
    n_need: np.ndarray | None = None

    def labels(self, alpha: float | None = None) -> tuple[npt.NDArray[np.str_], npt.NDArray[np.float64]]:
        """The status a user filters on (:func:`~leosop.positioning.quality.fix_status`) and the residual
        test's p-value, per fix: ``ok`` only when the toolkit can vouch for the fix.

        ``fixes.status`` is the solver's outcome alone: a converged fix from one pass, or with a mirror
        solution that fits as well, is ``FixStatus.OK`` there and ``single_pass`` or ``ambiguous`` here.

        Parameters
        ----------
        alpha : float, optional
            Significance of the chi-square test (default
            :data:`~leosop.positioning.quality.STATUS_ALPHA`).

        Returns
        -------
        labels : ndarray of str, (n_fix,)
            One per epoch (snapshot fixes) or one (static fixes).
        chi2_p : ndarray, (n_fix,)
        """
        from ..frames import ecef_to_geodetic
        from .quality import fix_status
        from .static import StaticFix
        from .static_passes import PassesFix

        f: Any = self.fixes
        _, _, alt = ecef_to_geodetic(np.asarray(f.pos_ecef_m))
        speed = n_passes = None
        if isinstance(f, PassesFix):
            n_passes = len(f.pass_ids)
        elif isinstance(f, StaticFix):
            n_passes = self.n_sats[0]
        else:
            speed = np.linalg.norm(f.vel_ecef_mps, axis=-1)
        return fix_status(f.status, f.dof, f.chi2, alt, speed, ambiguous=getattr(f, "ambiguous", False),
                          n_passes=n_passes, alpha=alpha)


def satellite_states(meas: Measurements, constellation: Constellation | None = None,
                     pos_rx_ecef_m: npt.ArrayLike | None = None
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.str_], str]:
    """Satellite states per row: the table's columns, else element sets with light time.

    Parameters
    ----------
    meas : Measurements
    constellation : Constellation, optional
        Needed when the table has no state columns.
    pos_rx_ecef_m : array_like, (n, 3) or (3,), optional
        Receiver position for the light time.

    Returns
    -------
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n, 3)
    reason : ndarray of str, (n,)
    source : str
        ``"csv"`` or ``"tle"``.

    Raises
    ------
    InputError
        States from element sets, and no row's satellite has one.
    """
    if meas.pos_sv_ecef_m is not None and meas.vel_sv_ecef_mps is not None:  # the state columns come together
        ok = np.isfinite(meas.pos_sv_ecef_m).all(-1) & np.isfinite(meas.vel_sv_ecef_mps).all(-1)
        reason = np.where(ok, "", "satellite state column is empty or not a number")
        return meas.pos_sv_ecef_m, meas.vel_sv_ecef_mps, reason, "csv"
    if constellation is None:
        raise InputError(f"{meas.source}: no satellite state columns ({', '.join(('x_sv_m', '...'))}); "
                         "give element sets as constellation", param="constellation")
    if meas.time_utc is None:
        raise InputError(f"{meas.source}: satellite states from constellation need a time_utc column "
                         "(the table has t_s)", param="constellation")
    if len(meas) and not np.isin(meas.sat_id, constellation.sat_ids).any():
        ids = np.unique(meas.sat_id)
        shown = ", ".join(ids[:4].tolist()) + (f", ... {ids.size} in all" if ids.size > 4 else "")
        raise InputError(f"{meas.source}: no sat_id of the table ({shown}) has an element set in "
                         f"{constellation.source or 'the element sets'}; give the satellites' element sets as "
                         "constellation", param="constellation")
    pos, vel, reason = sv_states_from_tle(constellation, meas.sat_id, meas.time_utc, pos_rx_ecef_m)
    return pos, vel, reason, "tle"


def _epochs(meas):
    """Epoch index of each row, epoch times, and each row's slot within its epoch."""
    key = meas.time_utc.astype(np.int64) if meas.time_utc is not None else meas.t_s
    _, first, epoch = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(epoch, kind="stable")
    counts = np.bincount(epoch)
    slot = np.empty(len(epoch), dtype=int)
    slot[order] = np.arange(len(epoch)) - np.repeat(np.cumsum(counts) - counts, counts)
    return epoch, first, slot, counts.max()


def _element_set_sigma_rc_m(meas, constellation, usable):
    """Radial and cross-track sigma of each usable row's element set at its age (m, 2); 0 on other rows."""
    sigma = np.zeros((len(meas), 2))
    if usable.any():
        epochs = constellation.epochs_utc[constellation.index_of(meas.sat_id[usable])]
        sigma[usable] = element_set_sigma_rc_m((meas.time_utc[usable] - epochs) / np.timedelta64(1, "D"))
    return sigma


def _robust_sigma(residuals_hz, n_states):
    """Robust scale of least-squares residuals (..., m), corrected for the fitted states."""
    r = residuals_hz[np.isfinite(residuals_hz)]
    n_fits = np.count_nonzero(np.isfinite(residuals_hz).any(-1)) if residuals_hz.ndim > 1 else 1
    if r.size <= n_states * n_fits:
        return np.nan
    mad = np.median(np.abs(r - np.median(r)))
    return float(_MAD_TO_SIGMA * mad * np.sqrt(r.size / (r.size - n_states * n_fits)))


def _clock_groups(meas, constellation, usable):
    """Clock of each row among the constellations of the usable rows, and their labels (see ``clock_groups``)."""
    group, labels = clock_groups(meas, constellation)
    present = np.unique(group[usable])
    remap = np.zeros(len(labels), int)
    remap[present] = np.arange(present.size)
    return remap[group], tuple(labels[i] for i in present) or labels[:1]


def _rejections(meas, reason):
    return list(meas.rejected) + [(int(meas.line[k]), str(reason[k])) for k in np.flatnonzero(reason != "")]


def position_snapshots(meas: Measurements, *, constellation: Constellation | None = None,
                       init_pos_ecef_m: npt.ArrayLike | None = None, sigma_hz: float | None = None,
                       alpha: float | None = 1e-3) -> PositionResult:
    """One snapshot fix per epoch with at least ``6 + k`` usable satellites of k constellations.

    Parameters
    ----------
    meas : Measurements
    constellation : Constellation, optional
        Element sets, when the table has no state columns.
    init_pos_ecef_m : array_like, (3,), optional
        Start position of every epoch; default the ground point below the
        satellites.
    sigma_hz : float, optional
        Sigma of rows without one; default estimated from the residuals.
    alpha : float or None
        Significance of the outlier test.

    Returns
    -------
    PositionResult
    """
    epoch, first, slot, n_sv = _epochs(meas)
    n_ep = len(first)
    rows = np.full((n_ep, n_sv), -1)
    rows[epoch, slot] = np.arange(len(meas))
    pos, vel, reason, source = satellite_states(meas, constellation)
    usable = reason == ""
    mask = (rows >= 0) & usable[np.maximum(rows, 0)]
    n_sats = mask.sum(-1)
    take = lambda a: np.where(mask[..., None] if a.ndim == 2 else mask, a[np.maximum(rows, 0)], np.nan)  # noqa: E731
    r_s, v_s = take(pos), take(vel)
    group, labels = _clock_groups(meas, constellation, usable)
    grp = np.where(mask, group[np.maximum(rows, 0)], -1)
    n_clk = len(labels)
    n_need = 6 + np.array([np.unique(g[g >= 0]).size for g in grp]).clip(min=1)
    # Starts with one clock column: the solver gives it to every receiver clock.
    x0 = np.zeros((n_ep, N_DOPPLER_STATES))
    if init_pos_ecef_m is not None:
        x0[:, :3] = np.asarray(init_pos_ecef_m, float)
    else:
        x0[:, :3] = np.nan_to_num(subpoint_centroid_ecef_m(r_s, mask))
    y, f0 = take(meas.doppler_hz), take(meas.carrier_hz)
    sigma_row = take(meas.sigma_hz)
    enough = n_sats >= n_need
    if not enough.any():
        k = int(np.argmax(n_sats - n_need))
        raise InputError(f"{meas.source}: fewer than {n_need[k]} usable satellites at every epoch (at most "
                         f"{n_sats[k]} where {n_need[k]} are needed); a snapshot fix needs 6 + one per "
                         f"constellation seen ({N_DOPPLER_STATES} for one)")
    # Clock group labels (all clocks, also those absent at an epoch): clock j of the fix is labels[j].
    cg = np.where(mask, np.maximum(grp, 0), 0) if n_clk > 1 else None
    if sigma_hz is None and np.isnan(sigma_row[mask]).any():
        pilot = solve_snapshots(y, np.nan_to_num(sigma_row, nan=1.0), r_s, v_s, f0, mask & enough[:, None], x0,
                                alpha=None, clock_group=cg)
        sigma_hz = _robust_sigma(pilot.residuals_hz[enough], int(np.median(n_need[enough])))
        if not np.isfinite(sigma_hz) or sigma_hz <= 0:
            sigma_hz = 1.0
    sigma_default = float(sigma_hz) if sigma_hz is not None else np.nan
    sigma = np.where(np.isfinite(sigma_row), sigma_row, sigma_default)
    for _ in range(2 if source == "tle" else 1):
        if source == "tle":
            # Light time from the current receiver position of each row's epoch.
            rx = np.where(np.isfinite(x0[epoch, :3]), x0[epoch, :3], 0.0)
            pos, vel, reason, _ = satellite_states(meas, constellation, rx)
            r_s, v_s = take(pos), take(vel)
        fixes = solve_snapshots(y, sigma, r_s, v_s, f0, mask & enough[:, None], x0, alpha=alpha, clock_group=cg)
        solved = np.isfinite(fixes.pos_ecef_m).all(-1)
        x0 = np.where(solved[:, None], np.concatenate(
            [fixes.pos_ecef_m, fixes.vel_ecef_mps, fixes.clock_offset_hz[:, None]], -1), x0)
    t_s = meas.t_s[first]
    time_utc = None if meas.time_utc is None else meas.time_utc[first]
    unsolved = [(float(t_s[k]), None if time_utc is None else time_utc[k],
                 f"only {n_sats[k]} usable satellites, a snapshot fix needs {n_need[k]}"
                 + (f" (6 + {n_need[k] - 6} constellation clocks)" if n_clk > 1 else ""))
                for k in np.flatnonzero(~enough)]
    return PositionResult(fixes, t_s, time_utc, n_sats, rows, _rejections(meas, reason), unsolved,
                          sigma_default, source, clock_labels=labels, n_need=n_need)


def position_static(meas: Measurements, *, constellation: Constellation | None = None,
                    init_pos_ecef_m: npt.ArrayLike | None = None, alt_m: float | None = None,
                    alt_sigma_m: float = 10.0, sigma_hz: float | None = None, alpha: float | None = 1e-3,
                    clock_degree: int | Sequence[int] = (1, 2, 3), side_clock_degree: int = 1) -> PositionResult:
    """One batch fix of a receiver at rest from all rows.

    Parameters
    ----------
    meas : Measurements
    constellation : Constellation, optional
    init_pos_ecef_m : array_like, (3,), optional
        Start position; default three starts on the ground around the
        satellites (see :func:`~leosop.positioning.static.solve_static`).
    alt_m : float, optional
        Known height above the ellipsoid, with standard deviation ``alt_sigma_m``.
    sigma_hz : float, optional
        Sigma of rows without one; default estimated from the residuals.
    alpha : float or None
    clock_degree : int or sequence of int
        Degree(s) of the frequency-offset polynomial of the fix (several:
        chosen by information criterion);
    side_clock_degree : int
        The degree that chooses between the starts' (mirror) solutions; see
        :func:`~leosop.positioning.static.solve_static`. The defaults
        (up to cubic, side chosen with a linear drift) gave the best
        single-pass fixes on the DopTrack passes
        (tools/real_doppler_position.py).

    Returns
    -------
    PositionResult
    """
    pos, vel, reason, source = satellite_states(meas, constellation)
    usable = reason == ""
    group, labels = _clock_groups(meas, constellation, usable)
    n_clk = len(labels)
    n_states = 3 + n_clk * (1 + min(np.atleast_1d(clock_degree).min(), side_clock_degree))
    n_need = n_states - (alt_m is not None)
    if usable.sum() < n_need:
        raise InputError(f"{meas.source}: {usable.sum()} usable measurements, a static fix needs {n_need}"
                         + (f" (first problem: line {meas.line[~usable][0]}: {reason[~usable][0]})"
                            if (~usable).any() and meas.line is not None else ""))
    kw = dict(pos0_ecef_m=init_pos_ecef_m, alt_m=alt_m, alt_sigma_m=alt_sigma_m, mask=usable,
              clock_degree=clock_degree, side_clock_degree=side_clock_degree,
              clock_group=group if len(labels) > 1 else None)
    # Light time is computed for the latest solution (the start at first).
    pos_lt = init_pos_ecef_m
    if sigma_hz is None and np.isnan(meas.sigma_hz[usable]).any():
        pilot = solve_static(meas.doppler_hz, np.nan_to_num(meas.sigma_hz, nan=1.0), pos, vel, meas.carrier_hz,
                             meas.t_s, alpha=None, **kw)
        sigma_hz = _robust_sigma(pilot.residuals_hz, 3 + pilot.clock_polys_hz.size)
        if not np.isfinite(sigma_hz) or sigma_hz <= 0:
            sigma_hz = 1.0
        if np.isfinite(pilot.pos_ecef_m).all():
            pos_lt = pilot.pos_ecef_m
    sigma_default = float(sigma_hz) if sigma_hz is not None else np.nan
    sigma = np.where(np.isfinite(meas.sigma_hz), meas.sigma_hz, sigma_default)
    for _ in range(2 if source == "tle" else 1):
        if source == "tle" and pos_lt is not None:
            pos, vel, reason, _ = satellite_states(meas, constellation, pos_lt)
        fix = solve_static(meas.doppler_hz, sigma, pos, vel, meas.carrier_hz, meas.t_s, alpha=alpha, **kw)
        if np.isfinite(fix.pos_ecef_m).all():
            pos_lt = fix.pos_ecef_m
    t_ref = np.array([fix.t_ref_s])
    time_utc = None if meas.time_utc is None else \
        meas.epoch_utc + np.array([np.round(fix.t_ref_s * 1e9)], dtype="timedelta64[ns]")
    n_sats = np.array([len(np.unique(meas.sat_id[usable]))])
    return PositionResult(fix, t_ref, time_utc, n_sats, np.arange(len(meas)), _rejections(meas, reason), [],
                          sigma_default, source, clock_labels=labels)


def position_static_passes(meas: Measurements, pass_id: npt.ArrayLike, *, constellation: Constellation | None = None,
                           init_pos_ecef_m: npt.ArrayLike | None = None, alt_m: float | None = None,
                           alt_sigma_m: float = 10.0, sigma_hz: float | None = None, alpha: float | None = 1e-3,
                           clock: Literal["per_pass", "common"] = "per_pass", clock_degree: int | None = None,
                           sat_offset_sigma_hz: float = SAT_OFFSET_SIGMA_HZ, time_bias: bool = True,
                           time_bias_sigma_s: float | None = TIME_OFFSET_SIGMA_S,
                           time_offset_model: Literal["inertial", "earth_fixed"] = "inertial",
                           block_id: npt.ArrayLike | None = None,
                           block_sigma_hz: npt.ArrayLike | None = None) -> PositionResult:
    """One batch fix of a receiver at rest from several passes (satellites), frequency terms per pass.

    Rows without ``sigma_hz`` get the caller's sigma, or their own pass's:
    the robust scale of that pass's residuals in a joint solve (passes
    differ in signal-to-noise ratio, and in how well their element sets fit
    the common position). That solve runs twice, first with unit weights,
    then with the first one's sigmas from all starts again: with unit
    weights a noisy pass can pull the choice among the starts to a wrong
    solution whose residuals would then set every sigma.

    Parameters
    ----------
    meas : Measurements
    pass_id : array_like, (n,)
        Pass (satellite track) of each row.
    constellation, init_pos_ecef_m, alt_m, alt_sigma_m, sigma_hz, alpha
        As :func:`position_static`.
    clock, clock_degree, sat_offset_sigma_hz
        Clock model: ``"per_pass"`` (a frequency polynomial per pass, degree
        3 by default) or ``"common"`` (one receiver polynomial, degree 1 by
        default, plus each satellite's constant offset with a prior); see
        :func:`~leosop.positioning.static_passes.solve_static_passes`.
    time_bias, time_bias_sigma_s
        Estimate a time offset of each pass's satellite states (its element
        set's along-track error) with a zero-mean prior (None: no prior).
        States from element sets also put their radial and cross-track
        error at each one's age (:func:`~leosop.orbits.accuracy.element_set_sigma_rc_m`)
        into the covariance, which no residual of one receiver shows.
    time_offset_model : {"inertial", "earth_fixed"}
        What each pass's time offset shifts: the satellite along its inertial
        orbit (an element set's along-track error) or its ECEF states (a
        receiver's time-tag error); see
        :func:`~leosop.positioning.static_passes.solve_static_passes`.
    block_id, block_sigma_hz : array_like, (n,), optional
        Rows sharing a block share a frequency error of this prior sigma [Hz]
        (a receiver LO's phase noise over a snapshot); see
        :func:`~leosop.positioning.static_passes.solve_static_passes`.

    Returns
    -------
    PositionResult
        ``fixes`` is a :class:`~leosop.positioning.static_passes.PassesFix`.
    """
    pass_id = np.asarray(pass_id)
    pos, vel, reason, source = satellite_states(meas, constellation)
    usable = reason == ""
    n_loc = (1 if clock == "common" else 1 + (3 if clock_degree is None else clock_degree))
    if usable.sum() < 3 + n_loc:
        raise InputError(f"{meas.source}: {usable.sum()} usable measurements, a static fix needs {3 + n_loc}")
    group, labels = _clock_groups(meas, constellation, usable)
    if clock != "common":
        labels = ()
    kw = dict(pos0_ecef_m=init_pos_ecef_m, alt_m=alt_m, alt_sigma_m=alt_sigma_m, mask=usable, clock=clock,
              clock_degree=clock_degree, sat_offset_sigma_hz=sat_offset_sigma_hz, time_bias=time_bias,
              time_bias_sigma_s=time_bias_sigma_s, time_offset_model=time_offset_model,
              block_id=block_id, block_sigma_hz=block_sigma_hz, clock_group=group if len(labels) > 1 else None,
              orbit_sigma_rc_m=_element_set_sigma_rc_m(meas, constellation, usable) if source == "tle" else None)
    pos_lt = init_pos_ecef_m
    sigma_pass = None
    if sigma_hz is None and np.isnan(meas.sigma_hz[usable]).any():
        sigma_pilot = np.nan_to_num(meas.sigma_hz, nan=1.0)
        for _ in range(2):
            try:
                pilot = solve_static_passes(meas.doppler_hz, sigma_pilot, pos, vel, meas.carrier_hz, meas.t_s,
                                            pass_id, alpha=None, **kw)
            except InputError as exc:  # the rows' fault: name the table
                raise InputError(f"{meas.source}: {exc}", param=exc.params) from None
            pass_sigmas = np.array([_robust_sigma(pilot.residuals_hz[(pass_id == p) & pilot.used],
                                                  n_loc + bool(time_bias))
                                    for p in pilot.pass_ids])
            pass_sigmas = np.where(np.isfinite(pass_sigmas) & (pass_sigmas > 0), pass_sigmas, 1.0)
            lookup = dict(zip(pilot.pass_ids.tolist(), pass_sigmas))
            sigma_rows = np.array([lookup.get(p, np.nan) for p in pass_id.tolist()])
            sigma_pilot = np.where(np.isfinite(meas.sigma_hz), meas.sigma_hz, np.nan_to_num(sigma_rows, nan=1.0))
        if np.isfinite(pilot.pos_ecef_m).all():
            pos_lt = pilot.pos_ecef_m
            # The pilot searched the starts: the fix starts from its solution and the best other one.
            kw["pos0_ecef_m"] = np.vstack([pilot.pos_ecef_m] + [pilot.mirror_pos_ecef_m] * bool(
                np.isfinite(pilot.mirror_pos_ecef_m).all()))
        sigma_pass = pass_sigmas
        sigma_default = float(np.median(sigma_pass)) if sigma_pass.size else np.nan
    else:
        sigma_default = float(sigma_hz) if sigma_hz is not None else np.nan
        sigma_rows = np.full(len(meas), sigma_default)
    sigma = np.where(np.isfinite(meas.sigma_hz), meas.sigma_hz, sigma_rows)
    for _ in range(2 if source == "tle" else 1):
        if source == "tle" and pos_lt is not None:
            pos, vel, reason, _ = satellite_states(meas, constellation, pos_lt)
        try:
            fix = solve_static_passes(meas.doppler_hz, sigma, pos, vel, meas.carrier_hz, meas.t_s, pass_id,
                                      alpha=alpha, **kw)
        except InputError as exc:
            raise InputError(f"{meas.source}: {exc}", param=exc.params) from None
        if np.isfinite(fix.pos_ecef_m).all():
            pos_lt = fix.pos_ecef_m
    t_ref = fix.t_ref_s
    time_utc = None if meas.time_utc is None else \
        meas.epoch_utc + np.round(t_ref * 1e9).astype("timedelta64[ns]")
    n_sats = np.array([len(np.unique(meas.sat_id[usable]))])
    return PositionResult(fix, t_ref, time_utc, n_sats, np.arange(len(meas)), _rejections(meas, reason), [],
                          sigma_default, source, sigma_pass, clock_labels=labels)
