"""Which satellite is this comb? Doppler tracks identified against a TLE snapshot.

The unknowns are the receiver position (a prior within ~100 km, or none),
the receiver's common frequency offset and its drift (the LNB's local
oscillator error, kHz to MHz, and the SDR's clock: common to all tracks),
each satellite's own small frequency offset and each element set's
along-track error (a time offset of its predicted Doppler curve). The
common offset and drift are nuisance parameters searched over
``+-lo_offset_max_hz`` and ``+-lo_drift_max_hz_per_s``: the differences
between tracks' Doppler curves do not depend on the offset, nor (to first
order) on the drift, so the search costs about as much at 3 MHz as at
25 kHz. The search runs in three stages:

1. **Cell vote.** The receiver position is searched on cells (a local grid
   round the prior, or a Fibonacci grid of the whole Earth without one).
   Every track gives three features at three reference times (first, middle
   and last): the Doppler offset at the middle, the slope and the curvature
   of the residual "measured minus predicted". Slope and curvature do not
   depend on the clock offset; the offset is the clock, common to all
   tracks. A (cell, track, candidate) triple passes when its slope and
   curvature are within tolerance; it then votes for the clock offsets
   within its offset tolerance. A cell's score is the number of tracks that
   agree on one clock offset. Tolerances are first-order bounds: the
   Doppler's gradient with respect to the receiver position times the cell
   radius, the Doppler rate times the largest along-track time error, the
   clock drift, and the measurement noise. The best cells are split 3 x 3
   and voted again, down to ~1 km.
2. **Joint least squares** on the best cells' tentative assignment:
   position, clock offset and drift, a frequency offset and a time offset
   per satellite (with priors), tracks that do not fit dropped one by one.
3. **Identification** at the solution: every candidate above the mask is
   fitted to every track (its own offset and time offset, with priors); the
   best is accepted only when its chi-square is consistent with the
   track's sigma (inflated for model and position errors) and clearly below
   the runner-up's; else ``sat_id`` is None. A satellite claimed by two
   tracks goes to the longer one (then the better fit). Each track gets a status (``ok`` only
   when the identity is vouched for, :data:`~leosop.replay.match.ID_STATUSES`):
   a track that another solution (another cell, another offset) identifies
   differently under the same tests is ``conflicting_solution``.

Satellite states come from one SGP4 propagation of every satellite on a
coarse time grid, interpolated by cubic Hermite polynomials (position and
velocity at the nodes); the light time is applied as in
:func:`leosop.positioning.measurements.sv_states_from_tle` (state at the
transmit time, rotated into the ECEF frame of the reception time) in stages
2 and 3, and bounded by a 10 ms time tolerance in stage 1. This is the
familiar Doppler-positioning problem [Kassas 2019] with unknown data
association, solved by voting over a position grid before refining.
"""

import time
from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS
from ..errors import InputError
from ..frames import ecef_to_geodetic
from ..positioning.measurements import DEFAULT_CARRIER_HZ
from .cellvote import CellSearch, fibonacci_cells, grid_around
from .ephemeris import Ephemeris
from .features import prepare_track
from .jointfit import solve
from .lo import LO_DRIFT_MAX_HZ_PER_S, LO_OFFSET_MAX_HZ
from .match import ID_STATUSES, accept, match

__all__ = ["ID_STATUSES", "LO_DRIFT_MAX_HZ_PER_S", "LO_OFFSET_MAX_HZ", "Identification", "identify_tracks"]


