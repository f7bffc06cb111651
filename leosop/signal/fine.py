"""Fine Doppler estimators of the pilot comb, from a coarse estimate: ``ml``, ``fmlef`` and ``fast``.

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

Why ``fast``: every constant-tone estimator (ml and fmlef here; interpolated
DFT and Aboutanios-Mulgrew share the model) sees a LEO chirp (up to ~4 kHz/s
at 11.3 GHz: 480 Hz, ~58 FFT bins over a 0.12 s block) as a smeared peak and
misses the bound on a real pass. Zoom/chirp-z transforms cost several
full-length FFTs per rate hypothesis. Newton on the joint ML cost reaches
the bound, but on full-rate samples each evaluation costs nine complex
exponentials of N samples; after integrate-and-dump decimation one costs
~1e4 operations, so the block's FFT and the decimation product are the only
full-length passes (timings: tools/bench_doppler.py). At low C/N0 the
product transform loses first (squaring loss): when its peak is not
significant a grid of rates 1/T^2 apart is searched instead, and the comb
position is checked with the coherent tone powers, which keeps fast at the
bound down to ~25 dB-Hz per tone for 0.12 s blocks.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from .coarse import MAX_RATE_HZ_PER_S, PFA, CoarseEstimate, abs2, detection_threshold, parabola_vertex
from .crlb import crlb_frequency_hz2
from .fft import fft
from .pilot import PilotComb
from .quality import position_margin_sigma, tone_spread

__all__ = ["CombFit", "periodogram_grid", "fine_ml", "fine_fmlef", "fine_fast", "cubic_bias_hz", "start_step_hz",
           "decimation_size", "comb_phasors", "interleaved_matrix", "segment_grid", "newton_comb", "wrap_hz",
           "trimmed_tone_sum", "rate_dpt", "dechirped_peak_hz", "rate_grid_search"]

#: Tone positions decimated beyond each end of the comb to check the comb position.
_EXTRA_TONES = 2
#: Coarse margin (noise sigmas) above which the central tone is taken as sure.
_SURE_SIGMA = 10.0


@dataclass(frozen=True)
class CombFit:
    """A joint comb fit of one block (:func:`fine_fast`) and what its checks (:mod:`.quality`) need.

    ``cn0_dbhz`` is the mean over tones, ``tone_cn0_dbhz`` (n_tones,) per
    tone, ``tone_noise_ratio`` (n_tones,) each tone's residual noise as the
    frequency sees it over the white-noise level; ``crlb_sigma_hz`` the Cramér-Rao bound at the fitted C/N0s and
    ``sigma_hz`` the larger of it and the sigma the fit's residual spectrum
    implies (:func:`_residual_sigma_hz`: other satellites' tones in the
    bands); ``snr`` the coherent comb power over its noise mean,
    ``snr_threshold`` its detection threshold; ``position_margin_sigma`` and
    ``tone_spread`` as :func:`.quality.position_margin_sigma` and :func:`.quality.tone_spread`.
    """

    doppler_hz: float
    doppler_rate_hz_per_s: float
    cn0_dbhz: float
    sigma_hz: float
    crlb_sigma_hz: float
    tone_cn0_dbhz: np.ndarray
    tone_noise_ratio: np.ndarray
    snr: float
    snr_threshold: float
    position_margin_sigma: float
    tone_spread: float


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


def start_step_hz(error_hz):
    """Decade step whose +-10 steps cover the coarse error."""
    return 10.0 ** np.ceil(np.log10(max(error_hz, 1e-12) / 10.0))


def fine_ml(iq: npt.NDArray[np.complexfloating], sample_rate_hz: float, coarse_hz: float, resolution_hz: float,
            span_hz: float) -> float:
    """Grid ML (eq. 2): argmax over ``coarse_hz + [-span, span]`` at ``resolution_hz``."""
    m = int(round(span_hz / resolution_hz))
    values = periodogram_grid(iq, sample_rate_hz, coarse_hz - m * resolution_hz, resolution_hz, 2 * m + 1)
    return coarse_hz + (int(np.argmax(values)) - m) * resolution_hz


def fine_fmlef(iq: npt.NDArray[np.complexfloating], sample_rate_hz: float, coarse_hz: float, resolution_hz: float,
               start_step_hz: float) -> float:
    """FMLEF ([Shen 2024] section 2.1): decade refinement with 21 points and a parabola per level."""
    step = float(start_step_hz)
    f = float(coarse_hz)
    while True:
        values = periodogram_grid(iq, sample_rate_hz, f - 10 * step, step, 21)
        i = int(np.argmax(values))
        f = f + (i - 10) * step
        if 0 < i < 20:
            f += step * parabola_vertex(values[i - 1], values[i], values[i + 1])
        if step <= resolution_hz * (1.0 + 1e-9):
            return f
        step /= 10.0


@lru_cache(maxsize=64)
def decimation_size(n, target):
    """Segments B >= target and samples per segment L with B * L >= n (a divisor of n if one is near)."""
    target = max(16, min(int(target), n // 4))
    for b in range(target, min(2 * target, n) + 1):
        if n % b == 0:
            return b, n // b
    seg = int(np.ceil(n / target))
    return int(np.ceil(n / seg)), seg


def comb_phasors(a_cycles, b_cycles, half):
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


def interleaved_matrix(mix, dtype):
    """Real (2L, 2K) matrix acting on interleaved (re, im) samples as the complex (L, K) ``mix``."""
    m = np.empty((mix.shape[0], 2, mix.shape[1], 2), dtype=dtype)
    m[:, 0, :, 0] = m[:, 1, :, 1] = mix.real
    m[:, 0, :, 1] = mix.imag
    m[:, 1, :, 0] = -mix.imag
    return m.reshape(2 * mix.shape[0], 2 * mix.shape[1])


@lru_cache(maxsize=32)
def segment_grid(n, fs, n_seg, seg):
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


def newton_comb(y, tau, tpow, ratio, delta_hz, rate, known_cycles, n_iter=2):
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
        u = comb_phasors(phase, ratio * phase, half)
        np.multiply(u, y, out=u)
        # (5, K): sum_m u tau^p, as one real product on the interleaved parts.
        m = (tpow.T @ u.view(float)).view(complex)
        y0, m1, m2 = m[0], m[1], m[2]
        q = m[1:] * np.conj(y0)  # m_p conj(Y), p = 1..4
        # J = sum |Y_k|^2 with dY/df = -j a m1, dY/dr = -j b m2, d2Y/df2 = -a^2 m2, ...
        g_f = 2.0 * np.dot(a, q[0].imag)
        g_r = 2.0 * np.dot(b, q[1].imag)
        h_ff = 2.0 * np.dot(a2, abs2(m1) - q[1].real)
        h_fr = 2.0 * np.dot(ab, (np.conj(m1) * m2).real - q[2].real)
        h_rr = 2.0 * np.dot(b2, abs2(m2) - q[3].real)
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


def wrap_hz(f_hz, fs_hz):
    """``f_hz`` wrapped into [-fs/2, fs/2) [Hz]."""
    return (f_hz + 0.5 * fs_hz) % fs_hz - 0.5 * fs_hz


def trimmed_tone_sum(power):
    """Sum over tones (axis -2, tones first: contiguous reductions) without the largest at each bin.

    Another satellite's tone falling into one tone band then cannot outvote
    the comb, which is present in all of them (cost: one of nine tones'
    energy, 0.5 dB, in the searches only; the final fit uses every tone).
    """
    return power.sum(axis=-2) - power.max(axis=-2) if power.shape[-2] >= 5 else power.sum(axis=-2)


def rate_dpt(yt, dt_dec, pfa):
    """Rate from ``y[m + h] conj(y[m])``, a tone at ``rate h dt_dec`` (discrete polynomial-phase
    transform); None when its peak is not significant at false-alarm ``pfa``. ``yt``: (K, B)."""
    h = yt.shape[1] // 2
    v = yt[:, h:2 * h] * np.conj(yt[:, :h])
    p = trimmed_tone_sum(abs2(fft(v, 2 * h, scratch=True)))
    i = int(np.argmax(p))
    k = yt.shape[0]
    if p[i] / np.mean(p) < detection_threshold(k - 1 if k >= 5 else k, p.size, pfa):  # Gamma(k-1): conservative
        return None
    nu = (i + parabola_vertex(p[i - 1], p[i], p[(i + 1) % p.size])) / (2 * h * dt_dec)
    return wrap_hz(nu, 1.0 / dt_dec) / (h * dt_dec)


def dechirped_peak_hz(yt, tau, rate, known, dt_dec):
    """Residual frequency of the tones after removing a rate: peak of the summed zero-padded spectra.
    ``yt``: (K, B)."""
    z = yt * np.exp(-2j * np.pi * (0.5 * rate * tau**2 + known)).astype(yt.dtype)  # s_k ~ 1 is close enough
    n_fft = 2 * yt.shape[1]
    p = trimmed_tone_sum(abs2(fft(z, n_fft, scratch=True)))
    i = int(np.argmax(p))
    return wrap_hz((i + parabola_vertex(p[i - 1], p[i], p[(i + 1) % n_fft])) / (n_fft * dt_dec), 1.0 / dt_dec)


def rate_grid_search(yt, tau, known, dt_dec, max_rate_hz_per_s, dur):
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
    p = trimmed_tone_sum(abs2(fft(z, n_fft, scratch=True)))  # (J, n_fft)
    j, i = np.unravel_index(int(np.argmax(p)), p.shape)
    return float(rates[j]), wrap_hz(i / (n_fft * dt2), 1.0 / dt2)


def _residual_sigma_hz(white, tau, counts, weight):
    """Frequency sigma from the fit's residual spectrum instead of white noise (a sandwich estimate).

    To first order the frequency error is the projection of each tone's
    perturbation on ``tau``; its variance is the perturbation's spectrum
    weighted by ``|G(nu)|^2``, ``G`` the Fourier transform of ``tau``. With
    the residual periodogram ``P_k`` for the spectrum, each tone's noise
    variance becomes ``sum_b |G_b|^2 P_kb / (B sum_b |G_b|^2)``: white
    noise gives the Cramér-Rao bound again, another satellite's tone near
    the comb's frequency (where ``G`` is large) inflates it.

    Parameters
    ----------
    white : ndarray of complex, shape (B, n_tones)
        Residual per segment, scaled to the noise variance per sample.
    tau, counts : ndarray, shape (B,)
        Segment centres re the block centre [s] and samples per segment.
    weight : ndarray, shape (n_tones,)
        ``|A_k|^2 s_k^2``: tone power per sample times its Doppler scale squared.

    Returns
    -------
    sigma_hz : float
    noise_k : ndarray, shape (n_tones,)
        Each tone's noise variance per sample as the frequency sees it.
    """
    g2 = abs2(np.fft.fft(tau * counts))
    p = abs2(np.fft.fft(white, axis=0))  # (B, n_tones)
    noise_k = (g2 @ p) / (white.shape[0] * np.sum(g2))
    s2 = counts @ tau**2
    den = 2.0 * (2.0 * np.pi) ** 2 * s2 * np.sum(weight) ** 2
    return (float(np.sqrt(np.sum(weight * noise_k) / den)) if den > 0 else np.inf), noise_k


def fine_fast(iq: npt.NDArray[np.complexfloating], sample_rate_hz: float, comb: PilotComb, coarse: CoarseEstimate,
              *, max_rate_hz_per_s: float = MAX_RATE_HZ_PER_S, doppler_accel_hz_per_s2: float = 0.0,
              pfa: float = PFA, resolve: bool = True) -> CombFit:
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
        Re-estimate once if the coherent tone powers put the comb whole
        spacings from the coarse position (they are checked whenever the
        coarse search is not sure of the central tone).

    Returns
    -------
    CombFit
    """
    n = iq.shape[-1]
    fs = float(sample_rate_hz)
    dur = n / fs
    half = comb.n_tones // 2
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    # The decimated band must hold the coarse error and the smear with the
    # integrate-and-dump sinc loss under ~3 % at its edge: fs_dec >= 8x.
    bw_hz = coarse.error_hz + 0.5 * max_rate_hz_per_s * dur
    n_seg, seg = decimation_size(n, int(np.ceil(8.0 * bw_hz * dur)))
    x = iq if n_seg * seg == n else np.concatenate([iq, np.zeros(n_seg * seg - n, dtype=iq.dtype)])
    # Tone k at f_k = k spacing + s_k D = D + k spacing (1 + D / f_c).
    d_c = coarse.doppler_hz
    spacing = comb.tone_spacing_hz * (1.0 + d_c / comb.carrier_hz)
    t_l, t_m, tau, tpow = segment_grid(n, fs, n_seg, seg)
    # When the coarse search is not sure of the central tone (weak comb), two
    # more tone positions either side decide it once the fit is coherent.
    check = not coarse.margin_sigma >= _SURE_SIGMA
    extra = _EXTRA_TONES if check else 0
    wide = half + extra
    mix = comb_phasors(d_c * t_l, spacing * t_l, wide)
    # The one full-length pass: a real product on interleaved (re, im) samples
    # runs ~15 % faster than the complex one (single precision for complex64).
    xr = np.ascontiguousarray(x).view(x.real.dtype).reshape(n_seg, 2 * seg)
    y_wide = (xr @ interleaved_matrix(mix, xr.dtype)).view(x.dtype) * comb_phasors(d_c * t_m, spacing * t_m, wide)
    y = y_wide[:, extra:y_wide.shape[1] - extra]
    dt_dec = seg / fs
    known = doppler_accel_hz_per_s2 / 6.0 * tpow[:, 3]  # known cubic phase [cycles]
    rate, f_res = 0.0, None
    # The searches only start Newton: single precision, tones first (contiguous FFTs and sums).
    yt = np.ascontiguousarray(y.T, dtype=np.complex64)
    if max_rate_hz_per_s * dur**2 > 0.25:
        rate = rate_dpt(yt, dt_dec, pfa)
        if rate is None:  # the product is too weak: search a grid of rates
            rate, f_res = rate_grid_search(yt, tau, known, dt_dec, max_rate_hz_per_s, dur)
    if f_res is None:
        f_res = dechirped_peak_hz(yt, tau, rate, known, dt_dec)
    delta, rate, y_sum = newton_comb(y, tau, tpow, ratio, f_res, rate, known)
    phase = delta * tau + 0.5 * rate * tau**2 + known
    if check:
        power = abs2(np.sum(y_wide * comb_phasors(phase, ratio * phase, wide), axis=0))
        shift = int(np.argmax(np.convolve(power, np.ones(comb.n_tones), mode="valid"))) - extra
        if shift and resolve:
            moved = CoarseEstimate(d_c + delta + shift * spacing, 2.0 / dur, True, np.nan, np.nan)
            return fine_fast(iq, fs, comb, moved, max_rate_hz_per_s=max_rate_hz_per_s,
                             doppler_accel_hz_per_s2=doppler_accel_hz_per_s2, pfa=pfa, resolve=False)
    # Amplitudes and noise from the fit: y_mk = c_m A_k exp(j psi) + noise of
    # variance c_m sigma^2; the least-squares residual is sum|y|^2 - |Y|^2 / B.
    # Per tone, so that another satellite's tone in one band does not count as noise.
    energy = (np.ones(n_seg) @ np.square(y.view(float))).reshape(-1, 2).sum(axis=1)  # sum_m |y_mk|^2
    resid = np.sort(np.maximum(energy - abs2(y_sum) / n_seg, 0.0))
    sigma2 = 0.5 * float(resid[(resid.size - 1) // 2] + resid[resid.size // 2]) / ((n_seg - 1) * seg)  # median
    scale = comb.doppler_scale
    a2 = np.maximum(abs2(y_sum) - n * sigma2, 0.0) / n**2
    cn0_k = a2 * fs / sigma2 if sigma2 > 0 else np.full(comb.n_tones, np.inf)
    w = np.sum(cn0_k * scale**2)
    sigma_hz = np.sqrt(crlb_frequency_hz2(10.0 * np.log10(w), n, fs)) if w > 0 else np.inf
    mean_cn0 = np.mean(cn0_k)
    with np.errstate(divide="ignore"):
        tone_cn0_dbhz = 10.0 * np.log10(cn0_k)
    # The checks of leosop.signal.quality: coherent comb power, comb position, whiteness of the residual.
    counts = np.minimum(seg, n - np.arange(n_seg) * seg).astype(float)
    z = y * comb_phasors(phase, ratio * phase, half)
    amp = (counts @ z) / (counts @ counts)  # (n_tones,) least-squares amplitude per tone
    white = (z - counts[:, None] * amp) / np.sqrt(counts)[:, None]
    noise_sum = n * sigma2 if sigma2 > 0 else np.inf  # noise mean of a coherent sum over the block
    resid_sigma_hz, noise_k = _residual_sigma_hz(white, tau, counts, a2 * scale**2)
    snr = float(np.sum(abs2(np.sum(z, axis=0))) / noise_sum)
    n_rates = 1 + int(2.0 * max_rate_hz_per_s * dur**2)
    margin = (position_margin_sigma(power / noise_sum, comb.n_tones) if check else float(coarse.margin_sigma))
    return CombFit(doppler_hz=d_c + delta, doppler_rate_hz_per_s=rate,
                   cn0_dbhz=10.0 * np.log10(mean_cn0) if mean_cn0 > 0 else -np.inf,
                   sigma_hz=float(max(sigma_hz, resid_sigma_hz)), crlb_sigma_hz=float(sigma_hz),
                   tone_cn0_dbhz=tone_cn0_dbhz, tone_noise_ratio=noise_k / sigma2 if sigma2 > 0 else noise_k, snr=snr,
                   snr_threshold=comb.n_tones * detection_threshold(comb.n_tones, n_seg * n_rates, pfa),
                   position_margin_sigma=margin,
                   tone_spread=tone_spread(np.abs(np.sum(z, axis=0)), comb.tone_amplitudes, noise_sum, pfa))
