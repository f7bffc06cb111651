"""Carrier phase of the pilot combs across the blocks of a continuous recording: a Kalman tracker.

Each satellite's central tone is followed by a three-state Kalman filter
(phase [cycles], frequency [Hz], frequency rate [Hz/s] at the block centre;
white noise on the rate's derivative and on the frequency, the continuous
third-order model of Brown and Hwang 2012). Every block, each comb is
correlated coherently with the comb the state predicts: tone k against
``exp(-j 2 pi (k spacing t + s_k Phi(t)))`` with ``Phi`` the predicted
central-tone phase over the block and ``s_k = f_k / f_c`` (the correlation
of :func:`leosop.signal.fine.newton_comb`, at the prediction instead of at
the optimum). The tones keep unknown phases of their own (Newman phases in
``leosop generate``, unknown on a real downlink), so the per-tone sums are
combined against a template, the first locked block's sums: the phase of
``sum_k Y_k conj(template_k)`` is the phase error at the block centre, its
noise ``1 / sqrt(2 snr)`` rad from the block's coherent comb SNR. The
template's own noise is a constant phase: it cancels in phase differences.

Per block and satellite the result gives the accumulated carrier phase (the
integral of ``doppler_hz``: its change between two blocks is ``-carrier_hz /
c`` times the change of range, plus the clocks' integral), its sigma, the
filter's frequency, a lock indicator (the coherent SNR over :data:`LOCK_SNR`)
and a cycle-slip flag (normalised innovation squared over :data:`SLIP_NIS`:
a phase jump the prediction cannot explain). The whole cycles are continuous
within an ``arc``; a slip, or a prediction whose phase sigma exceeds
:data:`ARC_SIGMA_CYCLES` (a long loss of lock), starts a new one.

What cannot be tracked across snapshot gaps: a snapshot recording (20 ms
every second, DESIGN 4.2) gives no accumulated phase. Over a gap of a second
the prediction of a 3-state model carries the Doppler's unmodelled second
derivative (tens of Hz/s^2 on a LEO pass at 11 GHz, ``T^3 / 6`` cycles per
Hz/s^2: several cycles) and the receiver oscillator's phase noise, so the
integer cycle count is lost: each snapshot starts a new arc, and only the
Doppler of each snapshot survives. The ambiguity of each arc (its constant
offset) is never resolved here; positioning uses phase differences within an
arc (:func:`phase_rate_doppler`).
"""

from dataclasses import dataclass, fields

import numpy as np
from scipy.stats import gamma

from ..errors import InputError
from ..signal.fine import comb_phasors
from ..signal.pilot import PilotComb
from ..timebase import format_utc
from .tracks import RATE_SIGMA_FACTOR, Track

__all__ = ["CarrierTracks", "track_carrier", "recording_blocks", "phase_rate_doppler", "LOCK_SNR", "SLIP_NIS",
           "ARC_SIGMA_CYCLES", "WINDOW_S", "ReplayCarrier", "check_continuous", "replay_carrier"]

#: Coherent comb SNR (|S|^2 over its noise mean) a block needs to update the
#: filter: noise alone exceeds it with probability exp(-LOCK_SNR) = 1e-6.
LOCK_SNR = 13.8
#: Normalised innovation squared flagged as a cycle slip: chi-square with one
#: degree of freedom exceeds it with probability 1e-4 (a few false flags per
#: 10^4 satellite-blocks; a quarter-cycle jump at 1e-2 cycles sigma is 600).
SLIP_NIS = 15.1
#: Predicted phase sigma [cycles] beyond which the integer cycle count is
#: taken as lost: the next locked block starts a new arc.
ARC_SIGMA_CYCLES = 0.1
#: Template detection: the tones' incoherent power exceeds this gamma quantile of noise alone with probability 1e-6.
_TEMPLATE_PFA = 1e-6


