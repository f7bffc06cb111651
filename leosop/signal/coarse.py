"""Coarse search for the pilot comb: detection in one block's FFT, and a short-time Fourier transform track.

The comb detector sums the powers of the comb's tones at each candidate
central-tone bin and compares the sum with a threshold for a false-alarm
probability over all candidates; the coarse estimate is good to its
``error_hz`` and starts the fine estimators of :mod:`leosop.signal.fine`.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ..errors import InputError
from .pilot import PilotComb

__all__ = ["MAX_DOPPLER_HZ", "MAX_RATE_HZ_PER_S", "PFA", "CoarseEstimate", "coarse_fft", "coarse_stft",
           "detection_threshold", "abs2", "parabola_vertex"]

#: Default search half-width for the central tone's Doppler [Hz]: a LEO
#: satellite at 550 km seen down to 10 deg elevation stays within +-270 kHz
#: at 11.325 GHz; above a 40 deg mask within +-210 kHz.
MAX_DOPPLER_HZ = 300e3
#: Default bound on |Doppler rate| the coarse search allows for [Hz/s]:
#: a 550 km pass through the zenith at 11.325 GHz peaks near 4 kHz/s.
MAX_RATE_HZ_PER_S = 5e3
#: False-alarm probability of the comb detector per block.
PFA = 1e-3


@dataclass(frozen=True)
class CoarseEstimate:
    """Comb detection in one spectrum.

    ``doppler_hz``: central tone at the strongest bin near the detected comb,
    interpolated; ``error_hz``: half-width of the interval it is good to
    (smear and smoothing included); ``statistic``/``threshold``: the comb
    power over its noise mean and the detector threshold; ``margin_sigma``:
    by how many noise standard deviations the comb beats the same comb
    shifted by one tone spacing (how sure the central tone is).
    """

    doppler_hz: float
    error_hz: float
    detected: bool
    statistic: float
    threshold: float
    margin_sigma: float = np.nan


@lru_cache(maxsize=64)
def detection_threshold(n_terms, n_cells, pfa):
    """Threshold on a mean of ``n_terms`` unit exponentials, false alarm ``pfa`` over ``n_cells``."""
    from scipy.special import gammainccinv

    return float(gammainccinv(n_terms, pfa / n_cells) / n_terms)


def abs2(z):
    """|z|^2 in two passes (np.abs is vectorised; real*real + imag*imag costs four)."""
    p = np.abs(z)
    return np.multiply(p, p, out=p)


def parabola_vertex(y_minus, y0, y_plus):
    """Offset in [-0.5, 0.5] of the vertex of the parabola through three equally spaced points."""
    den = y_minus - 2.0 * y0 + y_plus
    if not den < 0.0:
        return 0.0
    return float(np.clip(0.5 * (y_minus - y_plus) / den, -0.5, 0.5))


def coarse_fft(spectrum: npt.NDArray[np.complexfloating], sample_rate_hz: float, comb: PilotComb, *,
               max_doppler_hz: float = MAX_DOPPLER_HZ, smear_hz: float = 0.0, pfa: float = PFA,
               centre_hz: float = 0.0) -> CoarseEstimate:
    """Find the comb's central tone in one spectrum.

    Parameters
    ----------
    spectrum : ndarray, shape (n,)
        FFT (in FFT order) of a block of ``n`` samples.
    sample_rate_hz : float
    comb : PilotComb
    max_doppler_hz : float
        Search half-width for the central tone.
    centre_hz : float
        Centre of the search (a receiver LO offset, common to all satellites).
    smear_hz : float
        Expected spread of each tone over the block (|rate| * duration); the
        tone powers are summed over a window this wide.
    pfa : float
        False-alarm probability of the detector over the whole search.

    Returns
    -------
    CoarseEstimate
    """
    n = spectrum.shape[-1]
    df = sample_rate_hz / n
    offsets_hz = comb.offsets_hz
    # Tone k sits at k*spacing + s_k*D: the s_k - 1 part moves edge tones by
    # up to (n_tones // 2) * spacing / f_c * D relative to the centre.
    scale_spread_hz = np.max(np.abs(offsets_hz)) / comb.carrier_hz * max_doppler_hz  # max |s_k - 1| D
    spread_bins = int(np.ceil((0.5 * smear_hz + scale_spread_hz) / df))
    # Powers are summed in groups of g bins (g = 1 for steady tones): tone
    # offsets are then rounded to whole groups, so the window grows by one
    # group either side.
    g = max(1, spread_bins // 4)
    half_groups = int(np.ceil(spread_bins / g)) + (1 if g > 1 else 0)
    k_max = min(int(max_doppler_hz / df), n // 2 - 1)
    n_groups = int(np.ceil((2 * k_max + 1) / g)) + 2 * half_groups
    c_lo = int(round(centre_hz / df)) - k_max - half_groups * g  # first bin of the first candidate group
    og_k = np.round(offsets_hz / df / g).astype(int)
    lo = c_lo + og_k.min() * g
    hi = lo + (n_groups + og_k.max() - og_k.min()) * g - 1
    if hi - lo + 1 >= n:
        raise InputError(f"the comb (+-{offsets_hz.max():.0f} Hz) with +-{max_doppler_hz:.0f} Hz of Doppler "
                         f"does not fit in the {sample_rate_hz:.0f} Hz sample rate")
    if hi >= n or hi < 0:  # a search centred far off 0 Hz (an LO offset): wrapped indices
        power = abs2(spectrum[np.arange(lo, hi + 1) % n])
    elif lo < 0:  # the band wraps around bin 0: |X| of both ends in place, then squared
        power = np.empty(hi - lo + 1, dtype=spectrum.real.dtype)
        np.abs(spectrum[lo:], out=power[:-lo])
        np.abs(spectrum[:hi + 1], out=power[-lo:])
        np.multiply(power, power, out=power)
    else:
        power = abs2(spectrum[lo:hi + 1])
    # Noise mean from the median of a subsample of the band (the comb fills a
    # small fraction of it); exponential power: median = mean * ln 2. Bins
    # excised by the cleaning (zero) are not noise: a line's hole of a few
    # percent of the band would pull the median down and every statistic up.
    sub = power[::max(1, power.size // 8192)]
    kept = sub[sub > 0]
    sub = kept if kept.size else sub
    noise = float(np.partition(sub, sub.size // 2)[sub.size // 2]) / np.log(2.0)
    grouped = (power.reshape(-1, g) @ np.ones(g, dtype=power.dtype)).astype(float) if g > 1 else power.astype(float)
    comb_power = np.zeros(n_groups)
    for og in og_k - og_k.min():
        comb_power += grouped[og:og + n_groups]
    width = 2 * half_groups + 1
    csum = np.zeros(n_groups + 1)
    np.cumsum(comb_power, out=csum[1:])
    smooth = (csum[width:] - csum[:-width]) / (width * g * comb.n_tones * noise)
    j = int(np.argmax(smooth))
    stat = float(smooth[j])
    n_terms = width * g * comb.n_tones
    thr = detection_threshold(n_terms, smooth.size, pfa)  # Bonferroni over every (overlapping) window
    # Central tone: its strongest bin within the window, interpolated.
    first = c_lo + j * g
    p_win = power[first - lo: first - lo + width * g]
    b = first + int(np.argmax(p_win))
    p3 = abs2(spectrum[np.arange(b - 1, b + 2) % n])
    doppler_hz = (b + parabola_vertex(*p3)) * df
    # The strongest bin lies on the central tone's smeared track.
    error_hz = 0.5 * smear_hz + 2.0 * df
    step = int(round(comb.tone_spacing_hz / df / g))
    rival = max((smooth[i] for i in (j - step, j + step) if 0 <= i < smooth.size), default=0.0)
    margin = (stat - rival) * np.sqrt(n_terms / 2.0)
    return CoarseEstimate(doppler_hz, error_hz, stat > thr, stat, thr, float(margin))


def coarse_stft(iq: npt.NDArray[np.complexfloating], sample_rate_hz: float, comb: PilotComb | None = None, *,
                nperseg: int = 4096, hop: int | None = None, max_doppler_hz: float = MAX_DOPPLER_HZ,
                pfa: float = PFA) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
                                           npt.NDArray[np.float64]]:
    """Short-time Fourier transform and the comb's coarse Doppler track.

    Parameters
    ----------
    iq : ndarray, shape (n,)
    sample_rate_hz : float
    comb : PilotComb, optional
    nperseg, hop : int
        Hann window length and hop (default ``nperseg``) in samples.

    Returns
    -------
    t_s : ndarray, shape (n_frames,)
        Frame centres from the first sample [s].
    doppler_hz : ndarray, shape (n_frames,)
        Coarse central-tone Doppler; NaN where no comb is detected.
    f_hz : ndarray, shape (nperseg,)
        Frequencies, ascending.
    power : ndarray, shape (nperseg, n_frames)
        Spectrogram (|STFT|^2), rows ordered as ``f_hz``.
    """
    from scipy.signal import ShortTimeFFT
    from scipy.signal.windows import hann

    comb = comb or PilotComb()
    hop = hop or nperseg
    if nperseg > len(iq):
        raise InputError(f"nperseg={nperseg} is longer than the {len(iq)} samples given")
    stft = ShortTimeFFT(hann(nperseg, sym=False), hop, sample_rate_hz, fft_mode="centered")
    s = stft.stft(iq, p0=0, p1=(len(iq) - nperseg) // hop + 1, k_offset=nperseg // 2)
    t_s = stft.t(len(iq), p0=0, p1=s.shape[1], k_offset=nperseg // 2)
    doppler = np.full(s.shape[1], np.nan)
    # Hann main lobe is +-2 bins: count that as the smear of a steady tone.
    for j in range(s.shape[1]):
        col = np.fft.ifftshift(s[:, j])
        est = coarse_fft(col, sample_rate_hz, comb, max_doppler_hz=max_doppler_hz,
                         smear_hz=2.0 * sample_rate_hz / nperseg, pfa=pfa)
        if est.detected:
            doppler[j] = est.doppler_hz
    return t_s, doppler, stft.f, abs2(s)
