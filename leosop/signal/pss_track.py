"""Frame-by-frame tracking of the Starlink OFDM downlink at 240 MS/s: frame timing, Doppler, frame-timing jumps.

After :func:`.pss.acquire_pss` has found the frames at the start of a
recording, each frame's PSS is looked for within +-``TRACK_WINDOW_SAMPLES``
of its predicted start (the last start plus the receive frame period). The
windows of a batch of frames are read at once (only they are: a memory map
of a recording is touched only there), derotated by one phase ramp at the
carrier frequency so far, and correlated with the known PSS by one batched
FFT. Per frame:

- ``frame_start_s``: the correlation peak, to a fraction of a sample by
  :func:`.pss.subsample_peak`;
- ``metric``: |c|^2 over the energies of the PSS and of the window's 1056
  samples, ~SNR / (1 + SNR) per sample; on noise alone exponential with mean
  1/1056;
- ``doppler_hz``: the loop's carrier frequency plus the residual from the
  phase between the two halves of the PSS with its sequence wiped off
  (ambiguity +-117 kHz), as :attr:`.pss.PssAcquisition.doppler_hz`: a
  per-frame measurement, several kHz rms at -10 dB per sample;
- ``code_doppler_hz``: Doppler of the frame timing, ``f_ch (T_f / T_r - 1)``
  with ``T_r`` the least-squares period over ``code_window`` frames of the
  frame's timing segment. Precise (the 240 MHz-wide PSS times each frame to
  a few hundredths of a sample) but blind to clock offsets that move the
  carrier alone (a receiver's LO).

Frame-timing jumps: Qin et al. (2025) measured steps of hundreds of ns in
the frame timing of Starlink v1.x satellites about once per second. A frame
whose peak is at its window's edge, whose metric is below
:data:`TRACK_THRESHOLD` or whose start is more than ``jump_threshold_s``
from its prediction is searched again +-``REACQUIRE_SAMPLES`` about the
prediction. Found there more than the threshold away, it is flagged
(``jump``, ``jump_s`` the step) and starts a new timing segment: the code
Doppler is fitted within segments, so a step never enters it (across one it
would add ~f_ch step / window, kHz). Not found, the frame is reported with
NaN and the prediction runs on; every later frame is searched wide until
the PSS is found again. The first frame is always searched wide (the PSS's
eight 128-sample segments give 128-sample sidelobes that a weak acquisition
can start on), and the first two frames of a segment set its period rather
than being judged by it: a jump is told only from a segment's own period.
The carrier follows the residuals, a batch's mean weighted by its frames.
"""

from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..constellations import REGISTRY
from ..errors import InputError
from .ofdm_frame import FRAME_SAMPLES, FS_HZ, N_CP, N_FFT, N_SYMBOL, OFDM_CENTER_OFFSET_HZ, pss_time
from .pss import _useful_correlations, _useful_reference, acquire_pss, subsample_peak

__all__ = ["PssTrack", "track_pss", "TRACK_THRESHOLD", "TRACK_WINDOW_SAMPLES", "REACQUIRE_SAMPLES",
           "JUMP_THRESHOLD_S"]

#: Half-width of the search about each predicted start [samples]: the prediction errs by under a
#: sample (at 5 kHz/s of Doppler rate the period changes by 2e-4 samples per frame: ~0.8 sample at the
#: end of a batch of 64 predicted from a period fitted over the last 75 frames).
TRACK_WINDOW_SAMPLES = 8
#: Half-width of the search after a suspected jump [samples] (17 us: > 40 sigma of a 400 ns step).
REACQUIRE_SAMPLES = 4096
#: Detection threshold on the per-frame metric: noise alone exceeds it in one of the 8193 cells of a
#: wide search with probability 8193 exp(-0.02 * 1056) = 5e-6; a PSS at -15 dB per sample has ~0.03.
TRACK_THRESHOLD = 0.02
#: A start this far from its prediction is a jump [s] (one sample; the jumps are hundreds of ns). A
#: smaller step stays in its segment and biases the code Doppler by up to ~1.5 step / window.
JUMP_THRESHOLD_S = 4e-9
#: Frames in the least-squares period of the prediction, and most frames per batch.
_PERIOD_FRAMES = 75
_MAX_BATCH = 64
#: Frames whose mean residual frequency moves the carrier fully (fewer move it in proportion).
_CARRIER_FRAMES = 16
#: Samples read before the first frame by the default acquisition (10 ms: 7 frames).
_ACQUIRE_SAMPLES = 2_400_000