@dataclass(frozen=True)
class CarrierTracks:
    """Carrier tracking of several satellites over the blocks, each array (n_sats, n_blocks) but ``t_s``.

    Attributes
    ----------
    t_s : ndarray, (n_blocks,)
        Block centres [s] on the time base of the blocks' start times.
    phase_cycles : ndarray
        Accumulated central-tone carrier phase, the integral of ``doppler_hz``:
        the filter's prediction plus the block's phase error, the receiver's
        NCO phase plus its discriminator (NaN where not locked). Continuous
        within an arc; its offset is arbitrary per arc.
    phase_sigma_cycles : ndarray
        Its sigma, ``1 / (2 pi sqrt(2 snr))``: the block's own noise,
        independent from block to block (the prediction carries no error
        into it while the phase error stays well within half a cycle).
    doppler_hz, doppler_sigma_hz, doppler_rate_hz_per_s : ndarray
        The filter's frequency state (DESIGN 4.2 sign, clocks included), its sigma, its rate.
    snr : ndarray
        Coherent comb SNR of the block's correlation (NaN before the template).
    lock, slip : ndarray of bool
        ``lock``: the block updated the filter; ``slip``: its innovation failed the test (a new arc begins).
    arc : ndarray of int
        Arc number, -1 before the first lock; whole cycles are continuous within an arc.
    """

    t_s: np.ndarray
    phase_cycles: np.ndarray
    phase_sigma_cycles: np.ndarray
    doppler_hz: np.ndarray
    doppler_sigma_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    snr: np.ndarray
    lock: np.ndarray
    slip: np.ndarray
    arc: np.ndarray


def _transition(dt_s, accel_psd, freq_psd):
    """Phi (3, 3) and Q (3, 3) of the (phase, frequency, rate) model over ``dt_s``."""
    Phi = np.array([[1.0, dt_s, 0.5 * dt_s**2], [0.0, 1.0, dt_s], [0.0, 0.0, 1.0]])
    d = dt_s ** np.arange(6)
    Q = accel_psd * np.array([[d[5] / 20, d[4] / 8, d[3] / 6], [d[4] / 8, d[3] / 3, d[2] / 2],
                              [d[3] / 6, d[2] / 2, d[1]]])
    Q[:2, :2] += freq_psd * np.array([[d[3] / 3, d[2] / 2], [d[2] / 2, d[1]]])
    return Phi, Q


