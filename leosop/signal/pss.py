"""PSS acquisition: frame timing and carrier frequency offset of the Starlink OFDM downlink (:mod:`.ofdm_frame`)."""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.fft

from ..errors import InputError
from .ofdm_frame import (FRAME_SAMPLES, FS_HZ, N_CP, N_FFT, N_PSS_SEGMENTS, N_SYMBOL, OFDM_CENTER_OFFSET_HZ,
                         PSS_SEGMENT_LEN, pss_spectrum, pss_time)

__all__ = ["PssAcquisition", "acquire_pss", "PSS_DETECT_THRESHOLD", "subsample_peak"]

#: Sign pattern of the lag-128 products x[n + 128] conj(x[n]) over a PSS from its first
#: sample: + over the prefix, - over segment 0 (its successor is not negated), + over segments 1-6.
_PSS_PRODUCT_RUNS = ((N_CP, 1.0), (PSS_SEGMENT_LEN, -1.0), ((N_PSS_SEGMENTS - 2) * PSS_SEGMENT_LEN, 1.0))
_PSS_PRODUCT_LEN = sum(n for n, _ in _PSS_PRODUCT_RUNS)
#: Detection threshold on the normalised lag-128 metric. On noise alone a frame's
#: metric is Rayleigh with scale 1/sqrt(2 * 928) = 0.023; its largest value over
#: the ~1000 independent cells of a frame is ~0.09, averaged over frames less.
PSS_DETECT_THRESHOLD = 0.15


@dataclass(frozen=True)
class PssAcquisition:
    """PSS acquisition result.

    ``frame_start_s`` (n_frames,): receive time of each frame's first sample
    (the PSS's prefix) from the first sample of the snippet, to a fraction of a
    sample by :func:`subsample_peak`; ``frame_number`` (n_frames,):
    frame count from the first found; ``frame_period_s``: least-squares slope
    (NaN for one frame); ``doppler_hz``: frequency offset of the OFDM centre
    from its nominal place (Doppler plus clock offsets, ambiguity +-Fs/256 =
    +-937.5 kHz); ``metric``: normalised lag-128 coherence at the PSS, mean over
    frames (1 noise-free, ~0.03 on noise); ``detected``: metric above
    :data:`PSS_DETECT_THRESHOLD`.
    """

    frame_start_s: np.ndarray
    frame_number: np.ndarray
    frame_period_s: float
    doppler_hz: float
    metric: float
    detected: bool


def _run_sums(cum, n_out, runs):
    """Sums over consecutive runs ``(length, sign +-1)`` from each of ``n_out`` starts, from a leading-zero cumsum.

    Returns shape (n_out,).

    Slices of ``cum`` (views, no gather), accumulated in place.
    """
    total = np.zeros(n_out, dtype=cum.dtype)
    offset = 0
    for n, s in runs:
        hi, lo = cum[offset + n:offset + n + n_out], cum[offset:offset + n_out]
        if s > 0:
            total += hi
            total -= lo
        else:
            total -= hi
            total += lo
        offset += n
    return total


#: Fractional delays of the table of :func:`_peak_table` [samples].
_PEAK_TABLE_DELAYS = np.linspace(-0.5, 0.5, 201)


@lru_cache(maxsize=1)
def _peak_table():
    """Peak statistic of :func:`subsample_peak` at ``_PEAK_TABLE_DELAYS`` for the PSS, increasing, (201,).

    From the PSS's periodic autocorrelation ``R(tau) = sum_k |P_k|^2
    exp(j 2 pi k tau / N) / N``, the correlation of a PSS delayed by d at
    integer lags j is ``R(j - d)``.
    """
    k = np.fft.fftfreq(N_FFT, 1.0 / N_FFT)
    lags = np.arange(-1, 2)[None, :] - _PEAK_TABLE_DELAYS[:, None]
    c = np.exp(2j * np.pi * lags[..., None] * k / N_FFT) @ (np.abs(pss_spectrum()) ** 2)
    return _peak_statistic(c)


def _peak_statistic(c):
    """(y1 - y-1) / (y-1 + y0 + y1) with y the correlations projected on the peak's phase, (...,) from (..., 3)."""
    y = np.real(c * np.conj(c[..., 1:2]))
    return (y[..., 2] - y[..., 0]) / (y[..., 0] + y[..., 1] + y[..., 2])