@dataclass(frozen=True)
class PssTrack:
    """Frame-by-frame PSS track (:func:`track_pss`); every array (n_frames,), frames consecutive.

    ``frame_number`` counts from the acquisition's first frame; ``frame_start_s``
    is the receive time of each frame's first sample from the recording's
    first sample (NaN where the PSS was not found); ``metric``, ``doppler_hz``,
    ``code_doppler_hz`` as in the module docstring (NaN where not found;
    code Doppler also NaN on segments of fewer than 3 frames); ``jump`` flags
    the first frame after a frame-timing jump and ``jump_s`` holds its step
    (0 elsewhere); ``segment`` numbers the spans between jumps and lost frames.
    """

    frame_number: np.ndarray
    frame_start_s: np.ndarray
    metric: np.ndarray
    doppler_hz: np.ndarray
    code_doppler_hz: np.ndarray
    jump: np.ndarray
    jump_s: np.ndarray
    segment: np.ndarray

    @property
    def found(self):
        """Frames whose PSS was found, bool (n_frames,)."""
        return np.isfinite(self.frame_start_s)


class _Correlator:
    """The PSS correlated with windows of ``2 half + N_SYMBOL`` samples at lags 0 .. 2 half, by FFT.

    The FFT (pocketfft, no BLAS: matrix products would start BLAS threads,
    which a loaded machine makes erratic) has its length and the reference's
    spectrum fixed at construction. One thread: ``workers=2`` took more CPU
    and no less wall time over a 0.1 s track (8.3-8.7 ms against 7.2-7.7 ms
    of CPU at a load average of 13 on 2 cores; batches of 64 x 1078 points).
    """

    def __init__(self, half):
        self.half = half
        self.length = 2 * half + N_SYMBOL
        self.n_fft = scipy.fft.next_fast_len(self.length)
        self.ref_fft = np.conj(scipy.fft.fft(np.sqrt(N_FFT) * pss_time(), self.n_fft)).astype(np.complex64)
        self.ramp_n = np.arange(self.length)

    def __call__(self, windows, carrier_hz):
        """Peak lag, its complex correlations (lag -1, 0, +1 on the useful part) and metric; residual frequency.

        ``windows`` (n, length) complex64 are derotated in place. Returns
        ``k`` (n,) int, ``c`` (n, 3), ``metric`` (n,), ``df_hz`` (n,).
        """
        windows *= np.exp(-2j * np.pi * (carrier_hz / FS_HZ) * self.ramp_n).astype(np.complex64)
        spec = scipy.fft.fft(windows, self.n_fft, axis=-1)
        spec *= self.ref_fft
        corr = scipy.fft.ifft(spec, axis=-1)[:, :2 * self.half + 1]
        k = np.argmax(np.abs(corr), axis=-1)
        rows = np.arange(windows.shape[0])
        at = np.clip(k, 1, 2 * self.half - 1)
        span = windows[rows[:, None], (at - 1)[:, None] + np.arange(N_SYMBOL + 2)]
        c = _useful_correlations(span)
        energy = np.sum(np.abs(windows[rows[:, None], k[:, None] + np.arange(N_SYMBOL)]) ** 2, axis=-1)
        metric = np.abs(corr[rows, k]) ** 2 / np.maximum(N_FFT * N_SYMBOL * energy, np.finfo(float).tiny)
        # Residual frequency: the PSS wiped off its useful part, phase between its halves (512 samples apart).
        useful = span[:, 1 + N_CP:1 + N_CP + N_FFT] * _useful_reference()
        half = N_FFT // 2
        rot = np.sum(useful[:, half:], axis=-1) * np.conj(np.sum(useful[:, :half], axis=-1))
        return k, c, metric, np.angle(rot) * FS_HZ / (2.0 * np.pi * half)


def _read_windows(x, lo, length):
    """Windows ``x[lo_i : lo_i + length]`` (n, length) complex64, read by slices (a memory map reads only them)."""
    return np.stack([np.asarray(x[a:a + length]) for a in lo]).astype(np.complex64, copy=False)


