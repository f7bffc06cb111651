"""``leosop replay --carrier``: the carrier tracker of :mod:`leosop.replay.carrier` on a replay's satellites.

:func:`check_continuous` refuses recordings with gaps (snapshots);
:func:`replay_carrier` starts one tracker per identified satellite from
its track, runs it over the recording's blocks and makes the static fix
from the phase-rate Doppler (:class:`ReplayCarrier`: ``carrier.csv`` rows
and the JSON ``carrier`` block).
"""

from dataclasses import dataclass, fields

import numpy as np

from ..errors import InputError
from ..signal.pilot import PilotComb
from ..timebase import format_utc
from .carrier import CarrierTracks, comb_crossings, phase_rate_doppler, recording_blocks, track_carrier
from .tracks import RATE_SIGMA_FACTOR, Track

__all__ = ["WINDOW_S", "ReplayCarrier", "check_continuous", "replay_carrier"]


#: Window of the phase-rate Doppler replay takes [s]: a cubic over a second of phase
#: (~0.002 Hz sigma at 42 dB-Hz per tone, against ~0.03 Hz for one 0.1 s block's estimate).
WINDOW_S = 1.0


def check_continuous(rec):
    """Refuse a recording with gaps between its captures (snapshots): the carrier's whole cycles are lost there.

    Captures back to back (each starting one sample, within the microsecond
    of ``core:datetime``, after the last one ends) are continuous.

    Raises
    ------
    InputError
    """
    caps = rec.captures
    gap_s = np.array([float((b.start_utc - a.start_utc) / np.timedelta64(1, "ns")) * 1e-9
                      - a.n_samples / rec.sample_rate_hz for a, b in zip(caps[:-1], caps[1:])])
    if gap_s.size and np.max(np.abs(gap_s)) > 1e-6 + 1.0 / rec.sample_rate_hz:
        raise InputError(f"{rec.data_path}: carrier tracking needs a continuous recording, and this one is "
                         f"{len(caps)} captures with gaps of up to {np.max(gap_s):.3g} s: carrier phase coherence is "
                         "lost across a gap (each snapshot would start a new arc)")


@dataclass(frozen=True)
class ReplayCarrier:
    """The carrier tracks of a replay's identified satellites (:func:`replay_carrier`).

    Attributes
    ----------
    sat_id : tuple of str, (n_sats,)
    time_utc : ndarray of datetime64[ns], (n_blocks,)
        The block centres of ``tracks.t_s``.
    first, last : ndarray of int, (n_sats,)
        Each satellite's first and last block in replay's identified tracks;
        it is tracked from ``first`` to the end (before: ``arc`` -1).
    tracks : CarrierTracks
        Arrays (n_sats, n_blocks).
    doppler_hz, doppler_sigma_hz : ndarray, (n_sats, n_blocks)
        Phase-rate Doppler and its sigma (:func:`phase_rate_doppler` over :data:`WINDOW_S`).
    in_fix : ndarray of bool, (n_sats, n_blocks)
        The phase-rate rows the static fix takes: one per window and arc,
        their windows disjoint (independent rows).
    block_tracks : list of Track
        Replay's identified tracks (per-block Doppler).
    measurements : Measurements or None
        The static fix's rows: phase-rate Doppler where a satellite has
        some, its block Doppler where it has none; None without ``static``.
    position : PositionResult or None
        The static fix from them (None when they are too few for one).
    fix_note : str or None
        Why there is no such fix though ``static`` was asked for.
    """

    sat_id: tuple
    time_utc: np.ndarray
    first: np.ndarray
    last: np.ndarray
    tracks: CarrierTracks
    doppler_hz: np.ndarray
    doppler_sigma_hz: np.ndarray
    in_fix: np.ndarray
    block_tracks: list
    measurements: object = None
    position: object = None
    fix_note: str | None = None

    CSV_HEADER = ("time_utc", "t_s", "sat_id", "phase_cycles", "phase_sigma_cycles", "doppler_hz",
                  "doppler_sigma_hz", "lock", "slip", "arc", "in_fix", "crossing")

    def csv_rows(self):
        """Rows of ``carrier.csv`` (:attr:`CSV_HEADER`): each satellite from its first block on, in time order.

        ``doppler_hz`` is the phase-rate Doppler; empty fields where there is none (not locked, window short).
        """
        i, j = np.nonzero(np.arange(self.time_utc.size)[None, :] >= self.first[:, None])
        order = np.lexsort((i, j))
        i, j = i[order], j[order]
        utc = format_utc(self.time_utc[j]) if j.size else []
        num = lambda a: ["" if not np.isfinite(v) else float(v) for v in a[i, j]]  # noqa: E731
        tr = self.tracks
        cols = (utc, tr.t_s[j].tolist(), [self.sat_id[k] for k in i], num(tr.phase_cycles),
                num(tr.phase_sigma_cycles), num(self.doppler_hz), num(self.doppler_sigma_hz),
                tr.lock[i, j].astype(int).tolist(), tr.slip[i, j].astype(int).tolist(), tr.arc[i, j].tolist(),
                self.in_fix[i, j].astype(int).tolist(), tr.crossing[i, j].astype(int).tolist())
        return list(zip(*cols))

    def doc(self):
        """The JSON ``carrier`` block: per satellite its arcs, slips, locked fraction, phase-rate vs block Doppler."""
        sats = []
        for k, sat in enumerate(self.sat_id):
            lock = self.tracks.lock[k, self.first[k]: self.last[k] + 1]
            blocks = [tr for tr in self.block_tracks if tr.sat_id == sat]
            j = np.concatenate([_block_index(self.tracks.t_s, tr.t_s) for tr in blocks])
            diff = self.doppler_hz[k, j] - np.concatenate([tr.doppler_hz for tr in blocks])
            diff = diff[np.isfinite(diff)]
            sig = self.doppler_sigma_hz[k][np.isfinite(self.doppler_sigma_hz[k])]
            sats.append({"sat_id": sat, "start_utc": format_utc(self.time_utc[self.first[k]]),
                         "n_blocks": int(lock.size), "locked_fraction": float(np.mean(lock)),
                         "arcs": int(np.unique(self.tracks.arc[k][self.tracks.arc[k] >= 0]).size),
                         "slips": int(np.sum(self.tracks.slip[k])),
                         "crossing_blocks": int(np.sum(self.tracks.crossing[k])),
                         "n_phase_rate_rows": int(np.sum(self.in_fix[k])),
                         "phase_rate_sigma_median_hz": float(np.median(sig)) if sig.size else None,
                         "block_sigma_median_hz": float(np.median(np.concatenate([tr.sigma_hz for tr in blocks]))),
                         "phase_rate_vs_block_rms_hz": float(np.sqrt(np.mean(diff**2))) if diff.size else None})
        return {"window_s": WINDOW_S, "fix_doppler": "phase_rate" if self.position is not None else "block",
                "fix_note": self.fix_note, "satellites": sats}