@dataclass
class Identification:
    """What :func:`identify_tracks` found.

    Attributes
    ----------
    sat_id : list of (str or None), (n_tracks,)
        NORAD number per track (None unless ``status`` is ``ok``).
    status : list of str, (n_tracks,)
        ``ok`` when the identity is vouched for, else why not (:data:`ID_STATUSES`).
    match_rms_hz : ndarray, (n_tracks,)
        RMS Doppler residual of the identified satellite (NaN for None).
    margin : ndarray, (n_tracks,)
        Chi-square of the runner-up minus that of the best candidate (NaN
        when no candidate fitted).
    runner_up_id : list of (str or None), (n_tracks,)
    pos_ecef_m : ndarray, (3,)
        Receiver position of the search (a start for the fix); NaN if none.
    pos_cov_m2 : ndarray, (3, 3)
    lo_offset_hz, lo_drift_hz_per_s : float
        The receiver's common frequency offset (Doppler of the central tone;
        with the satellites' mean offset, which nothing separates from it)
        at ``t_ref_utc``, and its drift; NaN without a solution.
    lo_offset_sigma_hz, lo_drift_sigma_hz_per_s : float
        Their 1-sigma from the joint least squares.
    t_ref_utc : numpy.datetime64
    lo_offset_max_hz, lo_drift_max_hz_per_s : float
        The bounds searched.
    n_candidates : int
        Satellites considered.
    elapsed_s : float
    """

    sat_id: list
    status: list
    match_rms_hz: np.ndarray
    margin: np.ndarray
    runner_up_id: list
    pos_ecef_m: np.ndarray
    pos_cov_m2: np.ndarray
    lo_offset_hz: float
    lo_offset_sigma_hz: float
    lo_drift_hz_per_s: float
    lo_drift_sigma_hz_per_s: float
    t_ref_utc: np.datetime64
    lo_offset_max_hz: float
    lo_drift_max_hz_per_s: float
    n_candidates: int = 0
    elapsed_s: float = 0.0


#: Options of :func:`identify_tracks` (``**options``) and their defaults:
#: ``mask_slack_deg`` / ``id_mask_slack_deg`` lower the mask for the search / the identification
#: (the position is not known yet); ``cross_track_max_m``, ``along_track_max_m`` bound the element
#: errors, ``along_track_sigma_m`` is the prior of the fitted time offsets; ``alt_tol_m`` the
#: height error of the cells, ``alt_sigma_m`` its prior in the least squares; ``sat_offset_max_hz``
#: / ``sat_offset_sigma_hz`` bound and weigh the satellites' own offsets; ``model_sigma_hz`` is
#: added to every track's sigma; ``track_gate`` (normalised RMS) drops a track from the least
#: squares; ``false_alarm`` sets the chi-square acceptance, ``min_margin`` the chi-square lead over
#: the runner-up; ``pos_sigma_cap_hz`` caps the fix-uncertainty inflation; ``min_identified`` is the
#: fewest identities a solution must give; ``final_spacing_m`` ends the cell refinement and
#: ``n_final`` cells go on to the least squares; ``rx_speed_sigma_mps`` > 0 makes the receiver
#: move at a constant velocity estimated in the least squares (horizontal prior sigma; vertical
#: ``rx_climb_sigma_mps``), 0 holds it static.
_DEFAULTS = {
    "mask_slack_deg": 5.0, "id_mask_slack_deg": 2.0, "cross_track_max_m": 300.0, "alt_tol_m": 1000.0,
    "along_track_max_m": 1500.0, "along_track_sigma_m": 600.0, "sat_offset_max_hz": 30.0,
    "sat_offset_sigma_hz": 8.0, "model_sigma_hz": 1.0, "alt_sigma_m": 300.0, "track_gate": 4.0,
    "false_alarm": 1e-4, "min_margin": 25.0, "final_spacing_m": 1500.0, "n_final": 3, "pos_sigma_cap_hz": 3.0,
    "min_identified": 3, "rx_speed_sigma_mps": 0.0, "rx_climb_sigma_mps": 2.0,
}


