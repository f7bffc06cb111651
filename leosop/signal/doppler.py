"""Doppler of the pilot comb: coarse FFT/STFT, then fine estimation.

One interface, :func:`estimate_block` (and :func:`estimate_blocks` for a
batch), three fine methods:

``ml``
    The classical grid maximum likelihood of [Shen 2024] eq. 2 on the central
    tone, ``I(f) = |sum x[n] exp(-j 2 pi f n / fs)|^2 / N``, evaluated at every
    point of a grid at the requested resolution over +-10 start steps around
    the coarse estimate (the span the paper's Table 2 implies: at 1 Hz its ML
    costs as much as one FMLEF level, 21 evaluations).
``fmlef``
    The paper's method, faithfully: from the coarse estimate, each level
    evaluates eq. 2 at the optimum and 10 frequencies either side at a step 10x
    finer than the level before, fits a parabola through the maximum and its
    two neighbours, and moves to its vertex; levels continue down to the
    requested resolution.
``fast`` (default)
    Ours. One FFT of the block finds the comb (the sum of the nine tone powers,
    which also picks the central tone rather than the strongest one: the
    hypotheses one spacing apart differ only by the edge tones). Then one
    complex matrix product decimates each tone, mixed to baseband at its
    coarse frequency, by integrate-and-dump into B segments (B ~ 1000); the
    phase of an integrate-and-dump output is exactly the phase at the segment
    centre for a linear phase, so nothing is biased. On the (B, 9) decimated
    tones: the rate from the product ``y[m + B/2] conj(y[m])`` (a discrete
    polynomial-phase transform), the frequency from a zero-padded FFT of the
    dechirped tones, then Newton steps on the exact joint ML cost
    ``sum_k |sum_m y_k[m] exp(-j 2 pi s_k (f tau + r tau^2 / 2))|^2`` (unknown
    amplitude and phase per tone; ``s_k`` scales each tone's Doppler with its
    RF frequency).

Why this design (N = 3e5 at 2.5 MHz, tools/bench_doppler.py): every
constant-tone estimator (ml and fmlef here; interpolated DFT and
Aboutanios-Mulgrew share the model) sees a LEO chirp (up to ~4 kHz/s at
11.3 GHz: 480 Hz, ~58 FFT bins over a 0.12 s block) as a smeared peak: on a
real pass ml and fmlef miss the bound by 50x to 3000x. Zoom/chirp-z
transforms cost several full-length FFTs per rate hypothesis. Newton on the
joint ML cost reaches the bound, but on full-rate samples each evaluation
costs nine complex exponentials of N samples; after integrate-and-dump
decimation one costs ~1e4 operations. Measured (one thread, complex64):
fast = 1.75x one FFT, 40-50x faster than fmlef; beyond the FFT, the
decimation product (the only other full-length pass) takes ~0.3 FFT, the
comb search ~0.15, rate and frequency searches, Newton and the noise fit
together ~0.25.
At low C/N0 the product transform loses first (squaring loss): when its peak
is not significant a grid of rates 1/T^2 apart is searched instead, and the
comb position is checked with the coherent tone powers, which keeps fast at
the bound down to ~25 dB-Hz per tone for 0.12 s blocks.

Doppler here is the central tone's frequency at the block centre minus its
nominal frequency (DESIGN 4.2), positive when the satellite approaches.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from .crlb import crlb_frequency_hz2
from .fft import fft
from .pilot import PilotComb

__all__ = [
    "METHODS",
    "BlockEstimates",
    "CoarseEstimate",
    "coarse_fft",
    "coarse_stft",
    "periodogram_grid",
    "fine_ml",
    "fine_fmlef",
    "fine_fast",
    "cubic_bias_hz",
    "estimate_block",
    "estimate_blocks",
    "doppler_sigma_hz",
]

METHODS = ("fast", "fmlef", "ml")

#: Default search half-width for the central tone's Doppler [Hz]: a LEO
#: satellite at 550 km seen down to 10 deg elevation stays within +-270 kHz
#: at 11.325 GHz; above a 40 deg mask within +-210 kHz.
MAX_DOPPLER_HZ = 300e3
#: Default bound on |Doppler rate| the coarse search allows for [Hz/s]:
#: a 550 km pass through the zenith at 11.325 GHz peaks near 4 kHz/s.
MAX_RATE_HZ_PER_S = 5e3
#: False-alarm probability of the comb detector per block.
PFA = 1e-3
#: Tone positions decimated beyond each end of the comb to check the comb position.
_EXTRA_TONES = 2
#: Coarse margin (noise sigmas) above which the central tone is taken as sure.
_SURE_SIGMA = 10.0


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
def _threshold(n_terms, n_cells, pfa):
    """Threshold on a mean of ``n_terms`` unit exponentials, false alarm ``pfa`` over ``n_cells``."""
    from scipy.special import gammainccinv

    return float(gammainccinv(n_terms, pfa / n_cells) / n_terms)


def _abs2(z):
    """|z|^2 in two passes (np.abs is vectorised; real*real + imag*imag costs four)."""
    p = np.abs(z)
    return np.multiply(p, p, out=p)


def _parabola_vertex(y_minus, y0, y_plus):
    """Offset in [-0.5, 0.5] of the vertex of the parabola through three equally spaced points."""
    den = y_minus - 2.0 * y0 + y_plus
    if not den < 0.0:
        return 0.0
    return float(np.clip(0.5 * (y_minus - y_plus) / den, -0.5, 0.5))


def coarse_fft(spectrum, sample_rate_hz, comb, *, max_doppler_hz=MAX_DOPPLER_HZ,
               smear_hz=0.0, pfa=PFA):
    """Find the comb's central tone in one spectrum.

    Parameters
    ----------
    spectrum : ndarray, shape (n,)
        FFT (in FFT order) of a block of ``n`` samples.
    sample_rate_hz : float
    comb : PilotComb
    max_doppler_hz : float
        Search half-width for the central tone.
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
    c_lo = -k_max - half_groups * g  # first bin of the first candidate group of the central tone
    og_k = np.round(offsets_hz / df / g).astype(int)
    lo = c_lo + og_k.min() * g
    hi = lo + (n_groups + og_k.max() - og_k.min()) * g - 1
    if hi - lo + 1 >= n:
        raise InputError(f"the comb (+-{offsets_hz.max():.0f} Hz) with +-{max_doppler_hz:.0f} Hz of Doppler "
                         f"does not fit in the {sample_rate_hz:.0f} Hz sample rate")
    if lo < 0:  # the band wraps around bin 0: |X| of both ends in place, then squared
        power = np.empty(hi - lo + 1, dtype=spectrum.real.dtype)
        np.abs(spectrum[lo:], out=power[:-lo])
        np.abs(spectrum[:hi + 1], out=power[-lo:])
        np.multiply(power, power, out=power)
    else:
        power = _abs2(spectrum[lo:hi + 1])
    # Noise mean from the median of a subsample of the band (the comb fills a
    # small fraction of it); exponential power: median = mean * ln 2.
    sub = power[::max(1, power.size // 8192)]
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
    thr = _threshold(n_terms, smooth.size, pfa)  # Bonferroni over every (overlapping) window
    # Central tone: its strongest bin within the window, interpolated.
    first = c_lo + j * g
    p_win = power[first - lo: first - lo + width * g]
    b = first + int(np.argmax(p_win))
    p3 = _abs2(spectrum[np.arange(b - 1, b + 2) % n])
    doppler_hz = (b + _parabola_vertex(*p3)) * df
    # The strongest bin lies on the central tone's smeared track.
    error_hz = 0.5 * smear_hz + 2.0 * df
    step = int(round(comb.tone_spacing_hz / df / g))
    rival = max((smooth[i] for i in (j - step, j + step) if 0 <= i < smooth.size), default=0.0)
    margin = (stat - rival) * np.sqrt(n_terms / 2.0)
    return CoarseEstimate(doppler_hz, error_hz, stat > thr, stat, thr, float(margin))


def coarse_stft(iq, sample_rate_hz, comb=None, *, nperseg=4096, hop=None,
                max_doppler_hz=MAX_DOPPLER_HZ, pfa=PFA):
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
    return t_s, doppler, stft.f, _abs2(s)


def periodogram_grid(iq, sample_rate_hz, f_start_hz, step_hz, n_freqs):
    """[Shen 2024] eq. 2 at ``f_start_hz + i * step_hz``, i < n_freqs, by direct summation.

    The exponentials of a uniform grid are advanced by one complex product per
    frequency (``exp(-j 2 pi step n / fs)``), the cheapest exact direct
    evaluation; ``ml`` and ``fmlef`` share it.

    Returns
    -------
    ndarray, shape (n_freqs,)
    """
    x = np.asarray(iq, dtype=np.complex128)
    n = np.arange(x.size)
    v = x * np.exp(-2j * np.pi * ((f_start_hz / sample_rate_hz) * n % 1.0))
    w = np.exp(-2j * np.pi * ((step_hz / sample_rate_hz) * n % 1.0))
    out = np.empty(n_freqs)
    for i in range(n_freqs):
        out[i] = abs(v.sum()) ** 2 / x.size
        if i + 1 < n_freqs:
            v *= w
    return out


def _start_step(error_hz):
    """Decade step whose +-10 steps cover the coarse error."""
    return 10.0 ** np.ceil(np.log10(max(error_hz, 1e-12) / 10.0))


def fine_ml(iq, sample_rate_hz, coarse_hz, resolution_hz, span_hz):
    """Grid ML (eq. 2): argmax over ``coarse_hz + [-span, span]`` at ``resolution_hz``."""
    m = int(round(span_hz / resolution_hz))
    values = periodogram_grid(iq, sample_rate_hz, coarse_hz - m * resolution_hz, resolution_hz, 2 * m + 1)
    return coarse_hz + (int(np.argmax(values)) - m) * resolution_hz


def fine_fmlef(iq, sample_rate_hz, coarse_hz, resolution_hz, start_step_hz):
    """FMLEF ([Shen 2024] section 2.1): decade refinement with 21 points and a parabola per level."""
    step = float(start_step_hz)
    f = float(coarse_hz)
    while True:
        values = periodogram_grid(iq, sample_rate_hz, f - 10 * step, step, 21)
        i = int(np.argmax(values))
        f = f + (i - 10) * step
        if 0 < i < 20:
            f += step * _parabola_vertex(values[i - 1], values[i], values[i + 1])
        if step <= resolution_hz * (1.0 + 1e-9):
            return f
        step /= 10.0


@lru_cache(maxsize=64)
def _decimation(n, target):
    """Segments B >= target and samples per segment L with B * L >= n (a divisor of n if one is near)."""
    target = max(16, min(int(target), n // 4))
    for b in range(target, min(2 * target, n) + 1):
        if n % b == 0:
            return b, n // b
    seg = int(np.ceil(n / target))
    return int(np.ceil(n / seg)), seg


def _phasors(a_cycles, b_cycles, half):
    """exp(-j 2 pi (a + k b)) for k = -half..half, shape (len(a), 2 half + 1).

    One exponential call for both phases and a product per further column:
    the tones of the comb differ by whole multiples of one phase.
    """
    n = a_cycles.size
    e = np.exp(-2j * np.pi * np.concatenate([a_cycles - np.round(a_cycles), b_cycles - np.round(b_cycles)]))
    z = e[n:]
    out = np.empty((n, 2 * half + 1), dtype=complex)
    out[:, half] = e[:n]
    z_conj = np.conj(z)
    for k in range(1, half + 1):
        np.multiply(out[:, half + k - 1], z, out=out[:, half + k])
        np.multiply(out[:, half - k + 1], z_conj, out=out[:, half - k])
    return out


def _interleaved(mix, dtype):
    """Real (2L, 2K) matrix acting on interleaved (re, im) samples as the complex (L, K) ``mix``."""
    m = np.empty((mix.shape[0], 2, mix.shape[1], 2), dtype=dtype)
    m[:, 0, :, 0] = m[:, 1, :, 1] = mix.real
    m[:, 0, :, 1] = mix.imag
    m[:, 1, :, 0] = -mix.imag
    return m.reshape(2 * mix.shape[0], 2 * mix.shape[1])


@lru_cache(maxsize=32)
def _segments(n, fs, n_seg, seg):
    """Decimation grid: sample times in a segment, segment start times, segment centres re the
    block centre (tau), and tau^0..tau^4 (B, 5). Read-only, cached per block geometry."""
    t_l = np.arange(seg) / fs
    t_m = np.arange(n_seg) * (seg / fs)
    counts = np.minimum(seg, n - np.arange(n_seg) * seg)
    tau = t_m + 0.5 * (counts - 1) / fs - 0.5 * (n - 1) / fs
    tpow = np.cumprod(np.concatenate([np.ones((n_seg, 1)), np.repeat(tau[:, None], 4, axis=1)], axis=1), axis=1)
    for a in (t_l, t_m, tau, tpow):
        a.flags.writeable = False
    return t_l, t_m, tau, tpow


def _newton(y, tau, tpow, ratio, delta_hz, rate, known_cycles, n_iter=2):
    """Maximise J(f, r) = sum_k |sum_m y_mk exp(-j 2 pi s_k (f tau + r tau^2/2 + c))|^2 by Newton steps.

    ``s_k = 1 + k ratio`` (k = -half..half); ``c`` (B,) a known phase in
    cycles (the cubic term of a predicted rate change). Returns ``(f, r, Y)`` with ``Y``
    (n_tones,) the phase-aligned sums at the optimum (to first order).
    """
    half = y.shape[1] // 2
    scale = 1.0 + ratio * np.arange(-half, half + 1)
    a = 2.0 * np.pi * scale  # dpsi/df = a tau
    b = np.pi * scale        # dpsi/dr = b tau^2
    a2, ab, b2 = a * a, a * b, b * b
    f, r = float(delta_hz), float(rate)
    step_f = step_r = 0.0
    for _ in range(n_iter):
        phase = f * tau + (0.5 * r) * tpow[:, 2] + known_cycles
        u = _phasors(phase, ratio * phase, half)
        np.multiply(u, y, out=u)
        # (5, K): sum_m u tau^p, as one real product on the interleaved parts.
        m = (tpow.T @ u.view(float)).view(complex)
        y0, m1, m2 = m[0], m[1], m[2]
        q = m[1:] * np.conj(y0)  # m_p conj(Y), p = 1..4
        # J = sum |Y_k|^2 with dY/df = -j a m1, dY/dr = -j b m2, d2Y/df2 = -a^2 m2, ...
        g_f = 2.0 * np.dot(a, q[0].imag)
        g_r = 2.0 * np.dot(b, q[1].imag)
        h_ff = 2.0 * np.dot(a2, _abs2(m1) - q[1].real)
        h_fr = 2.0 * np.dot(ab, (np.conj(m1) * m2).real - q[2].real)
        h_rr = 2.0 * np.dot(b2, _abs2(m2) - q[3].real)
        det = h_ff * h_rr - h_fr * h_fr
        if not (np.isfinite(det) and h_ff < 0.0 and det > 0.0):
            step_f = step_r = 0.0
            break
        step_f = -(h_rr * g_f - h_fr * g_r) / det
        step_r = -(h_ff * g_r - h_fr * g_f) / det
        f, r = f + step_f, r + step_r
    return f, r, y0 - 1j * (step_f * a * m1 + step_r * b * m2)


def cubic_bias_hz(doppler_accel_hz_per_s2, n_samples, sample_rate_hz):
    """Frequency bias of a (frequency, rate) fit caused by a rate change ``a``.

    The phase term ``2 pi a tau^3 / 6`` projects onto ``2 pi f tau`` with
    weight ``sum tau^4 / sum tau^2 = (3 N^2 - 7) / (20 fs^2)``.
    """
    n = np.asarray(n_samples, dtype=float)
    return np.asarray(doppler_accel_hz_per_s2) / 6.0 * (3.0 * n**2 - 7.0) / (20.0 * sample_rate_hz**2)


def _wrap(f_hz, fs_hz):
    return (f_hz + 0.5 * fs_hz) % fs_hz - 0.5 * fs_hz


def _trimmed_sum(power):
    """Sum over tones (axis -2, tones first: contiguous reductions) without the largest at each bin.

    Another satellite's tone falling into one tone band then cannot outvote
    the comb, which is present in all of them (cost: one of nine tones'
    energy, 0.5 dB, in the searches only; the final fit uses every tone).
    """
    return power.sum(axis=-2) - power.max(axis=-2) if power.shape[-2] >= 5 else power.sum(axis=-2)


def _rate_dpt(yt, dt_dec, pfa):
    """Rate from ``y[m + h] conj(y[m])``, a tone at ``rate h dt_dec`` (discrete polynomial-phase
    transform); None when its peak is not significant at false-alarm ``pfa``. ``yt``: (K, B)."""
    h = yt.shape[1] // 2
    v = yt[:, h:2 * h] * np.conj(yt[:, :h])
    p = _trimmed_sum(_abs2(fft(v, 2 * h, scratch=True)))
    i = int(np.argmax(p))
    k = yt.shape[0]
    if p[i] / np.mean(p) < _threshold(k - 1 if k >= 5 else k, p.size, pfa):  # Gamma(k-1): conservative
        return None
    nu = (i + _parabola_vertex(p[i - 1], p[i], p[(i + 1) % p.size])) / (2 * h * dt_dec)
    return _wrap(nu, 1.0 / dt_dec) / (h * dt_dec)


def _dechirped_peak(yt, tau, rate, known, dt_dec):
    """Residual frequency of the tones after removing a rate: peak of the summed zero-padded spectra.
    ``yt``: (K, B)."""
    z = yt * np.exp(-2j * np.pi * (0.5 * rate * tau**2 + known)).astype(yt.dtype)  # s_k ~ 1 is close enough
    n_fft = 2 * yt.shape[1]
    p = _trimmed_sum(_abs2(fft(z, n_fft, scratch=True)))
    i = int(np.argmax(p))
    return _wrap((i + _parabola_vertex(p[i - 1], p[i], p[(i + 1) % n_fft])) / (n_fft * dt_dec), 1.0 / dt_dec)


def _rate_grid(yt, tau, known, dt_dec, max_rate_hz_per_s, dur):
    """(rate, frequency) of the largest dechirped comb power over rates 1/T^2 apart (low C/N0 fallback).

    Pairs of segments are summed first: the band still holds the residual
    tones and the search costs half as much. ``yt``: (K, B).
    """
    m = yt.shape[1] // 2 * 2
    y2 = yt[:, :m:2] + yt[:, 1:m:2]
    t2 = 0.5 * (tau[:m:2] + tau[1:m:2])
    k2 = 0.5 * (known[:m:2] + known[1:m:2])
    dt2 = 2.0 * dt_dec
    rates = np.arange(-max_rate_hz_per_s, max_rate_hz_per_s + 1.0 / dur**2, 1.0 / dur**2)
    z = y2 * np.exp(-2j * np.pi * (0.5 * rates[:, None] * t2**2 + k2))[:, None, :].astype(yt.dtype)  # (J, K, B/2)
    n_fft = 2 * y2.shape[1]
    p = _trimmed_sum(_abs2(fft(z, n_fft, scratch=True)))  # (J, n_fft)
    j, i = np.unravel_index(int(np.argmax(p)), p.shape)
    return float(rates[j]), _wrap(i / (n_fft * dt2), 1.0 / dt2)


def fine_fast(iq, sample_rate_hz, comb, coarse, *, max_rate_hz_per_s=MAX_RATE_HZ_PER_S,
              doppler_accel_hz_per_s2=0.0, pfa=PFA, resolve=True):
    """Joint comb ML of Doppler and Doppler rate on integrate-and-dump decimated tones.

    Parameters
    ----------
    iq : ndarray, shape (n,)
    sample_rate_hz : float
    comb : PilotComb
    coarse : CoarseEstimate
    max_rate_hz_per_s : float
        Bound on |rate|; 0 skips the rate search (the rate is still refined).
    doppler_accel_hz_per_s2 : float
        Known (predicted) change of the rate, put into the phase model as
        ``a tau^3 / 6``. Ignored, it biases the frequency by
        :func:`cubic_bias_hz` (a T^2 / 40: 0.009 Hz at LEO's ~37 Hz/s^2 for
        0.1 s blocks, ~0.9 Hz for 1 s blocks). Estimating ``a`` as a fourth
        unknown would cost a factor 2.5 in sigma.
    pfa : float
        False-alarm probability of the rate transform's peak (below it, a rate grid is searched).
    resolve : bool
        Check the comb position (central tone) with the coherent tone powers
        and re-estimate once if the coarse search was off by whole spacings.

    Returns
    -------
    doppler_hz, doppler_rate_hz_per_s, cn0_dbhz, sigma_hz : float
    """
    n = iq.shape[-1]
    fs = float(sample_rate_hz)
    dur = n / fs
    half = comb.n_tones // 2
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    # The decimated band must hold the coarse error and the smear with the
    # integrate-and-dump sinc loss under ~3 % at its edge: fs_dec >= 8x.
    bw_hz = coarse.error_hz + 0.5 * max_rate_hz_per_s * dur
    n_seg, seg = _decimation(n, int(np.ceil(8.0 * bw_hz * dur)))
    x = iq if n_seg * seg == n else np.concatenate([iq, np.zeros(n_seg * seg - n, dtype=iq.dtype)])
    # Tone k at f_k = k spacing + s_k D = D + k spacing (1 + D / f_c).
    d_c = coarse.doppler_hz
    spacing = comb.tone_spacing_hz * (1.0 + d_c / comb.carrier_hz)
    t_l, t_m, tau, tpow = _segments(n, fs, n_seg, seg)
    # When the coarse search is not sure of the central tone (weak comb), two
    # more tone positions either side decide it once the fit is coherent.
    resolve = resolve and not coarse.margin_sigma >= _SURE_SIGMA
    extra = _EXTRA_TONES if resolve else 0
    wide = half + extra
    mix = _phasors(d_c * t_l, spacing * t_l, wide)
    # The one full-length pass: a real product on interleaved (re, im) samples
    # runs ~15 % faster than the complex one (single precision for complex64).
    xr = np.ascontiguousarray(x).view(x.real.dtype).reshape(n_seg, 2 * seg)
    y_wide = (xr @ _interleaved(mix, xr.dtype)).view(x.dtype) * _phasors(d_c * t_m, spacing * t_m, wide)
    y = y_wide[:, extra:y_wide.shape[1] - extra]
    dt_dec = seg / fs
    known = doppler_accel_hz_per_s2 / 6.0 * tpow[:, 3]  # known cubic phase [cycles]
    rate, f_res = 0.0, None
    # The searches only start Newton: single precision, tones first (contiguous FFTs and sums).
    yt = np.ascontiguousarray(y.T, dtype=np.complex64)
    if max_rate_hz_per_s * dur**2 > 0.25:
        rate = _rate_dpt(yt, dt_dec, pfa)
        if rate is None:  # the product is too weak: search a grid of rates
            rate, f_res = _rate_grid(yt, tau, known, dt_dec, max_rate_hz_per_s, dur)
    if f_res is None:
        f_res = _dechirped_peak(yt, tau, rate, known, dt_dec)
    delta, rate, y_sum = _newton(y, tau, tpow, ratio, f_res, rate, known)
    if resolve:
        phase = delta * tau + 0.5 * rate * tau**2 + known
        power = _abs2(np.sum(y_wide * _phasors(phase, ratio * phase, wide), axis=0))
        shift = int(np.argmax(np.convolve(power, np.ones(comb.n_tones), mode="valid"))) - extra
        if shift:
            moved = CoarseEstimate(d_c + delta + shift * spacing, 2.0 / dur, True, np.nan, np.nan)
            return fine_fast(iq, fs, comb, moved, max_rate_hz_per_s=max_rate_hz_per_s,
                             doppler_accel_hz_per_s2=doppler_accel_hz_per_s2, pfa=pfa, resolve=False)
    # Amplitudes and noise from the fit: y_mk = c_m A_k exp(j psi) + noise of
    # variance c_m sigma^2; the least-squares residual is sum|y|^2 - |Y|^2 / B.
    # Per tone, so that another satellite's tone in one band does not count as noise.
    energy = (np.ones(n_seg) @ np.square(y.view(float))).reshape(-1, 2).sum(axis=1)  # sum_m |y_mk|^2
    resid = np.sort(np.maximum(energy - _abs2(y_sum) / n_seg, 0.0))
    sigma2 = 0.5 * float(resid[(resid.size - 1) // 2] + resid[resid.size // 2]) / ((n_seg - 1) * seg)  # median
    scale = comb.doppler_scale
    a2 = np.maximum(_abs2(y_sum) - n * sigma2, 0.0) / n**2
    cn0_k = a2 * fs / sigma2 if sigma2 > 0 else np.full(comb.n_tones, np.inf)
    w = np.sum(cn0_k * scale**2)
    sigma_hz = np.sqrt(crlb_frequency_hz2(10.0 * np.log10(w), n, fs)) if w > 0 else np.inf
    mean_cn0 = np.mean(cn0_k)
    cn0_dbhz = 10.0 * np.log10(mean_cn0) if mean_cn0 > 0 else -np.inf
    return d_c + delta, rate, cn0_dbhz, sigma_hz


@dataclass
class BlockEstimates:
    """Estimates for a batch of blocks, each field shape (n_blocks,); NaN where not detected."""

    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray
    detected: np.ndarray


def _check_iq(iq, sample_rate_hz):
    if not np.isfinite(sample_rate_hz) or sample_rate_hz <= 0:
        raise InputError(f"sample_rate_hz={sample_rate_hz} must be a finite number > 0")
    iq = np.asarray(iq)
    if iq.ndim != 1 or not np.iscomplexobj(iq):
        raise InputError(f"IQ samples must be a 1-D complex array, got {iq.dtype} of shape {iq.shape}")
    return iq


def _check_finite(value):
    """A NaN or inf sample makes every FFT bin (and any sum) non-finite."""
    if not np.isfinite(value):
        raise InputError("IQ samples contain NaN or inf")


def estimate_block(iq, sample_rate_hz, *, method="fast", comb=None, resolution_hz=1e-3,
                   coarse_hz=None, coarse_error_hz=None, max_doppler_hz=MAX_DOPPLER_HZ,
                   max_rate_hz_per_s=MAX_RATE_HZ_PER_S, doppler_accel_hz_per_s2=0.0, pfa=PFA):
    """Doppler of the comb's central tone at the centre of one block.

    Parameters
    ----------
    iq : ndarray of complex, shape (n,)
    sample_rate_hz : float
    method : {"fast", "fmlef", "ml"}
    comb : PilotComb, optional
    resolution_hz : float
        Final step of ``ml`` and ``fmlef`` (``fast`` is continuous).
    coarse_hz, coarse_error_hz : float, optional
        An outside coarse estimate (e.g. the STFT track) and its half-width;
        by default the block's own FFT provides them.
    max_doppler_hz, max_rate_hz_per_s, pfa : float
        Search limits and false-alarm probability of the comb detector.
    doppler_accel_hz_per_s2 : float
        Predicted rate of change of the Doppler rate (``fast``; see :func:`fine_fast`).

    Returns
    -------
    dict with ``doppler_hz``, ``doppler_rate_hz_per_s`` (``fast`` only, else
    NaN), ``cn0_dbhz``, ``sigma_hz`` (NaN for ml/fmlef: no per-block model),
    ``detected``. Everything but ``detected`` is NaN when no pilot is found.
    """
    if method not in METHODS:
        raise InputError(f"method={method!r} must be one of {', '.join(METHODS)}")
    if not resolution_hz > 0:
        raise InputError(f"resolution_hz={resolution_hz} must be > 0")
    comb = comb or PilotComb()
    iq = _check_iq(iq, sample_rate_hz)
    nan = float("nan")
    out = dict(doppler_hz=nan, doppler_rate_hz_per_s=nan, cn0_dbhz=nan, sigma_hz=nan, detected=False)
    dur = iq.shape[-1] / sample_rate_hz
    if coarse_hz is None:
        smear = max_rate_hz_per_s * dur if method == "fast" else 0.0
        spectrum = fft(iq, scratch=True)
        _check_finite(spectrum[0])
        coarse = coarse_fft(spectrum, sample_rate_hz, comb, max_doppler_hz=max_doppler_hz,
                            smear_hz=smear, pfa=pfa)
        if not coarse.detected:
            return out
    else:
        _check_finite(np.sum(iq))
        if not np.isfinite(coarse_hz):
            return out
        err = coarse_error_hz if coarse_error_hz is not None else sample_rate_hz / iq.shape[-1]
        coarse = CoarseEstimate(float(coarse_hz), float(err), True, nan, nan)
    out["detected"] = True
    if method == "fast":
        d, r, c, s = fine_fast(iq, sample_rate_hz, comb, coarse, max_rate_hz_per_s=max_rate_hz_per_s,
                               doppler_accel_hz_per_s2=doppler_accel_hz_per_s2, pfa=pfa)
        out.update(doppler_hz=d, doppler_rate_hz_per_s=r, cn0_dbhz=c, sigma_hz=s)
        return out
    # The paper's estimators start from the strongest bin of the central tone,
    # good to half a bin when the tone is steady.
    start = _start_step(coarse.error_hz if coarse_hz is not None else 0.5 * sample_rate_hz / iq.shape[-1])
    if method == "fmlef":
        out["doppler_hz"] = fine_fmlef(iq, sample_rate_hz, coarse.doppler_hz, resolution_hz, start)
    else:
        out["doppler_hz"] = fine_ml(iq, sample_rate_hz, coarse.doppler_hz, resolution_hz, 10.0 * start)
    return out


def estimate_blocks(iq_blocks, sample_rate_hz, *, method="fast", comb=None, resolution_hz=1e-3,
                    max_doppler_hz=MAX_DOPPLER_HZ, max_rate_hz_per_s=MAX_RATE_HZ_PER_S,
                    doppler_accel_hz_per_s2=0.0, pfa=PFA, show_progress=False):
    """:func:`estimate_block` over the rows of ``iq_blocks`` (n_blocks, n_samples).

    ``doppler_accel_hz_per_s2`` may be a scalar or one value per block
    (e.g. predicted from the orbits).

    Returns
    -------
    BlockEstimates
    """
    from ..progress import progress

    blocks = np.asarray(iq_blocks)
    if blocks.ndim != 2:
        raise InputError(f"iq_blocks must have shape (n_blocks, n_samples), got {blocks.shape}")
    comb = comb or PilotComb()
    accel = np.broadcast_to(np.asarray(doppler_accel_hz_per_s2, dtype=float), blocks.shape[:1])
    rows = [estimate_block(b, sample_rate_hz, method=method, comb=comb, resolution_hz=resolution_hz,
                           max_doppler_hz=max_doppler_hz, max_rate_hz_per_s=max_rate_hz_per_s,
                           doppler_accel_hz_per_s2=a, pfa=pfa)
            for b, a in zip(progress(blocks, desc="doppler", unit="block") if show_progress else blocks, accel)]
    cols = {k: np.array([r[k] for r in rows]) for k in rows[0]} if rows else {}
    return BlockEstimates(**{k: cols.get(k, np.empty(0)) for k in BlockEstimates.__dataclass_fields__})


def doppler_sigma_hz(cn0_dbhz, block_s, *, comb=None, method="fast", sample_rate_hz=2.5e6):
    """Standard deviation of a block's Doppler estimate [Hz] (error model for measurement-level runs).

    Above threshold the estimators reach the Cramér-Rao bound (validated by
    tools/bench_doppler.py and tests/test_doppler.py): ``fast`` the bound of
    the whole comb, ``ml`` and ``fmlef`` that of the central tone alone.
    Quantisation of ml/fmlef (their resolution / sqrt(12)) is not included.

    Parameters
    ----------
    cn0_dbhz : float or array_like
        C/N0 per unit-amplitude tone [dB-Hz].
    block_s : float or array_like
        Block length [s].

    Returns
    -------
    ndarray, broadcast shape of the inputs
    """
    comb = comb or PilotComb()
    n = np.round(np.asarray(block_s, dtype=float) * sample_rate_hz)
    if method == "fast":
        var = crlb_frequency_hz2(cn0_dbhz, n, sample_rate_hz, amplitudes=comb.tone_amplitudes,
                                 doppler_scale=comb.doppler_scale)
    else:
        a_c = comb.tone_amplitudes[comb.n_tones // 2]
        var = crlb_frequency_hz2(cn0_dbhz, n, sample_rate_hz, amplitudes=[a_c])
    return np.sqrt(var)