def _correlate(iq, t0_s, fs, x, comb):
    """Per-tone sums of the block against the predicted comb of each satellite, (n_sats, n_tones)."""
    n = iq.size
    t = t0_s + np.arange(n) / fs
    tau = t - (t0_s + 0.5 * (n - 1) / fs)
    sp = float(comb.tone_spacing_hz)
    ratio = sp / float(comb.carrier_hz)
    dphi = x[:, 1:2] * tau + 0.5 * x[:, 2:3] * tau**2                     # (n_sats, n)
    a = (x[:, :1] - np.round(x[:, :1])) + dphi
    b = sp * t + ratio * (x[:, :1] + dphi)
    phasors = comb_phasors(a.ravel(), b.ravel(), comb.n_tones // 2).reshape(x.shape[0], n, comb.n_tones)
    return np.einsum("n,snk->sk", iq.astype(complex), phasors)


def track_carrier(blocks, sample_rate_hz, doppler0_hz, rate0_hz_per_s, *, comb=None, doppler0_sigma_hz=1.0,
                  rate0_sigma_hz_per_s=100.0, accel_psd_hz2_per_s5=1e3, freq_psd_hz2_per_s=1e-2):
    """Track the carrier phase of several combs over successive blocks.

    Parameters
    ----------
    blocks : iterable of (float, ndarray)
        ``(t0_s, iq)`` per block in time order: the time of its first sample
        [s] (one time base; the tones' nominal phases refer to its origin)
        and its samples, complex, shape (n,) (n may change between blocks).
    sample_rate_hz : float
    doppler0_hz, rate0_hz_per_s : array_like, (n_sats,)
        Each comb's central-tone Doppler and rate at the first block's centre
        (e.g. :func:`~leosop.signal.multicomb.find_combs` on that block).
    comb : PilotComb, optional
        The comb as the receiver sees it (:meth:`~.PilotComb.through_lo` for a large LO offset).
    doppler0_sigma_hz, rate0_sigma_hz_per_s : float
        Their prior sigmas. The first block's phase error is
        ``2 pi sigma_f T / sqrt(12)``: a block of T = 20 ms needs sigma_f below ~5 Hz.
    accel_psd_hz2_per_s5 : float
        Spectral density of the white noise driving the frequency rate
        [Hz^2/s^5]: a LEO pass's Doppler changes its rate by up to ~60
        Hz/s^2 at 11 GHz; the default lets the rate follow that within a
        fraction of a second.
    freq_psd_hz2_per_s : float
        Frequency random walk [Hz^2/s] (receiver and satellite oscillators).

    Returns
    -------
    CarrierTracks
    """
    comb = comb or PilotComb()
    fs = float(sample_rate_hz)
    f0 = np.atleast_1d(np.asarray(doppler0_hz, dtype=float))
    r0 = np.broadcast_to(np.asarray(rate0_hz_per_s, dtype=float), f0.shape)
    if f0.ndim != 1 or not np.all(np.isfinite(f0)) or not np.all(np.isfinite(r0)):
        raise InputError("doppler0_hz and rate0_hz_per_s must be finite, one per satellite")
    n_sats = f0.size
    x = np.stack([np.zeros(n_sats), f0, r0], axis=1)
    P = np.zeros((n_sats, 3, 3))
    P[:, 0, 0] = 1.0
    P[:, 1, 1] = doppler0_sigma_hz**2
    P[:, 2, 2] = rate0_sigma_hz_per_s**2
    template = np.full((n_sats, comb.n_tones), np.nan + 0j)
    arc = np.full(n_sats, -1)
    template_threshold = gamma.isf(_TEMPLATE_PFA, comb.n_tones)
    rows = []
    t_prev = None
    for t0_s, iq in blocks:
        iq = np.asarray(iq)
        t_c = float(t0_s) + 0.5 * (iq.size - 1) / fs
        if t_prev is not None:
            if not t_c > t_prev:
                raise InputError(f"blocks out of time order at t0_s={t0_s:g}")
            Phi, Q = _transition(t_c - t_prev, accel_psd_hz2_per_s5, freq_psd_hz2_per_s)
            x = x @ Phi.T
            P = Phi @ P @ Phi.T + Q
        t_prev = t_c
        Y = _correlate(iq, float(t0_s), fs, x, comb)
        noise = _noise(iq, Y)
        new = np.isnan(template[:, 0]) & (np.sum(np.abs(Y) ** 2, axis=1) / noise > template_threshold)
        template[new] = Y[new]
        s = np.sum(Y * np.conj(template), axis=1)
        snr = np.abs(s) ** 2 / (noise * np.sum(np.abs(template) ** 2, axis=1))
        lock = snr > LOCK_SNR
        z = np.angle(s) / (2 * np.pi)
        r = 1.0 / (2.0 * snr) / (2 * np.pi) ** 2
        nis = z**2 / (P[:, 0, 0] + r)
        restart = lock & ((arc < 0) | (P[:, 0, 0] > ARC_SIGMA_CYCLES**2) | (nis > SLIP_NIS))
        slip = restart & (arc >= 0) & (nis > SLIP_NIS)
        phase = np.where(lock, x[:, 0] + z, np.nan)
        x, P = _update(x, P, np.where(lock, z, 0.0), np.where(lock, r, np.inf), restart)
        arc = np.where(restart, arc + 1, arc)
        rows.append((t_c, phase, np.where(lock, np.sqrt(r), np.nan), x[:, 1].copy(), np.sqrt(P[:, 1, 1]),
                     x[:, 2].copy(), snr, lock, slip, arc.copy()))
    if not rows:
        raise InputError("no blocks to track")
    cols = list(zip(*rows))
    return CarrierTracks(np.array(cols[0]), *(np.stack(c, axis=1) for c in cols[1:]))


def _noise(iq, Y):
    """Noise power of the per-tone sums: n times the block's power less the combs' (tone power ``|Y|^2 / n^2``)."""
    n = iq.size
    power = float(np.mean(np.abs(iq) ** 2)) - float(np.sum(np.abs(Y) ** 2)) / n**2
    return n * max(power, 1e-3 * float(np.mean(np.abs(iq) ** 2)), np.finfo(float).tiny)


def _update(x, P, y, r, restart):
    """Scalar phase update of every satellite (Joseph form); ``restart`` rows take the phase afresh.

    A restarted row keeps its frequency and rate, and its phase becomes the
    measurement (a new arc: the old phase's integer is gone). ``r`` inf: no update.
    """
    x = x.copy()
    P = P.copy()
    P[restart, 0, :] = 0.0
    P[restart, :, 0] = 0.0
    P[restart, 0, 0] = np.where(np.isfinite(r[restart]), 1e6, 0.0)
    s = P[:, 0, 0] + r
    k = np.where(np.isfinite(s)[:, None], P[:, :, 0] / np.where(np.isfinite(s), s, 1.0)[:, None], 0.0)
    x += k * y[:, None]
    ikh = np.eye(3) - k[:, :, None] * np.array([1.0, 0.0, 0.0])[None, None, :]
    r_used = np.where(np.isfinite(r), r, 0.0)[:, None, None]
    P = ikh @ P @ np.swapaxes(ikh, 1, 2) + r_used * k[:, :, None] * k[:, None, :]
    return x, 0.5 * (P + np.swapaxes(P, 1, 2))


def recording_blocks(rec, block_s, *, factor=1, first=0):
    """``(t0_s, iq)`` of the blocks of a SigMF recording (:func:`~leosop.replay.pipeline.block_plan`), lazily.

    From block ``first`` on, narrowed by ``factor`` as replay narrows them
    (:func:`~leosop.replay.pipeline.narrow`: sample k of a block is input
    sample ``k factor``, so ``t0_s`` is unchanged and the rate is
    ``sample_rate_hz / factor``).
    """
    from .pipeline import block_plan, narrow

    fs = rec.sample_rate_hz
    for b in block_plan(rec, block_s)[first:]:
        yield b.t_s - 0.5 * (b.n_samples - 1) / fs, narrow(rec.read(b.start, b.n_samples), factor)


def phase_rate_doppler(tracks, window_s=1.0, degree=3):
    """Doppler at every block from the accumulated phase: the slope of a local polynomial over ``window_s``.

    A polynomial of ``degree`` in time is fitted to the phase of the locked
    blocks of one arc within ``window_s / 2`` of each block (the arc's
    unknown offset drops out of the slope); its derivative at the block is
    the Doppler, with the sigma the fit's covariance gives from the blocks'
    phase sigmas (independent from block to block, :class:`CarrierTracks`).

    Returns
    -------
    doppler_hz, sigma_hz : ndarray, (n_sats, n_blocks)
        NaN where the window holds fewer than ``2 degree + 1`` locked blocks of the same arc.
    """
    t = tracks.t_s
    dop = np.full(tracks.phase_cycles.shape, np.nan)
    sig = np.full(tracks.phase_cycles.shape, np.nan)
    for i, j in zip(*np.nonzero(tracks.lock)):
        use = tracks.lock[i] & (tracks.arc[i] == tracks.arc[i, j]) & (np.abs(t - t[j]) <= 0.5 * window_s)
        if use.sum() < 2 * degree + 1:
            continue
        tau = t[use] - t[j]
        A = tau[:, None] ** np.arange(degree + 1)
        w = 1.0 / tracks.phase_sigma_cycles[i, use]
        coef, *_ = np.linalg.lstsq(A * w[:, None], (tracks.phase_cycles[i, use] - tracks.phase_cycles[i, j]) * w,
                                   rcond=None)
        cov = np.linalg.inv((A * w[:, None]).T @ (A * w[:, None]))
        dop[i, j], sig[i, j] = coef[1], np.sqrt(cov[1, 1])
    return dop, sig


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
        raise InputError(f"{rec.data_path}: --carrier needs a continuous recording, and this one is {len(caps)} "
                         f"captures with gaps of up to {np.max(gap_s):.3g} s: carrier phase coherence is lost "
                         "across a gap (each snapshot would start a new arc); replay it without --carrier")


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
                  "doppler_sigma_hz", "lock", "slip", "arc", "in_fix")

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
                self.in_fix[i, j].astype(int).tolist())
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
                         "slips": int(np.sum(self.tracks.slip[k])), "n_phase_rate_rows": int(np.sum(self.in_fix[k])),
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

    comb = PilotComb(carrier_hz=rec.center_hz or PilotComb.carrier_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    factor, _ = search_band(rec.sample_rate_hz, comb, lo_offset_max_hz)
    shift_s = 0.5 * (factor - 1) / rec.sample_rate_hz  # a narrowed block's centre (pipeline.replay)
    t_s = np.array([b.t_s for b in res.blocks]) - shift_s
    time_utc = np.array([b.time_utc for b in res.blocks]) - np.timedelta64(int(round(shift_s * 1e9)), "ns")
    ident = [tr for tr in res.tracks if tr.sat_id is not None]
    sats = tuple(sorted({tr.sat_id for tr in ident}))
    starts = [min((tr for tr in ident if tr.sat_id == s), key=lambda tr: tr.t_s[0]) for s in sats]
    first = np.array([_block_index(t_s, tr.t_s[0]) for tr in starts], dtype=int)
    last = np.array([max(_block_index(t_s, tr.t_s[-1]) for tr in ident if tr.sat_id == s) for s in sats], dtype=int)
    lo_hz = res.lo.offset_hz if res.lo is not None and np.isfinite(res.lo.offset_hz) else 0.0
    shape = (len(sats), t_s.size)
    cols = {f.name: np.full(shape, np.nan) for f in fields(CarrierTracks) if f.name != "t_s"}
    cols.update(lock=np.zeros(shape, bool), slip=np.zeros(shape, bool), arc=np.full(shape, -1))
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