def identify_tracks(tracks, constellation, *, init_pos_ecef_m=None, mask_deg=10.0, carrier_hz=DEFAULT_CARRIER_HZ,
                    lo_offset_max_hz=LO_OFFSET_MAX_HZ, lo_drift_max_hz_per_s=LO_DRIFT_MAX_HZ_PER_S,
                    prior_radius_m=150e3, alt_m=None, global_spacing_m=150e3, keep_cells=None, threads=1,
                    **options):
    """Identify Doppler tracks against element sets; sets ``track.sat_id`` and ``track.match_rms_hz`` in place.

    Parameters
    ----------
    tracks : list of Track
        ``time_utc``, ``doppler_hz`` and ``sigma_hz`` are used.
    constellation : Constellation
        Candidates (e.g. a 10,000-satellite Starlink snapshot).
    init_pos_ecef_m : array_like, (3,), optional
        Prior receiver position, within ``prior_radius_m``; None: global search.
    mask_deg : float
        Elevation mask of the candidates.
    carrier_hz : float
        Carrier of ``doppler_hz``.
    lo_offset_max_hz : float
        Largest common receiver offset searched, +- (:data:`LO_OFFSET_MAX_HZ`).
    lo_drift_max_hz_per_s : float
        Largest drift of that offset, +- (:data:`LO_DRIFT_MAX_HZ_PER_S`).
    prior_radius_m : float
        Horizontal radius searched round the prior.
    alt_m : float, optional
        Receiver height; default that of the prior, or 0 without one.
    global_spacing_m : float
        First cell spacing of the global search.
    keep_cells : int, optional
        Cells kept per refinement level (default 40 with a prior, 300 without).
    threads : int
        Threads of the cell vote (:class:`~leosop.replay.cellvote.CellSearch`); the same result whatever N.
    **options
        Tolerances and thresholds; see ``_DEFAULTS`` in this module.

    Returns
    -------
    Identification
        Also written into the tracks: ``sat_id`` (None unless vouched for),
        ``match_rms_hz`` (None when unidentified) and ``id_status``.

    Notes
    -----
    With a prior: ~1 s for 5-8 tracks against 10,138 satellites. Without:
    the whole Earth on ~23,000 cells of 150 km first: 24 s of CPU for the
    bundled recording against its 4,408 satellites (``tools/bench_identify.py
    --replay``); the same at a 3 MHz offset bound (``tools/bench_lo_offset.py``).
    """
    start = time.perf_counter()
    opts = _options(options, mask_deg, lo_offset_max_hz, lo_drift_max_hz_per_s)
    n_tr = len(tracks)
    t_all = np.concatenate([np.asarray(tr.time_utc, "datetime64[ns]") for tr in tracks]) if tracks else None
    t0 = t_all.min() if tracks else np.datetime64("NaT", "ns")
    prepared = [prepare_track(tr, t0) for tr in tracks]
    live = [k for k, p in enumerate(prepared) if p is not None]
    result = Identification([None] * n_tr, ["too_short"] * n_tr, np.full(n_tr, np.nan), np.full(n_tr, np.nan),
                            [None] * n_tr, np.full(3, np.nan), np.full((3, 3), np.nan), np.nan, np.nan, np.nan,
                            np.nan, t0, opts["lo_offset_max_hz"], opts["lo_drift_max_hz_per_s"])
    if live:
        eph = Ephemeris(constellation, t0, float((t_all.max() - t0) / np.timedelta64(1, "s")))
        prior = None if init_pos_ecef_m is None else np.asarray(init_pos_ecef_m, float).reshape(3)
        opts["alt_m"] = (0.0 if prior is None else float(ecef_to_geodetic(prior)[2])) if alt_m is None else float(alt_m)
        region = None if prior is None else (prior, 1.5 * prior_radius_m)
        search = CellSearch([prepared[k] for k in live], eph, float(carrier_hz) / C_MPS, opts, region, threads)
        if prior is not None:
            finals = search.search_cells(_prior_cells(prior, prior_radius_m, opts["alt_m"]), prior_radius_m / 5,
                                         keep_cells or 40)
        else:
            finals = search.search_cells(fibonacci_cells(global_spacing_m, opts["alt_m"]), global_spacing_m * 1.1,
                                         keep_cells or 300)
        solutions = _solutions(search, finals, prior_radius_m if prior is not None else 20e3)
        result.n_candidates = int(eph.ok.sum())
        _fill(result, live, search, solutions, constellation, t0)
    result.elapsed_s = time.perf_counter() - start
    for tr, sid, rms, status in zip(tracks, result.sat_id, result.match_rms_hz, result.status):
        tr.sat_id = sid
        tr.match_rms_hz = None if sid is None else float(rms)
        tr.id_status = status
    return result