def _useful_correlations(seg):
    """Correlations of the PSS's useful part with ``seg`` (a PSS from its sample 1, (..., 1058)), at lags 0, 1, 2.

    The periodic autocorrelation of :func:`_peak_table` holds for the useful
    part (1024 samples); its negated prefix would bias the fraction. Returns
    shape (..., 3). (Products and sums, not a matrix product: no BLAS threads.)
    """
    useful = _useful_reference()
    return np.stack([np.sum(seg[..., N_CP + j:N_CP + j + N_FFT] * useful, axis=-1) for j in range(3)], axis=-1)


@lru_cache(maxsize=1)
def _useful_reference():
    """Conjugate of the PSS's useful part in the frame's scale (modulus 32), complex64 (1024,)."""
    return np.conj(np.sqrt(N_FFT) * pss_time()[N_CP:]).astype(np.complex64)


def subsample_peak(c):
    """Fraction of a sample to add to a PSS correlation peak, from the peak and its neighbours.

    The statistic of :func:`_peak_statistic` mapped back through its values
    for the PSS's own autocorrelation: exact without noise (a parabola
    through |c|^2 is off by up to 0.3 samples on this sharp, 240 MHz-wide
    peak).

    Parameters
    ----------
    c : ndarray of complex, (..., 3)
        Correlations at the integer peak minus one, the peak and plus one.

    Returns
    -------
    delta : ndarray, (...,), in [-0.5, 0.5]
    """
    return np.interp(_peak_statistic(np.asarray(c)), _peak_table(), _PEAK_TABLE_DELAYS)


#: Metric values computed per block: the block's temporaries stay in cache (2**15 complex128: 512 kB).
_METRIC_BLOCK = 1 << 15


def _lag_metric(x, n_metric):
    """``M(tau)`` and the normalised metric ``|M| / e`` for tau = 0 .. n_metric - 1, ((n_metric,), (n_metric,)).

    Block by block, each from its own leading-zero cumsums of the lag-128
    products and of the power (complex128 / float64): the same window sums
    as one cumsum over the snippet, with smaller partial sums.
    """
    lag, span = PSS_SEGMENT_LEN, _PSS_PRODUCT_LEN
    m_tau = np.empty(n_metric, dtype=np.complex128)
    rho = np.empty(n_metric)
    prod = np.zeros(_METRIC_BLOCK + span, dtype=np.complex128)
    energy = np.zeros(_METRIC_BLOCK + lag + span)
    for a in range(0, n_metric, _METRIC_BLOCK):
        n = min(_METRIC_BLOCK, n_metric - a)
        seg = x[a:a + n + lag + span - 1]
        np.cumsum(seg[lag:] * np.conj(seg[:-lag]), out=prod[1:n + span])
        np.cumsum(np.abs(seg).astype(np.float64) ** 2, out=energy[1:n + lag + span])
        m = _run_sums(prod, n, _PSS_PRODUCT_RUNS)
        e = _run_sums(energy, n, ((span, 1.0),))
        e += _run_sums(energy[lag:], n, ((span, 1.0),))
        e *= 0.5
        m_tau[a:a + n] = m
        rho[a:a + n] = np.abs(m) / np.maximum(e, np.finfo(float).tiny)
    return m_tau, rho


#: Zero-padded length of the PSS periodograms of the frequency refinement.
_CFO_FFT = 16 * N_FFT
#: Half-width of the residual frequency search after the lag-128 estimate [Hz]
#: (its error is ~4 kHz rms at 0 dB SNR and 8 frames, ~25 kHz at -10 dB).
_CFO_SEARCH_HZ = 100e3


def _residual_cfo_hz(x, starts, cfo_hz):
    """Residual frequency from the PSS's useful parts with the known sequence wiped off.

    Sum over frames of the zero-padded periodograms of ``x conj(pss)``
    (1024 samples each), peak within +-_CFO_SEARCH_HZ, parabolic interpolation.
    """
    ref = np.conj(np.sqrt(N_FFT) * pss_time()[N_CP:])
    first = np.round(starts).astype(np.int64) + N_CP
    first = first[first + N_FFT <= x.size]
    n = first[:, None] + np.arange(N_FFT)
    wiped = x[n] * ref * np.exp(-2j * np.pi * (cfo_hz / FS_HZ) * n)
    power = np.sum(np.abs(scipy.fft.fft(wiped, _CFO_FFT, axis=-1)) ** 2, axis=0)
    f_hz = scipy.fft.fftfreq(_CFO_FFT, 1.0 / FS_HZ)
    power[np.abs(f_hz) > _CFO_SEARCH_HZ] = 0.0
    peak = int(np.argmax(power))
    y0, y1, y2 = power[peak - 1], power[peak], power[(peak + 1) % _CFO_FFT]
    denom = y0 - 2.0 * y1 + y2
    frac = 0.5 * (y0 - y2) / denom if denom < 0 else 0.0
    return float(f_hz[peak] + frac * FS_HZ / _CFO_FFT)


