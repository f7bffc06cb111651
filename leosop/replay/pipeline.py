"""From a recording to tracks, identities, measurements and a fix.

:func:`replay` streams the recording one block at a time (memory is bounded
by the block, whatever the file size), finds every comb in each block
(:func:`~leosop.signal.multicomb.find_combs`), joins the detections into
tracks (:class:`~leosop.replay.tracks.Tracker`), identifies the tracks
against the element sets (:func:`~leosop.replay.identify.identify_tracks`),
follows the fragments too short to name along the curves of the satellites
that could be theirs (:mod:`~leosop.replay.extend`, static replays) and
solves a static batch fix or per-block snapshot fixes from the identified
tracks' Doppler (:mod:`leosop.positioning.solve`).

Blocks never straddle a capture: a snapshot recording (DESIGN 4.2) gives one
block per capture when the capture is shorter than the block length. With
``threads`` > 1 the next blocks are read and cleaned on worker threads
(:mod:`~leosop.replay.stream`) while this one is searched; the result is the
same.

Wide recordings (a whole 240 MHz OFDM channel) are narrowed block by block
to :data:`WORK_RATE_HZ` around the pilot comb (an exact band-limited
decimation by an integer factor, in the frequency domain) before the comb
search; at the full channel rate the frame timing and the OFDM centre's
Doppler also come from the PSS of the first capture
(:func:`~leosop.signal.ofdm.acquire_pss`), and its frames are tracked over
that capture (:func:`~leosop.signal.ofdm.track_pss`: timing, code Doppler,
frame-timing jumps).
"""

import time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..positioning.measurements import Measurements
from ..signal.coarse import MAX_DOPPLER_HZ
from ..signal.fine import cubic_bias_hz
from ..signal.comb_fit import fit_kernel
from ..signal.multicomb import find_combs
from ..signal.pilot import PilotComb
from .elements import check_snapshot_age
from .extend import extend_fragments
from .identify import identify_tracks
from .lo import LO_DRIFT_MAX_HZ_PER_S, LO_OFFSET_MAX_HZ, LoEstimate, check_band, lo_estimate, lo_noise, rough_lo_hz
from .refit import refit_through_lo
from .stream import SPECTRUM_BINS, SPECTRUM_COLUMNS, prepared_blocks, track_times
from .tracks import Detections, Tracker, join_fragments, remove_outliers

__all__ = ["Block", "ReplayResult", "block_plan", "replay", "track_measurements"]

#: Sample rate the comb search works at [Hz]: the comb (+-176 kHz) under
#: +-300 kHz of Doppler fits with margin; wider recordings are narrowed to it.
WORK_RATE_HZ = 2.5e6
#: Fraction of the sample rate kept clear of each band edge in the comb search.
BAND_MARGIN = 0.05
#: In a continuous recording, blocks between full spectrum searches: the
#: others only fit the combs the tracks predict (tracking mode, a fifth of
#: the cost), so a rising satellite is picked up within this many blocks.
SEARCH_EVERY = 10
#: Combs a full search finds in one block; a tracking block fits every
#: tracked comb and, when it also searches, looks for up to this many more
#: (a continuous recording of more than ten satellites keeps them all).
MAX_NEW_COMBS = 10
#: Half-width of the window a tracked comb is fitted in around its
#: prediction [Hz]: the tracks predict the next block to well below a hertz;
#: the window sets the decimated band, so it is kept small. A comb outside
#: it is lost for the block and picked up by the next full search.
TRACK_GATE_HZ = 25.0
#: Refinement passes in tracking mode: the predictions are good enough that
#: one pass with the other combs removed reaches the bound (two in a search).
TRACK_REFINE = 1
#: The tracked blocks are fitted again through the identification's LO
#: offset when the Doppler-only tone model misplaces the comb's edge tones by
#: more than this many cycles over a block: a tone then loses at most
#: (pi x)^2 / 3 of its power, 0.03 % at 0.01 (5 kHz in 20 ms blocks is below).
LO_REFIT_CYCLES = 0.01
#: Radius searched round the first identification's position when the
#: refitted tracks are identified again [m]: that position is good to ~1-2 km.
REFIT_PRIOR_RADIUS_M = 20e3
#: Default radius of identification's search around a prior position [m] (DESIGN 4.1: ``--init`` within
#: ~100 km).
PRIOR_RADIUS_M = 150e3
#: Longest gap between two tracks of one comb that are joined [s].
JOIN_GAP_S = 10.0