def _options(options, mask_deg, lo_offset_max_hz, lo_drift_max_hz_per_s):
    """The search's options: ``_DEFAULTS`` updated by ``options``, the bounds checked."""
    unknown = set(options) - set(_DEFAULTS)
    if unknown:
        raise InputError(f"identify_tracks: unknown option(s) {', '.join(sorted(unknown))}")
    if not (np.isfinite(lo_offset_max_hz) and lo_offset_max_hz > 0):
        raise InputError(f"lo_offset_max_hz={lo_offset_max_hz!r}: expected a positive number")
    if not (np.isfinite(lo_drift_max_hz_per_s) and lo_drift_max_hz_per_s >= 0):
        raise InputError(f"lo_drift_max_hz_per_s={lo_drift_max_hz_per_s!r}: expected a number >= 0")
    return {**_DEFAULTS, **options, "mask_deg": float(mask_deg), "lo_offset_max_hz": float(lo_offset_max_hz),
            "lo_drift_max_hz_per_s": float(lo_drift_max_hz_per_s)}


def _prior_cells(prior, radius_m, alt_m):
    """A square grid of spacing ``radius_m / 5`` within ``radius_m`` of the prior, (n, 3)."""
    spacing = radius_m / 5
    n = int(np.ceil(radius_m / spacing))
    grid = spacing * np.array([(e, m) for e in range(-n, n + 1) for m in range(-n, n + 1)], float)
    grid = grid[np.hypot(grid[:, 0], grid[:, 1]) <= radius_m + spacing / 2]
    return grid_around(prior[None, :], grid, alt_m)


def _solutions(search, finals, prior_sigma_m):
    """Joint fit and identification at each final cell, best first.

    Returns
    -------
    list of (sol, ids, sat, status), ordered by identified tracks, then chi-square.
    """
    out = []
    for cell, assign, clock in finals:
        sol = solve(search, cell, assign, clock, prior_sigma_m)
        if sol is None:
            continue
        for _ in range(2):  # identify, re-solve on the accepted identities, identify again
            ids = match(search, sol)
            sat, status = accept(search, ids)
            if (sat >= 0).sum() < 2:
                break
            again = solve(search, sol["pos"], sat, sol["clock"], prior_sigma_m)
            if again is None:
                break
            sol = again
        out.append((sol, ids, sat, status))
    score = lambda o: ((o[2] >= 0).sum(), -sum(o[1][k]["chi2"] for k in np.flatnonzero(o[2] >= 0)))  # noqa: E731
    return sorted(out, key=score, reverse=True)


def _fill(result, live, search, solutions, constellation, t0):
    """Write the best solution into ``result``; tracks another accepted solution names otherwise conflict."""
    if not solutions:
        for k in live:
            result.status[k] = "no_solution"
        return
    sol, ids, sat, status = solutions[0]
    sat = sat.copy()
    for _, _, other, _ in solutions[1:]:
        clash = (sat >= 0) & (other >= 0) & (other != sat)
        status[clash], sat[clash] = "conflicting_solution", -1
    result.pos_ecef_m, result.pos_cov_m2 = sol["pos"], sol["cov"]
    result.lo_offset_hz, result.lo_drift_hz_per_s = float(sol["clock"]), float(sol["drift"])
    result.lo_offset_sigma_hz, result.lo_drift_sigma_hz_per_s = sol["clock_sigma"], sol["drift_sigma"]
    result.t_ref_utc = t0 + np.timedelta64(int(round(search.t_c * 1e9)), "ns")
    for j, k in enumerate(live):
        d = ids[j]
        result.status[k] = str(status[j])
        if d is None:
            continue
        result.margin[k] = d["margin"]
        result.runner_up_id[k] = str(constellation.sat_ids[d["runner_up"]]) if d["runner_up"] >= 0 else None
        if sat[j] >= 0:
            result.sat_id[k] = str(constellation.sat_ids[sat[j]])
            result.match_rms_hz[k] = d["rms_hz"]