def track_pss(iq, acquisition=None, *, sample_rate_hz=FS_HZ, channel_hz=REGISTRY["starlink"].carrier_hz,
              center_offset_hz=OFDM_CENTER_OFFSET_HZ, jump_threshold_s=JUMP_THRESHOLD_S, code_window=75):
    """Track the PSS of one satellite frame by frame over a 240 MS/s recording (module docstring).

    Parameters
    ----------
    iq : array_like of complex, (n,)
        The recording: an ndarray or a memory map (only the PSS windows are read).
    acquisition : PssAcquisition, optional
        Of the recording's first samples (default: :func:`.pss.acquire_pss` of its first 10 ms).
    sample_rate_hz : float
        Must be ``FS_HZ``.
    channel_hz : float
        Channel centre, for the code Doppler.
    center_offset_hz : float
        Nominal OFDM centre in the recording's baseband (as :func:`.pss.acquire_pss`).
    jump_threshold_s : float
        A start further than this from its prediction is a frame-timing jump.
    code_window : int
        Frames in the least-squares period of the code Doppler (75: 0.1 s).

    Returns
    -------
    PssTrack
        Tracked from the acquisition's first frame even when it reports
        ``detected`` False: its threshold (0.15, for one snippet's lag-128
        metric) is passed only above ~-8 dB per sample, while each frame's
        matched-filter metric here detects the PSS to ~-17 dB; frames not
        found are NaN.
    """
    if sample_rate_hz != FS_HZ:
        raise InputError(f"track_pss: sample_rate_hz={sample_rate_hz} must be {FS_HZ:g} (the full channel)")
    if getattr(iq, "ndim", 1) != 1 or not np.iscomplexobj(iq):
        raise InputError(f"IQ samples must be a 1-D complex array, got {getattr(iq, 'dtype', type(iq))}")
    if not (np.isfinite(jump_threshold_s) and jump_threshold_s > 0):
        raise InputError(f"jump_threshold_s={jump_threshold_s} must be a finite number > 0")
    if int(code_window) < 3:
        raise InputError(f"code_window={code_window} must be at least 3 frames")
    n = len(iq)
    acq = acquisition if acquisition is not None else acquire_pss(np.asarray(iq[:min(n, _ACQUIRE_SAMPLES)]))
    if acq.frame_start_s.size == 0:  # (no frame whole in the snippet)
        return _track(np.zeros((0, 5)), channel_hz, center_offset_hz, int(code_window))
    period = (acq.frame_period_s * FS_HZ if np.isfinite(acq.frame_period_s)
              else FRAME_SAMPLES / (1.0 + acq.doppler_hz / channel_hz))
    state = _Loop(acq.frame_start_s[0] * FS_HZ - period, period, acq.doppler_hz + center_offset_hz)
    narrow, wide = _Correlator(TRACK_WINDOW_SAMPLES), _Correlator(REACQUIRE_SAMPLES)
    jump_samples = jump_threshold_s * FS_HZ
    rows = []  # (start [samples], metric, carrier [Hz], step [samples], jump) per frame
    while True:
        count = min(_MAX_BATCH, state.batch)
        pred = state.start + state.period * np.arange(1, count + 1)
        lo = np.round(pred).astype(np.int64) - narrow.half
        count = int(np.searchsorted(lo + narrow.length, n, side="right"))
        if count == 0:
            break
        pred, lo = pred[:count], lo[:count]
        if state.searching or lo[0] < 0:
            count = 1
        else:
            k, c, metric, df_hz = narrow(_read_windows(iq, lo, narrow.length), state.carrier_hz)
            start = lo + k + subsample_peak(c)
            bad = (k == 0) | (k == 2 * narrow.half) | (metric < TRACK_THRESHOLD)
            if not state.learning:
                bad |= np.abs(start - pred) > jump_samples
            good = int(np.argmax(bad)) if bad.any() else count
            for j in range(good):
                rows.append((start[j], metric[j], state.carrier_hz + df_hz[j], np.nan, False))
            state.accept(start[:good], df_hz[:good])
            if good == count:
                continue
            pred, lo = pred[good:good + 1], lo[good:good + 1]
        # A suspected jump (or a lost PSS): the wide search about the prediction.
        lo_w = int(np.clip(np.round(pred[0]) - wide.half, 0, max(n - wide.length, 0)))
        if lo_w + wide.length > n:
            break
        k, c, metric, df_hz = wide(_read_windows(iq, [lo_w], wide.length), state.carrier_hz)
        start = lo_w + k[0] + float(subsample_peak(c[0]))
        if metric[0] < TRACK_THRESHOLD or k[0] in (0, 2 * wide.half):  # (at an edge: the recording's)
            rows.append((np.nan, np.nan, np.nan, np.nan, False))
            state.lose(pred[0])
            continue
        step = start - pred[0]
        jumped = abs(step) > jump_samples and not state.learning
        rows.append((start, metric[0], state.carrier_hz + df_hz[0], step if jumped else 0.0, jumped))
        state.found(start, df_hz[:1], new_segment=jumped)
    return _track(np.array(rows).reshape(-1, 5), channel_hz, center_offset_hz, int(code_window))