def acquire_pss(iq, sample_rate_hz=FS_HZ, *, center_offset_hz=OFDM_CENTER_OFFSET_HZ, refine_samples=48):
    """Frame timing and carrier frequency offset from the PSS of a 240 MS/s snippet.

    Timing: the products ``x[n + 128] conj(x[n])`` are constant over a PSS
    but for the sign of segment 0 (:data:`_PSS_PRODUCT_RUNS`); their signed
    sum over 928 samples, ``M(tau)``, has a magnitude independent of the
    frequency offset. ``|M|`` over the energy of the window is folded modulo
    the frame length (noise averages down; code Doppler moves frames by at
    most ~9 samples per frame at 350 kHz, well inside the metric's ~100-sample
    peak); its maximum gives the first frame, and each next one is searched
    +-``refine_samples`` from the previous one plus a frame. The frequency
    offset is the phase of the sum of ``M`` at the frames over 2 pi 128 / Fs.
    Each frame's start is then refined by correlating the frequency-corrected
    snippet with the known PSS (1056 samples) over +-``refine_samples``.

    Parameters
    ----------
    iq : ndarray of complex, (n,)
        At least one frame plus a symbol; 10 ms (2.4e6 samples) holds 7 frames.
    sample_rate_hz : float
        Must be ``FS_HZ``.
    center_offset_hz : float
        Nominal OFDM centre in the snippet's baseband (default: the channel
        centre at 0 Hz, as recordings are, so +F/2).
    refine_samples : int

    Returns
    -------
    PssAcquisition
    """
    if sample_rate_hz != FS_HZ:
        raise InputError(f"acquire_pss: sample_rate_hz={sample_rate_hz} must be {FS_HZ:g} (the full channel)")
    x = np.asarray(iq)
    if x.ndim != 1 or not np.iscomplexobj(x):
        raise InputError(f"IQ samples must be a 1-D complex array, got {x.dtype} of shape {x.shape}")
    lag = PSS_SEGMENT_LEN
    n_metric = x.size - lag - _PSS_PRODUCT_LEN + 1
    if n_metric < FRAME_SAMPLES:
        raise InputError(f"acquire_pss needs at least {FRAME_SAMPLES + lag + _PSS_PRODUCT_LEN - 1} samples, "
                         f"got {x.size}")
    x = x.astype(np.complex64, copy=False)
    m_tau, rho = _lag_metric(x, n_metric)
    n_fold = n_metric // FRAME_SAMPLES
    folded = rho[:n_fold * FRAME_SAMPLES].reshape(n_fold, FRAME_SAMPLES).mean(axis=0)
    tau = [int(np.argmax(folded))]
    while tau[-1] + FRAME_SAMPLES + refine_samples < n_metric:
        lo = tau[-1] + FRAME_SAMPLES - refine_samples
        tau.append(lo + int(np.argmax(rho[lo:lo + 2 * refine_samples + 1])))
    tau = np.array(tau)
    metric = float(np.mean(rho[tau]))
    cfo_hz = float(np.angle(np.sum(m_tau[tau]))) * FS_HZ / (2.0 * np.pi * lag)
    # Refinement: correlation with the known PSS over +-refine_samples.
    ref = np.sqrt(N_FFT) * pss_time()
    starts, numbers = [], []
    for j, t0 in enumerate(tau):
        lo = t0 - refine_samples
        hi = t0 + refine_samples + N_SYMBOL
        if lo < 0 or hi > x.size:
            continue
        n = np.arange(lo, hi)
        seg = x[lo:hi] * np.exp(-2j * np.pi * (cfo_hz / FS_HZ) * n)
        peak = int(np.clip(np.argmax(np.abs(np.correlate(seg, ref, mode="valid"))), 1, 2 * refine_samples - 1))
        starts.append(lo + peak + float(subsample_peak(_useful_correlations(seg[peak - 1:peak + N_SYMBOL + 1]))))
        numbers.append(int(round((t0 - tau[0]) / FRAME_SAMPLES)))
    cfo_hz += _residual_cfo_hz(x, np.array(starts), cfo_hz)
    starts_s = np.array(starts) / FS_HZ
    numbers = np.array(numbers, dtype=np.int64)
    period = float(np.polyfit(numbers, starts_s, 1)[0]) if numbers.size > 1 else float("nan")
    return PssAcquisition(starts_s, numbers, period, cfo_hz - center_offset_hz, metric,
                          metric > PSS_DETECT_THRESHOLD)