@dataclass(frozen=True)
class Block:
    """One block of a recording: samples ``start .. start + n_samples - 1``.

    ``t_s`` is the block centre in seconds from the recording's first sample
    (capture gaps included); ``time_utc`` the same instant in UTC.
    """

    start: int
    n_samples: int
    t_s: float
    time_utc: np.datetime64


def block_plan(rec, block_s):
    """The blocks of every capture, in time order.

    A capture shorter than ``block_s`` is one block; a longer one is cut
    into whole blocks (the remainder, shorter than a block, is left out).

    Returns
    -------
    list of Block
    """
    if rec.start_utc is None:
        raise InputError(f"{rec.data_path}: the recording has no core:datetime; replay needs the UTC time "
                         "of its samples to compare them with the satellites")
    fs = rec.sample_rate_hz
    block_len = int(round(block_s * fs))
    if block_len < 64:
        raise InputError(f"block_s {block_s:g}: {block_len} samples at {fs:g} Hz; need at least 64", param="block_s")
    blocks = []
    for cap in rec.captures:
        n = min(block_len, cap.n_samples)
        if n < 64:
            continue
        cap_t0_s = (cap.start_utc - rec.start_utc) / np.timedelta64(1, "s")
        for k in range(cap.n_samples // n):
            offset_s = (k * n + 0.5 * (n - 1)) / fs
            blocks.append(Block(cap.sample_start + k * n, n, cap_t0_s + offset_s,
                                cap.start_utc + np.timedelta64(int(round(offset_s * 1e9)), "ns")))
    return blocks


def search_band(sample_rate_hz, comb, lo_offset_max_hz):
    """Narrowing factor and Doppler search half-width for combs within ``lo_offset_max_hz`` of the band centre.

    The search spans the satellites' Doppler (:data:`MAX_DOPPLER_HZ`) plus
    the receiver's offset, clipped to what the band holds (the comb's
    half-width and :data:`BAND_MARGIN` of the rate off its edges); a
    recording is narrowed only as far as that span allows.

    Returns
    -------
    factor : int
    max_doppler_hz : float
    """
    half_comb = float(np.max(np.abs(comb.offsets_hz)))
    need_hz = 2.0 * (MAX_DOPPLER_HZ + lo_offset_max_hz + half_comb) / (1.0 - 2.0 * BAND_MARGIN)
    factor = max(1, int(sample_rate_hz // max(WORK_RATE_HZ, need_hz)))
    fs = sample_rate_hz / factor
    return factor, min(MAX_DOPPLER_HZ + lo_offset_max_hz, (0.5 - BAND_MARGIN) * fs - half_comb)


def _pss(rec):
    """PSS acquisition on the first 10 ms of the first capture of a full-channel recording, the capture's
    start and the frames tracked over it: (PssAcquisition, datetime64, PssTrack), or None."""
    from ..signal.ofdm import FRAME_SAMPLES, FS_HZ, acquire_pss, track_pss

    if rec.sample_rate_hz != FS_HZ:
        return None
    cap = rec.captures[0]
    n = min(cap.n_samples, int(round(0.01 * FS_HZ)))
    if n < 2 * FRAME_SAMPLES:
        return None
    samples = rec.capture_samples(cap)
    acq = acquire_pss(samples[:n], FS_HZ)
    track = track_pss(samples, acq, channel_hz=rec.center_hz) if rec.center_hz else track_pss(samples, acq)
    return acq, cap.start_utc, track


def _correct_rate_change(track, n_samples, fs):
    """Remove the Doppler bias a change of rate puts on each block (cubic phase).

    ``n_samples`` (len(track),) are the lengths of the track's blocks.

    The rate change is the slope of the track's own rates, which the track
    measures far better than one block does.
    """
    if len(track) < 3 or not np.all(np.isfinite(track.doppler_rate_hz_per_s)):
        return
    accel = np.gradient(track.doppler_rate_hz_per_s, track.t_s)
    track.doppler_hz = track.doppler_hz - cubic_bias_hz(accel, n_samples, fs)


@dataclass
class ReplayResult:
    """What :func:`replay` found.

    Attributes
    ----------
    tracks : list of Track
        Every confirmed track, identified or not (``sat_id`` None).
    identification : object
        The result of :func:`~leosop.replay.identify.identify_tracks`.
    measurements : Measurements or None
        The identified tracks' Doppler (DESIGN 4.3 rows); None without any.
    position : PositionResult or None
        The fix (static) or fixes (snapshot); None when nothing could be solved.
    blocks : list of Block
    spectrum_t_s : ndarray, (n_cols,)
    spectrum_f_hz : ndarray, (SPECTRUM_BINS,)
    spectrum : ndarray, (SPECTRUM_BINS, n_cols)
        Mean periodograms of a subset of the blocks (after narrowing), for the figure.
    pss : (PssAcquisition, datetime64, PssTrack) or None
        Full-channel OFDM recordings: the PSS acquisition on the first
        capture, that capture's start time and its frames tracked over it.
    cpu_s : dict
        Processor time of each stage [s]: ``blocks`` (reading, comb search
        and tracking), ``identify``, ``refit`` (the tracked blocks fitted
        again through the LO offset and identified again,
        :func:`~leosop.replay.refit.refit_through_lo`; 0 when the offset is too small to matter),
        ``extend`` (unnamed fragments followed along their candidates' curves
        and the tracks identified again, :mod:`~leosop.replay.extend`; static
        replays), ``fix``; with several threads the sum of their times.
    lo : LoEstimate or None
        The receiver's common offset and drift (:mod:`leosop.replay.lo`).
    wall_s : dict
        Elapsed (wall-clock) time of the same stages [s].
    """

    tracks: list
    identification: object
    measurements: Measurements | None
    position: object
    blocks: list
    spectrum_t_s: np.ndarray
    spectrum_f_hz: np.ndarray
    spectrum: np.ndarray
    pss: object = None
    cpu_s: dict = None
    lo: LoEstimate | None = None
    wall_s: dict = None


#: Sigma of a satellite's own frequency offset about the constellation's
#: mean [Hz], added to every measurement of a snapshot fix, which cannot
#: estimate it (the static fix estimates one per satellite). Offsets of a
#: few hertz: drawn uniform over 5 Hz, as ``leosop generate`` does, their
#: rms about the mean is 5 / sqrt(12) = 1.44 Hz. Without it a snapshot fix
#: from such a recording errs ~5x its sigma (0.7x with no offsets).
SAT_OFFSET_SIGMA_HZ = 1.5

#: Prior sigma of the receiver's horizontal speed [m/s] in identification
#: when it may move (no ``static``): a road vehicle. Identification fits one
#: constant velocity over the recording.
RX_SPEED_SIGMA_MPS = 30.0


def track_measurements(tracks, carrier_hz, model_sigma_hz=0.0):
    """The identified tracks as measurement rows (DESIGN 4.3), time-ordered.

    ``pass_id`` is the satellite: each satellite's rows share its clock and
    orbit-error states in a static fix (``leosop position --static`` on the
    written table solves the same fix). ``model_sigma_hz`` is added in
    quadrature to every row's sigma.

    Returns
    -------
    Measurements or None
        None when no track is identified.
    """
    ids = [tr for tr in tracks if tr.sat_id is not None]
    if not ids:
        return None
    time_utc = np.concatenate([tr.time_utc for tr in ids])
    order = np.argsort(time_utc, kind="stable")
    col = lambda name: np.concatenate([getattr(tr, name) for tr in ids])[order]  # noqa: E731
    time_utc = time_utc[order]
    t_s = (time_utc - time_utc.min()) / np.timedelta64(1, "s")
    sat_id = np.concatenate([np.full(len(tr), tr.sat_id, dtype=object) for tr in ids])[order].astype(str)
    n = len(t_s)
    return Measurements(t_s=t_s, time_utc=time_utc, sat_id=sat_id, doppler_hz=col("doppler_hz"),
                        sigma_hz=np.hypot(col("sigma_hz"), model_sigma_hz), carrier_hz=np.full(n, float(carrier_hz)),
                        line=np.arange(2, n + 2), source="replay", pass_id=sat_id.copy())


def replay(rec, constellation, *, block_s=0.1, init_pos_ecef_m=None, static=True, mask_deg=10.0,
           max_gap_s=None, lo_offset_max_hz=LO_OFFSET_MAX_HZ, lo_drift_max_hz_per_s=LO_DRIFT_MAX_HZ_PER_S,
           show_progress=False, prior_radius_m=PRIOR_RADIUS_M, threads=1):
    """Find, track and identify the combs of a recording, then fix the receiver.

    Parameters
    ----------
    rec : Recording
        With ``start_utc`` and ``captures`` (:func:`leosop.signal.iq.open_sigmf`).
    constellation : Constellation
        The element sets the satellites are identified against.
    block_s : float
        Block length; captures shorter than this are one block each.
    init_pos_ecef_m : array_like, (3,), optional
        A prior receiver position (within ~100 km); None for a global search.
    static : bool
        One batch fix of a receiver at rest; else a snapshot fix per block.
    mask_deg : float
        Elevation mask for the identification's candidates.
    max_gap_s : float, optional
        Longest gap a track survives (default: 5 blocks or 5 capture periods).
    lo_offset_max_hz, lo_drift_max_hz_per_s : float
        Bounds of the receiver's common offset (the LNB's local oscillator
        error) and of its drift searched: the comb search widens by the
        offset (up to the band's edges, :func:`search_band`) and the
        identification searches both (:func:`~leosop.replay.identify.identify_tracks`).
    show_progress : bool
    prior_radius_m : float
        How far from ``init_pos_ecef_m`` identification searches [m]: a
        known site (a differential base) needs only a few km, and is fast.
    threads : int
        Threads for the blocks: N > 1 reads and cleans the next blocks on
        N - 1 worker threads while this one searches and tracks
        (:func:`~leosop.replay.stream.prepared_blocks`), and votes on N
        threads in the identification's cell search; the result is the
        same whatever N.

    Returns
    -------
    ReplayResult
    """
    from ..positioning.solve import position_snapshots, position_static_passes
    from ..progress import progress

    comb = PilotComb(carrier_hz=rec.center_hz or PilotComb.carrier_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    check_band(rec, float(np.max(np.abs(comb.offsets_hz))), lo_offset_max_hz)
    factor, max_doppler = search_band(rec.sample_rate_hz, comb, lo_offset_max_hz)
    fs = rec.sample_rate_hz / factor
    blocks = block_plan(rec, block_s)
    check_snapshot_age(rec, constellation)
    if not blocks:
        raise InputError(f"{rec.data_path}: no capture holds a block of at least 64 samples")
    if max_gap_s is None:
        spacing = np.median(np.diff([b.t_s for b in blocks])) if len(blocks) > 1 else block_s
        max_gap_s = 5.0 * max(spacing, block_s)
    tracker = Tracker(max_gap_s=max_gap_s, max_gap_tentative_s=max(2.5, 2.5 * max_gap_s / 5.0))
    every = max(1, int(np.ceil(len(blocks) / SPECTRUM_COLUMNS)))
    t0, wall0 = time.process_time(), time.perf_counter()
    spec_t, spec = [], []
    block_len = {}
    n_last = 0  # combs found in the last block
    lo_rough = None  # the tracking blocks' tone-model LO offset, from the first full search (rough_lo_hz)
    # Central tones within the band (BAND_MARGIN off its edges), as search_band's.
    band_hz = (0.5 - BAND_MARGIN) * fs - float(np.max(np.abs(comb.offsets_hz)))
    kernel = fit_kernel(len(blocks))  # compiled comb fits and line finding where they pay for their load
    prepared = prepared_blocks(rec, blocks, factor, comb, threads=threads, spectrum_every=every, kernel=kernel)
    t_trk, utc_trk = track_times(blocks, factor, rec.sample_rate_hz)
    try:
        for k, (b, block) in enumerate(zip(blocks, progress(prepared, total=len(blocks), desc="replay", unit="block")
                                           if show_progress else prepared)):
            n_block = block.n_samples  # narrowed
            # Tracking mode between full searches, where blocks follow each other.
            # (contiguous in time: snapshot captures lie back to back in the file, seconds apart)
            contiguous = k > 0 and abs(b.t_s - blocks[k - 1].t_s - b.n_samples / rec.sample_rate_hz) < 1e-6
            pred = tracker.predictions(b.t_s) if contiguous else None
            # Following blocks of a continuous recording fit the tone model through the rough LO offset, the
            # search centred on it as far either side as the band allows (snapshots: the refit does it).
            lo = (lo_rough or 0.0) if contiguous else 0.0
            span = min(max_doppler, band_hz - abs(lo))
            if pred is None:
                # After a birth the combs of the last block are searched for again, with as many new.
                n_known = n_last if contiguous else 0
                found = find_combs(None, fs, comb=comb, max_doppler_hz=span, max_combs=n_known + MAX_NEW_COMBS,
                                   lo_offset_hz=lo, clean=False, spectrum=block.iq_fft, kernel=kernel)
                if lo_rough is None:
                    lo_rough = rough_lo_hz(found.doppler_hz)
            else:
                # Every SEARCH_EVERY-th block also searches the spectrum for new
                # combs, with the tracked ones fitted first and removed.
                search = k % SEARCH_EVERY == 0
                found = find_combs(None, fs, comb=comb, predicted_hz=pred[0], predicted_rate_hz_per_s=pred[1],
                                   search=search, gate_hz=TRACK_GATE_HZ, max_doppler_hz=span, lo_offset_hz=lo,
                                   max_combs=pred[0].size + MAX_NEW_COMBS, n_refine=2 if search else TRACK_REFINE,
                                   clean=False, spectrum=block.iq_fft, kernel=kernel)
            det = Detections(found.doppler_hz, found.doppler_rate_hz_per_s, found.cn0_dbhz, found.sigma_hz)
            n_last = len(det)
            tracker.update(t_trk[k], utc_trk[k], det, block_s=n_block / fs)
            block_len[t_trk[k]] = block_len[utc_trk[k]] = n_block
            if block.spectrum is not None:
                spec_t.append(b.t_s)
                spec.append(block.spectrum)
    finally:
        prepared.close()  # its workers and the switch interval, also when a block's work raised
    cpu_s = {"blocks": time.process_time() - t0}
    wall_s = {"blocks": time.perf_counter() - wall0}
    raw = [remove_outliers(tr) for tr in join_fragments(tracker.finish(), max(JOIN_GAP_S, 2.0 * max_gap_s))]

    def identify(raw, init, radius_m):
        tracks = [replace(tr) for tr in raw]  # _correct_rate_change assigns a new doppler_hz
        for tr in tracks:
            _correct_rate_change(tr, np.array([block_len[t] for t in tr.t_s]), fs)
        ident = identify_tracks(tracks, constellation, init_pos_ecef_m=init, prior_radius_m=radius_m, mask_deg=mask_deg,
                                carrier_hz=comb.carrier_hz, lo_offset_max_hz=lo_offset_max_hz,
                                lo_drift_max_hz_per_s=lo_drift_max_hz_per_s,
                                rx_speed_sigma_mps=0.0 if static else RX_SPEED_SIGMA_MPS,
                                threads=threads) if tracks else None
        return tracks, ident

    tracks, ident = identify(raw, init_pos_ecef_m, prior_radius_m)
    cpu_s["identify"] = time.process_time() - t0 - cpu_s["blocks"]
    wall_s["identify"] = time.perf_counter() - wall0 - wall_s["blocks"]
    lo = lo_estimate(ident)
    # The edge tones' misfit over the longest block [cycles] under the Doppler-only tone model.
    misfit = (0 if lo is None else abs(lo.offset_hz) * np.max(np.abs(comb.offsets_hz)) / comb.carrier_hz
              * max(block_len.values()) / fs)
    if misfit > LO_REFIT_CYCLES:
        refit = refit_through_lo(rec, raw, blocks, factor, comb, lo, gate_hz=TRACK_GATE_HZ, threads=threads,
                                 kernel=kernel)
        raw = [remove_outliers(tr) for tr in refit]
        tracks, ident = identify(raw, ident.pos_ecef_m, REFIT_PRIOR_RADIUS_M)
    cpu_s["refit"] = time.process_time() - t0 - cpu_s["blocks"] - cpu_s["identify"]
    wall_s["refit"] = time.perf_counter() - wall0 - wall_s["blocks"] - wall_s["identify"]
    if static and ident is not None and np.all(np.isfinite(ident.pos_ecef_m)):
        # Fragments too short to name, followed along their candidates' curves (extend.py).
        ext, n_ext = extend_fragments(rec, raw, tracks, blocks, factor, comb, lo_estimate(ident), ident.pos_ecef_m,
                                      ident.pos_cov_m2, constellation, mask_deg=mask_deg, band_hz=band_hz,
                                      gate_hz=TRACK_GATE_HZ, threads=threads, kernel=kernel)
        if n_ext:
            raw_ext = [remove_outliers(tr) for tr in ext]
            again = identify(raw_ext, ident.pos_ecef_m, REFIT_PRIOR_RADIUS_M)
            if sum(tr.sat_id is not None for tr in again[0]) >= sum(tr.sat_id is not None for tr in tracks):
                raw, (tracks, ident) = raw_ext, again
    cpu_s["extend"] = time.process_time() - t0 - sum(cpu_s.values())
    wall_s["extend"] = time.perf_counter() - wall0 - sum(wall_s.values())
    meas = track_measurements(tracks, comb.carrier_hz, 0.0 if static else SAT_OFFSET_SIGMA_HZ)
    position = noise = None
    if meas is not None:
        start = getattr(ident, "pos_ecef_m", None)
        start = init_pos_ecef_m if start is None or not np.all(np.isfinite(start)) else start
        if static:
            # One receiver clock (offset and drift) and each satellite's small
            # offset and along-track time offset: the physics of one receiver.
            fix = lambda **kw: position_static_passes(meas, meas.sat_id, constellation=constellation,  # noqa: E731
                                                      init_pos_ecef_m=start, clock="common", **kw)
            position = fix()
            # The LO's short-term noise, common to a block's rows: one frequency state per block (lo.lo_noise).
            block_s_rows = np.array([block_len[t] for t in meas.time_utc]) / fs
            used = position.fixes.used
            noise = lo_noise(position.fixes.residuals_hz[used], meas.sigma_hz[used], meas.time_utc[used],
                             block_s_rows[used])
            if noise.linewidth_hz > 0:
                position = fix(block_id=meas.time_utc, block_sigma_hz=noise.sigma_hz(block_s_rows))
        else:
            position = position_snapshots(meas, constellation=constellation, init_pos_ecef_m=start)
    cpu_s["fix"] = time.process_time() - t0 - sum(cpu_s.values())
    wall_s["fix"] = time.perf_counter() - wall0 - sum(wall_s.values())
    f_hz = (np.arange(SPECTRUM_BINS) - SPECTRUM_BINS // 2) * fs / SPECTRUM_BINS
    return ReplayResult(tracks, ident, meas, position, blocks, np.array(spec_t), f_hz,
                        np.array(spec).T if spec else np.zeros((SPECTRUM_BINS, 0)), _pss(rec), cpu_s,
                        lo_estimate(ident, position if static else None, meas, noise), wall_s)