class _Loop:
    """The tracker's state: last start [samples], frame period [samples], carrier [Hz], the segment's starts."""

    def __init__(self, start, period, carrier_hz):
        self.start, self.period, self.carrier_hz = start, period, carrier_hz
        self.segment = []  # starts of the current segment, consecutive frames
        self.batch = 1  # frames predicted at once: doubles once the period is the segment's own
        self.searching = True  # the first frame is searched wide (module docstring)

    def accept(self, starts, df_hz):
        """Frames found at ``starts`` [samples] with residual frequencies ``df_hz`` (n,).

        The carrier moves by their mean times n / _CARRIER_FRAMES (at most 1):
        one frame's residual (~6 kHz rms at -5 dB per sample, and wild when
        the PSS sits at a window's edge) moves it little.
        """
        if starts.size == 0:
            return
        self.segment.extend(starts.tolist())
        self.start = float(starts[-1])
        self.carrier_hz += float(np.mean(df_hz)) * min(1.0, starts.size / _CARRIER_FRAMES)
        recent = np.array(self.segment[-_PERIOD_FRAMES:])
        if recent.size > 1:
            m = np.arange(recent.size) - 0.5 * (recent.size - 1)
            self.period = float(np.dot(m, recent - recent[0]) / np.dot(m, m))
        self.batch = 1 if self.learning else min(2 * self.batch, _MAX_BATCH)

    @property
    def learning(self):
        """Fewer than two frames in the segment: the period is not its own yet (no jump is told from it)."""
        return len(self.segment) < 2

    def found(self, start, df_hz, *, new_segment):
        if new_segment:
            self.segment, self.batch = [], 1
        self.searching = False
        self.accept(np.array([start]), df_hz)

    def lose(self, predicted):
        self.start, self.segment, self.batch, self.searching = predicted, [], 1, True


def _track(rows, channel_hz, center_offset_hz, code_window):
    """The :class:`PssTrack` from the tracker's rows (n, 5)."""
    start, metric, carrier, step, new = rows.T
    new = new.astype(bool)
    found = np.isfinite(start)
    # A segment also ends at a lost frame: the code Doppler fits consecutive found frames only.
    breaks = new | ~found | np.concatenate(([False], ~found[:-1]))
    segment = np.cumsum(breaks)
    segment -= segment[0] if segment.size else 0
    code = np.full(start.size, np.nan)
    for s in np.unique(segment[found]):
        idx = np.flatnonzero((segment == s) & found)
        code[idx] = _sliding_doppler_hz(start[idx], code_window, channel_hz)
    return PssTrack(np.arange(start.size, dtype=np.int64), start / FS_HZ, metric, carrier - center_offset_hz,
                    code, new, np.where(new, step / FS_HZ, 0.0), segment.astype(np.int64))


def _sliding_doppler_hz(start, window, channel_hz):
    """Code Doppler at each of consecutive frames' starts [samples] (m,), LS over <= ``window`` frames about it."""
    m = start.size
    out = np.full(m, np.nan)
    if m < 3:
        return out
    i = np.arange(m, dtype=float)
    nominal = (start[-1] - start[0]) / (m - 1)
    r = start - start[0] - nominal * i  # small residuals: the sums below keep their digits
    cum = [np.concatenate(([0.0], np.cumsum(v))) for v in (np.ones(m), i, i * i, r, i * r)]
    lo = np.clip(np.arange(m) - window // 2, 0, None)
    hi = np.minimum(lo + window, m)
    lo = np.maximum(hi - window, 0)
    s0, s1, s2, sr, sir = (c[hi] - c[lo] for c in cum)
    slope = nominal + (s0 * sir - s1 * sr) / (s0 * s2 - s1 * s1)
    return channel_hz * (FRAME_SAMPLES / slope - 1.0)