def _block_index(t_s, t):
    """Indices in the block centres ``t_s`` (n_blocks,) of the instants ``t`` (n,), which are among them."""
    return np.minimum(np.searchsorted(t_s, np.asarray(t) - 1e-9), t_s.size - 1)


def replay_carrier(rec, res, constellation, *, block_s, lo_offset_max_hz, static):
    """Carrier tracking of a replay's identified satellites over a continuous recording, and its static fix.

    Each satellite's tracker starts at the first block of its earliest
    identified track, from the Doppler and rate the track gives there
    (:func:`_start`; satellites starting at the same block share one pass
    over the recording). The blocks are
    replay's (``block_s``, narrowed as replay narrows them); the comb is seen
    through the receiver's LO offset at its reference time (its drift over a
    recording moves the edge tones by ~1e-5 of the change: negligible). With
    ``static`` the fix is replay's static fix (one receiver clock, each
    satellite's offset and time offset) from the phase-rate Doppler, one row
    per :data:`WINDOW_S` and arc, in place of the block Doppler: the two
    come from the same samples, so using both would count the signal twice,
    and the phase-rate rows are ~15 times less noisy.

    Parameters
    ----------
    rec : Recording
        Continuous (:func:`check_continuous`).
    res : ReplayResult
        :func:`~leosop.replay.pipeline.replay` of ``rec`` with ``block_s`` and ``lo_offset_max_hz``.
    constellation : Constellation
    block_s, lo_offset_max_hz : float
    static : bool

    Returns
    -------
    ReplayCarrier
    """
    from ..positioning.solve import position_static_passes
    from .pipeline import search_band, track_measurements
    from .stream import track_times

    comb = PilotComb(carrier_hz=rec.center_hz or PilotComb.carrier_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    factor, _ = search_band(rec.sample_rate_hz, comb, lo_offset_max_hz)
    t_s, time_utc = track_times(res.blocks, factor, rec.sample_rate_hz)
    ident = [tr for tr in res.tracks if tr.sat_id is not None]
    sats = tuple(sorted({tr.sat_id for tr in ident}))
    starts = [min((tr for tr in ident if tr.sat_id == s), key=lambda tr: tr.t_s[0]) for s in sats]
    first = np.array([_block_index(t_s, tr.t_s[0]) for tr in starts], dtype=int)
    last = np.array([max(_block_index(t_s, tr.t_s[-1]) for tr in ident if tr.sat_id == s) for s in sats], dtype=int)
    lo_hz = res.lo.offset_hz if res.lo is not None and np.isfinite(res.lo.offset_hz) else 0.0
    shape = (len(sats), t_s.size)
    cols = {f.name: np.full(shape, np.nan) for f in fields(CarrierTracks) if f.name != "t_s"}
    cols.update(lock=np.zeros(shape, bool), slip=np.zeros(shape, bool), arc=np.full(shape, -1),
                crossing=np.zeros(shape, bool))
    for k in np.unique(first):
        group = np.flatnonzero(first == k)
        f0, r0, f0_sigma, r0_sigma = np.array([_start(starts[g], res.blocks[k].n_samples / rec.sample_rate_hz)
                                               for g in group]).T
        # Priors of three sigmas. The rate's matters: the prediction to the next block must stay well within
        # ARC_SIGMA_CYCLES, or every block restarts an arc and the filter never learns the rate.
        ct = track_carrier(recording_blocks(rec, block_s, factor=factor, first=k), rec.sample_rate_hz / factor, f0, r0,
                           comb=comb.through_lo(lo_hz), doppler0_sigma_hz=3.0 * np.max(f0_sigma),
                           rate0_sigma_hz_per_s=3.0 * np.max(r0_sigma))
        for name, arr in cols.items():
            arr[group, k:] = getattr(ct, name)
    # Each tracker saw the crossings of its own group; those between groups (satellites starting at other
    # blocks) are found here, from every satellite's frequency, and left out the same way (their blocks did
    # update their filters: harmless to the phase of the blocks after, which is measured, not predicted).
    cross = comb_crossings(cols["doppler_hz"], cols["doppler_rate_hz_per_s"], block_s, comb.through_lo(lo_hz))
    cross &= cols["lock"]
    cols["crossing"] |= cross
    cols["lock"] &= ~cross
    for name in ("phase_cycles", "phase_sigma_cycles", "phase_ref_sigma_cycles"):
        cols[name][cross] = np.nan
    tracks = CarrierTracks(t_s, **cols)
    dop, sig = phase_rate_doppler(tracks, WINDOW_S)
    in_fix = _disjoint_windows(t_s, dop, tracks.arc, tracks.lock, WINDOW_S)
    meas = position = note = None
    if static and not in_fix.any():
        note = "no phase-rate Doppler (no window of locked blocks): the block-Doppler fix stands"
    elif static:
        rows = []
        for k, sat in enumerate(sats):
            j = np.flatnonzero(in_fix[k])
            rows += ([Track(t_s[j], time_utc[j], dop[k, j], tracks.doppler_rate_hz_per_s[k, j], np.full(j.size, np.nan),
                            sig[k, j], sat_id=sat)] if j.size else [tr for tr in ident if tr.sat_id == sat])
        meas = track_measurements(rows, comb.carrier_hz)
        # replay's static fix (pipeline.replay), started from its block-Doppler fix
        start = res.identification.pos_ecef_m if res.position is None else res.position.fixes.pos_ecef_m
        try:
            position = position_static_passes(meas, meas.sat_id, constellation=constellation,
                                              init_pos_ecef_m=start, clock="common")
        except InputError as exc:  # too few rows (a recording of a few windows): the block-Doppler fix stands
            meas, note = None, str(exc)
    return ReplayCarrier(sats, time_utc, first, last, tracks, dop, sig, in_fix, ident, meas, position, note)


def _start(track, block_s):
    """Doppler, rate and their sigmas at a track's first block: a quadratic fitted to its first :data:`WINDOW_S`.

    The track's blocks know the rate far better than one block does (its
    sigma ``RATE_SIGMA_FACTOR sigma_hz / block_s``, ~130 Hz/s for a 20 ms
    block at 42 dB-Hz; a second of 0.1 s blocks: a few tenths of Hz/s).
    A track with fewer than four blocks in the window gives its first block's own estimates.
    """
    use = (track.t_s - track.t_s[0] <= WINDOW_S) & np.isfinite(track.sigma_hz) & np.isfinite(track.doppler_hz)
    if use.sum() < 4:
        rate = track.doppler_rate_hz_per_s[0]
        return (track.doppler_hz[0], rate if np.isfinite(rate) else 0.0, track.sigma_hz[0],
                RATE_SIGMA_FACTOR * track.sigma_hz[0] / block_s)
    Aw = ((track.t_s[use] - track.t_s[0])[:, None] ** np.arange(3)) / track.sigma_hz[use, None]
    coef, *_ = np.linalg.lstsq(Aw, track.doppler_hz[use] / track.sigma_hz[use], rcond=None)
    cov = np.linalg.inv(Aw.T @ Aw)
    return coef[0], coef[1], np.sqrt(cov[0, 0]), np.sqrt(cov[1, 1])


def _disjoint_windows(t_s, doppler_hz, arc, lock, window_s):
    """Rows (n_sats, n_blocks) of bool: per arc, windows of ``window_s`` within its locked blocks sharing no block.

    From the first row whose window is whole (the fit centred, not
    extrapolated to an arc's end), greedily the next more than a window on:
    the kept rows' phase-rate Dopplers are independent. An arc shorter than
    a window keeps one row, its first with a Doppler.
    """
    keep = np.zeros(doppler_hz.shape, bool)
    tol = 1e-9
    for i in range(doppler_hz.shape[0]):
        for a in np.unique(arc[i][arc[i] >= 0]):
            t_arc = t_s[lock[i] & (arc[i] == a)]
            idx = np.flatnonzero(np.isfinite(doppler_hz[i]) & (arc[i] == a))
            whole = idx[(t_s[idx] - 0.5 * window_s >= t_arc[0] - tol) & (t_s[idx] + 0.5 * window_s <= t_arc[-1] + tol)]
            idx = whole if whole.size else idx[:1]
            k = 0
            while k < idx.size:
                keep[i, idx[k]] = True
                k = int(np.searchsorted(t_s[idx], t_s[idx[k]] + window_s + tol))
    return keep
