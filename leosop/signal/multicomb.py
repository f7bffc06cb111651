"""Every pilot comb in a block: successive interference cancellation.

A Starlink recording carries the combs of several satellites interleaved in
one band. :func:`find_combs` finds them one at a time, strongest first, with
the single-comb ``fast`` machinery of :mod:`leosop.signal.fine`, cancelling
each comb once found [successive interference cancellation, as in the
multi-satellite Starlink receivers of Humphreys 2023 and Kozhaya 2023]:

1. One FFT of the block. The comb detector (:func:`~.doppler.coarse_fft`,
   false-alarm probability ``pfa`` per search) runs on the spectrum with every
   comb found so far subtracted.
2. A detected comb is decimated as ``fast`` does (integrate-and-dump into B
   segments per tone, mixed at the coarse frequency), here from the block's
   FFT (:class:`_Grid`), the contributions of the combs already found are removed from
   its (B, tones) matrix, and rate search, frequency search and Newton on the
   joint ML cost follow (``fast``'s own helpers). The coherent tone powers
   at two more tone positions either side then fix the comb position (always:
   another satellite's strong tone next to an edge tone can make the
   spectrum prefer the comb shifted by one spacing; it does not follow this
   comb's chirp, so the coherent check sees through it).
3. Per tone, the complex amplitude by least squares on the chirp model.
   The comb is subtracted from the spectrum (tone by tone over a window of
   ``B_s`` bins, from ``B_s`` samples of the model and one short FFT; exact
   to the within-segment chirp curvature, ~1e-4 rad) and the search repeats.
4. After the last detection, ``n_refine`` passes re-estimate every comb
   (Newton from its estimate) with all the others removed from its decimated
   tones, so early estimates lose the bias of combs found later. Each pass
   treats all combs at once (one leakage product, one batched Newton), each
   cleaned with the others' estimates of the previous pass (Jacobi).

Tracking (``predicted_hz`` and ``predicted_rate_hz_per_s`` given,
``batch=True``): all predictions are decimated in one matrix product and
fitted at once from their own tones (dechirped peak, Newton, position
check), then the refinement passes clean them. ``batch=False`` fits them
one after another as the search does; both end within ~0.03 sigma of each
other (tests/test_multicomb.py). A replay that tracks should call with the
previous block's estimates propagated (``doppler_hz + rate * block_s``,
the rate) and ``search=False``, and with ``search=True`` every k-th block
(and whenever a track is lost) to pick up rising satellites: the search
costs ~2x the tracking fit.

Contributions of one comb to another's decimated tones are closed forms: a
tone at local frequency nu in segment m, seen by a channel mixed at f_c,
gives its value at the segment centre times the Dirichlet kernel
``sin(pi (nu - f_c) L / fs) / sin(pi (nu - f_c) / fs)`` and the channel's
mixing phase. Only tones within ``_LEAK_BANDS`` decimated bands of a channel
are counted, the reach of the frequency-domain decimation (:class:`_Grid`):
farther tones reach the channel only through their own spectral sidelobes.

Ambiguities
-----------
*Comb shifted by one spacing*: handled by the coherent check (step 2).
*Nearly coinciding tones* (Doppler difference ``m * spacing + delta``):
measured at 0.05 s blocks, 45 dB-Hz (tests/test_multicomb.py): with
``delta`` = 150 Hz (7.5/T) and rates 2 kHz/s apart both combs are found
within 1 sigma; at the same rate and ``m = 0`` with ``delta`` = 0.5 Hz one
comb is reported (a candidate within 2/T, modulo the spacing, and 4/T^2 in
rate of a comb already found is taken as its residue, subtracted and not
reported; the search goes on, up to three residues per block).
Not handled: ``delta`` of ~2-3/T with similar rates gives biased estimates
(~6 sigma seen) or a third, spurious comb; ``m = +-1`` with ``delta`` below
~1/T gives spurious combs (the pair looks like one ten-tone comb).

Cost (tools/bench_multicomb.py; CPU time, one core, 7 combs, 0.1 s at 2.5 MS/s;
numbers in the commit log): one FFT of the block feeds every channel; in
tracking mode the decimated band covers only the gate and the predicted chirp
(B ~200 segments instead of ~500, and the leakage cost goes with B^2), the
cross-comb leakage is a Dirichlet kernel per pair of a tone and a channel
within reach at every segment, and Newton, amplitude fits and bookkeeping the
rest. Transcendentals are single precision (1e-7 rad).

Output order is detection order (strongest first in the full search;
predicted combs first, in the order given, in tracking mode).
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from .crlb import crlb_frequency_hz2
from .coarse import MAX_DOPPLER_HZ, MAX_RATE_HZ_PER_S, PFA, _abs2, _threshold, coarse_fft
from .fine import (_decimation, _dechirped_peak, _newton, _phasors, _rate_dpt, _rate_grid, _segments, _trimmed_sum,
                   _wrap)
from .fft import fft
from .frontend import clean_block
from .pilot import PilotComb

__all__ = ["Combs", "NonFiniteSamples", "find_combs"]

#: Tone positions decimated beyond each end of a comb for the coherent position check.
_EXTRA = 2
#: Aliases either side of a channel kept by the frequency-domain decimation (whole decimated bands;
#: half a band more is kept, so the reach is ``_LEAK_BANDS``): what is decimated is what is modelled.
#: Two bands: RMSE/CRLB as with four (0.96 on 7-comb blocks), half the work.
_ALIAS_BANDS = 2
#: Channels count another comb's tone within this many decimated bandwidths.
_LEAK_BANDS = _ALIAS_BANDS + 0.5
#: Decimated rate over the band a tracked tone can cover (the search uses 8).
_TRACK_OVERSAMPLE = 4.0


class NonFiniteSamples(InputError):
    """The block holds NaN or inf samples (seen in its FFT: every bin turns NaN)."""


@dataclass(frozen=True)
class Combs:
    """Combs found in one block, arrays of shape (n_found,) unless stated.

    Attributes
    ----------
    doppler_hz : central-tone Doppler at the block centre [Hz].
    doppler_rate_hz_per_s : its rate [Hz/s].
    cn0_dbhz : mean C/N0 of the tones [dB-Hz].
    sigma_hz : Cramér-Rao sigma of ``doppler_hz`` from the fitted tone C/N0s [Hz].
    amplitudes : (n_found, n_tones) complex amplitude of each tone at the block
        centre (sample units; ``|a|^2 fs / N0`` is the tone's C/N0).
    statistic : coherent comb power over noise, mean over tones (~1 for noise only).
    predicted_index : index into ``predicted_hz`` of the prediction a comb was
        found at, -1 for a comb found by the search.
    """

    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray
    amplitudes: np.ndarray
    statistic: np.ndarray
    predicted_index: np.ndarray

    @property
    def n_found(self):
        return self.doppler_hz.size


@lru_cache(maxsize=16)
def _alias_weights(n_fft, n_seg, seg):
    """Bin offsets from a channel, (R,), the integrate-and-dump response there over ``seg`` (R,)
    complex, and the fraction of the decimated noise they keep (see :class:`_Grid`)."""
    k = np.arange(-(_ALIAS_BANDS * n_seg + n_seg // 2), (_ALIAS_BANDS + 1) * n_seg - n_seg // 2)
    x = np.pi * k / n_fft
    sin_x = np.sin(x)
    safe = np.where(sin_x == 0.0, 1.0, sin_x)
    g = np.where(sin_x == 0.0, float(seg), np.sin(seg * x) / safe) * np.exp(1j * (seg - 1) * x)
    noise_gain = float(np.sum(np.abs(g) ** 2) / (n_fft * seg))
    g = (g / seg).astype(np.complex64)
    for a in (k, g):
        a.flags.writeable = False
    return k, g, noise_gain


class _Grid:
    """Shared decimation grid of one block (integrate-and-dump into ``n_seg`` segments).

    Channels are decimated in the frequency domain from one FFT of the
    block: a channel mixed at bin b and summed over segments of L samples
    has as n_seg-point spectrum, at q, the sum over p of the block's bins
    ``b + q + p n_seg`` times the segment's response ``G`` there, over L
    (exact over all p). Only ``_ALIAS_BANDS`` aliases either side are kept:
    tones beyond them reach a channel through the response's sidelobes
    alone, which the leakage model leaves out too, and the noise there is
    dropped (``noise_gain``, the fraction kept, corrects the noise
    estimates). A channel frequency off the bin grid by ``eps`` (< half a
    bin) is mixed at the bin and rotated by ``eps`` at the segment centres
    (exact to ``(pi eps L / fs)^2 / 6``, ~1e-6). One FFT and a short inverse
    FFT per channel replace a product of the block with every channel's
    mixer (~10x less work with 7 combs).
    """

    def __init__(self, iq, fs, bw_hz, oversample=8.0):
        n = iq.shape[-1]
        self.n, self.fs = n, fs
        self.n_seg, self.seg = _decimation(n, int(np.ceil(oversample * bw_hz * n / fs)))
        self.t_l, self.t_m, self.tau, self.tpow = _segments(n, fs, self.n_seg, self.seg)
        self.counts = np.minimum(self.seg, n - np.arange(self.n_seg) * self.seg)
        self.t_abs = self.tau + 0.5 * (n - 1) / fs  # segment centres from the first sample
        self.n_fft = self.n_seg * self.seg
        self.k, self.weights, self.noise_gain = _alias_weights(self.n_fft, self.n_seg, self.seg)
        self._iq = iq
        self._spectrum = None
        self._windows = None

    @property
    def fs_dec(self):
        return self.n_seg * self.fs / self.n

    @property
    def spectrum(self):
        """FFT of the block zero-padded to n_seg * seg samples (computed once)."""
        if self._spectrum is None:
            self._spectrum = fft(self._iq, self.n_fft, scratch=True)  # valid for this block's work
            if not np.isfinite(self._spectrum[0]):
                raise NonFiniteSamples("IQ samples contain NaN or inf")
        return self._spectrum

    def channels(self, f_c):
        """Integrate-and-dump outputs of channels mixed at ``f_c`` (n_ch,) [Hz]: (n_seg, n_ch) complex."""
        f_c = np.asarray(f_c, dtype=float)
        df = self.fs / self.n_fft
        b = np.round(f_c / df).astype(np.int64)
        if self._windows is None:
            # Every run of len(k) bins starting at bin i + k[0], i = 0..n_fft - 1 (circular).
            x = self.spectrum
            wrapped = np.concatenate([x[self.k[0]:], x, x[:self.k[-1]]])
            self._windows = np.lib.stride_tricks.sliding_window_view(wrapped, self.k.size)
        z = self._windows[b % self.n_fft] * self.weights
        z = z.reshape(f_c.size, -1, self.n_seg).sum(axis=1)  # column c: spectral index k[0] + c (mod n_seg)
        y = np.fft.ifft(z, axis=1).T
        # The first column's index k[0] as a phase ramp, and the rotation by the off-bin part.
        return y * _cis((self.k[0] / self.n_seg) * np.arange(self.n_seg)[:, None]
                        - np.multiply.outer(self.t_abs, f_c - b * df))


def _channels_hz(comb, d_c, wide):
    """Mixing frequency of tone positions -wide..wide of a comb whose central tone is at ``d_c``."""
    k = np.arange(-wide, wide + 1)
    return k * comb.tone_spacing_hz * (1.0 + d_c / comb.carrier_hz) + d_c


def _decimate(grid, comb, c, wide):
    """Fill ``c.y_wide``: integrate-and-dump outputs of tone positions -wide..wide, (n_seg, 2 wide + 1),
    and the channels' mixing frequencies and phasors at the segment centres."""
    c.f_c = _channels_hz(comb, c.d_c, wide)
    c.mix = _cis(-np.multiply.outer(grid.t_abs, c.f_c))
    c.y_wide = grid.channels(c.f_c)


def _frac(c):
    return c - np.round(c)


def _tones(comb, doppler_hz, rate, tau):
    """Phase [cycles] and frequency [Hz] of every tone at times ``tau`` from the block centre, (len(tau), K)."""
    k_hz = comb.offsets_hz
    s = comb.doppler_scale
    cycles = np.multiply.outer(tau, k_hz) + np.multiply.outer(doppler_hz * tau + 0.5 * rate * tau**2, s)
    nu = k_hz + np.multiply.outer(doppler_hz + rate * tau, s)
    return cycles, nu


def _dirichlet(delta_hz, counts, fs):
    """sum over a segment of ``counts`` samples, centred, of exp(j 2 pi delta t): real, float32.

    Single precision (~1e-7 relative, far below the noise of any segment;
    float64 sines cost 5x more): ``sin(x L) / sin(x)`` with x = pi delta / fs,
    here |x| <= ~0.05 and |x L| <= ~15 (tones within a few decimated bands),
    the denominator by its Taylor series to x^5.
    """
    x = (delta_hz * (np.pi / fs)).astype(np.float32)
    num = np.sin(x * np.asarray(counts, dtype=np.float32))
    den = x * (1.0 - x * x * np.float32(1.0 / 6.0))
    full = np.broadcast_to(np.asarray(counts, dtype=np.float32), num.shape)
    return np.divide(num, den, out=np.array(full), where=den != 0.0)


def _cis(cycles):
    """exp(j 2 pi cycles), complex128, from single-precision cosine and sine of the reduced phase
    (~1e-7 rad; float64 complex exponentials cost 9x more)."""
    ph = (2.0 * np.pi * _frac(cycles)).astype(np.float32)
    out = np.empty(ph.shape, dtype=complex)
    out.real = np.cos(ph)
    out.imag = np.sin(ph)
    return out


def _leakage(grid, sources, f_c, mix):
    """Decimated outputs that the combs ``sources`` put into channels mixed at ``f_c`` (mixing
    phasors ``mix``, (n_seg, len(f_c))), in one product over all their tones: None when no tone
    is within reach. Returns (n_seg, len(f_c))."""
    have = [o for o in sources if o.val is not None]
    if not have:
        return None
    nu_mid = np.concatenate([o.nu[grid.n_seg // 2] for o in have])
    near = np.abs(nu_mid[:, None] - f_c) < _LEAK_BANDS * grid.fs_dec
    jj, ii = np.nonzero(near.T)  # pairs grouped by channel
    if ii.size == 0:
        return None
    val = np.hstack([o.val for o in have])[:, ii]
    nu = np.hstack([o.nu for o in have])[:, ii]
    val *= _dirichlet(nu - f_c[jj], grid.counts[:, None], grid.fs)
    first = np.flatnonzero(np.r_[True, jj[1:] != jj[:-1]])
    out = np.zeros((grid.n_seg, f_c.size), dtype=complex)
    out[:, jj[first]] = np.add.reduceat(val, first, axis=1) * mix[:, jj[first]]
    return out


@dataclass
class _Comb:
    """Working state of one comb: decimated raw tones and current estimates."""

    d_c: float          # mixing (coarse) central frequency
    y_wide: np.ndarray  # (n_seg, K + 2 extra) raw decimated tones
    f_c: np.ndarray = None  # (K + 2 extra,) mixing frequencies
    mix: np.ndarray = None  # (n_seg, K + 2 extra) exp(-j 2 pi f_c t) at the segment centres
    val: np.ndarray = None  # (n_seg, K) tone values at the segment centres (complex64)
    nu: np.ndarray = None   # (n_seg, K) tone frequencies there
    doppler_hz: float = np.nan
    rate: float = np.nan
    amp: np.ndarray = None
    cn0_dbhz: float = np.nan
    sigma_hz: float = np.nan
    statistic: float = np.nan
    predicted_index: int = -1
    z_wide: np.ndarray = None  # (n_seg, K + 2 extra) the tones the last batched fit used


def _fit(grid, comb, c, z_wide, *, max_rate, pfa, start=None, resolve=True):
    """``fast``'s fine stage on cleaned decimated tones ``z_wide``; fills ``c``. Returns the comb shift."""
    half = comb.n_tones // 2
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    extra = (z_wide.shape[1] - comb.n_tones) // 2
    y = z_wide[:, extra:z_wide.shape[1] - extra]
    tau, tpow = grid.tau, grid.tpow
    dt_dec = grid.seg / grid.fs
    dur = grid.n / grid.fs
    known = np.zeros(grid.n_seg)
    if start is None:
        rate, f_res = 0.0, None
        yt = np.ascontiguousarray(y.T, dtype=np.complex64)
        if max_rate * dur**2 > 0.25:
            rate = _rate_dpt(yt, dt_dec, pfa)
            if rate is None:
                rate, f_res = _rate_grid(yt, tau, known, dt_dec, max_rate, dur)
        if f_res is None:
            f_res = _dechirped_peak(yt, tau, rate, known, dt_dec)
    else:
        f_res, rate = start
        if f_res is None:
            yt = np.ascontiguousarray(y.T, dtype=np.complex64)
            f_res = _dechirped_peak(yt, tau, rate, known, dt_dec)
    delta, rate, y_sum = _newton(y, tau, tpow, ratio, f_res, rate, known)
    if resolve and extra:
        phase = delta * tau + 0.5 * rate * tau**2
        power = _abs2(np.sum(z_wide * _phasors(phase, ratio * phase, half + extra), axis=0))
        shift = int(np.argmax(np.convolve(power, np.ones(comb.n_tones), mode="valid"))) - extra
        if shift:
            return shift, c.d_c + delta
    n, fs = grid.n, grid.fs
    c.doppler_hz, c.rate = c.d_c + delta, rate
    energy = np.sum(_abs2(y), axis=0)
    resid = np.sort(np.maximum(energy - _abs2(y_sum) / grid.n_seg, 0.0))
    sigma2 = (0.5 * float(resid[(resid.size - 1) // 2] + resid[resid.size // 2])
              / ((grid.n_seg - 1) * grid.seg * grid.noise_gain))
    a2 = np.maximum(_abs2(y_sum) - n * sigma2, 0.0) / n**2
    cn0_k = a2 * fs / sigma2 if sigma2 > 0 else np.full(comb.n_tones, np.inf)
    w = np.sum(cn0_k * comb.doppler_scale**2)
    c.sigma_hz = float(np.sqrt(crlb_frequency_hz2(10.0 * np.log10(w), n, fs))) if w > 0 else np.inf
    mean_cn0 = np.mean(cn0_k)
    c.cn0_dbhz = float(10.0 * np.log10(mean_cn0)) if mean_cn0 > 0 else -np.inf
    c.statistic = float(np.mean(_abs2(y_sum)) / (n * sigma2)) if sigma2 > 0 else np.inf
    cycles, c.nu = _tones(comb, c.doppler_hz, c.rate, grid.tau)
    k = slice(extra, extra + comb.n_tones)
    e = _cis(cycles)
    g = e * c.mix[:, k] * _dirichlet(c.nu - c.f_c[k], grid.counts[:, None], grid.fs)
    c.amp = np.sum(y * np.conj(g), axis=0) / np.sum(_abs2(g), axis=0)
    c.val = (e * c.amp).astype(np.complex64)  # leakage into other combs: 1e-7 relative
    return 0, None


def _cleaned(grid, comb, combs, j):
    """Decimated tones of comb ``j`` with every other comb's contribution removed."""
    c = combs[j]
    r = _leakage(grid, combs[:j] + combs[j + 1:], c.f_c, c.mix)
    return c.y_wide.astype(complex) if r is None else c.y_wide - r


def _comb_cis(a_cycles, b_cycles, half):
    """exp(j 2 pi (a + k b)) for k = -half..half, shape a.shape + (2 half + 1,): two :func:`_cis`
    calls and a product per further tone (as :func:`~.doppler._phasors`, single-precision phases)."""
    e0, z = _cis(a_cycles), _cis(b_cycles)
    out = np.empty(a_cycles.shape + (2 * half + 1,), dtype=complex)
    out[..., half] = e0
    zc = np.conj(z)
    for k in range(1, half + 1):
        np.multiply(out[..., half + k - 1], z, out=out[..., half + k])
        np.multiply(out[..., half - k + 1], zc, out=out[..., half - k])
    return out


def _leakage_all(grid, f_c, mix, val, nu):
    """What every comb's channels receive from all the other combs' tones, in one product.

    ``f_c`` (C, W) mixing frequencies, ``mix`` (B, C, W) their phasors, ``val`` and
    ``nu`` (B, C, K) tone values and frequencies at the segment centres. Returns (B, C, W).
    """
    n_seg, n_c, n_w = mix.shape
    n_k = val.shape[2]
    fc = f_c.reshape(-1)
    near = np.abs(nu[n_seg // 2].reshape(-1) - fc[:, None]) < _LEAK_BANDS * grid.fs_dec  # (C W, C K)
    near &= np.repeat(np.arange(n_c), n_w)[:, None] != np.repeat(np.arange(n_c), n_k)
    jj, ii = np.nonzero(near)  # pairs grouped by channel
    out = np.zeros((n_seg, n_c * n_w), dtype=complex)
    if ii.size:
        v = val.reshape(n_seg, -1)[:, ii] * _dirichlet(nu.reshape(n_seg, -1)[:, ii] - fc[jj], grid.counts[:, None],
                                                        grid.fs)
        first = np.flatnonzero(np.r_[True, jj[1:] != jj[:-1]])
        out[:, jj[first]] = np.add.reduceat(v, first, axis=1) * mix.reshape(n_seg, -1)[:, jj[first]]
    return out.reshape(n_seg, n_c, n_w)


def _newton_all(y, tau, tpow, ratio, f, r, n_iter=2):
    """:func:`~.doppler._newton` for C combs at once (no known phase): ``y`` (B, C, K), ``f``, ``r`` (C,)
    start values. Returns ``(f, r, Y)``, Y (C, K) the phase-aligned sums at the optimum."""
    n_seg, n_c, n_k = y.shape
    half = n_k // 2
    scale = 1.0 + ratio * np.arange(-half, half + 1)
    a, b = 2.0 * np.pi * scale, np.pi * scale
    f, r = np.array(f, dtype=float), np.array(r, dtype=float)
    step_f, step_r = np.zeros(n_c), np.zeros(n_c)
    live = np.ones(n_c, dtype=bool)
    for _ in range(n_iter):
        phase = np.multiply.outer(tau, f) + np.multiply.outer(0.5 * tpow[:, 2], r)  # (B, C)
        u = _comb_cis(-phase, -ratio * phase, half)
        u *= y
        m = (tpow.T @ u.reshape(n_seg, -1).view(float)).view(complex).reshape(5, n_c, n_k)
        y0, m1, m2 = m[0], m[1], m[2]
        q = m[1:] * np.conj(y0)
        g_f = 2.0 * (q[0].imag @ a)
        g_r = 2.0 * (q[1].imag @ b)
        h_ff = 2.0 * ((_abs2(m1) - q[1].real) @ (a * a))
        h_fr = 2.0 * (((np.conj(m1) * m2).real - q[2].real) @ (a * b))
        h_rr = 2.0 * ((_abs2(m2) - q[3].real) @ (b * b))
        det = h_ff * h_rr - h_fr * h_fr
        live &= np.isfinite(det) & (h_ff < 0.0) & (det > 0.0)
        safe = np.where(live, det, 1.0)
        step_f = np.where(live, -(h_rr * g_f - h_fr * g_r) / safe, 0.0)
        step_r = np.where(live, -(h_ff * g_r - h_fr * g_f) / safe, 0.0)
        f += step_f
        r += step_r
    return f, r, y0 - 1j * (step_f[:, None] * a * m1 + step_r[:, None] * b * m2)


def _refine_all(grid, comb, combs, clean=True):
    """One pass of re-estimation of every comb (Newton from its estimate) with all the others removed
    (``clean``), all combs at once (each from the others' previous estimates)."""
    n, fs, n_k = grid.n, grid.fs, comb.n_tones
    extra = (combs[0].f_c.size - n_k) // 2
    k = slice(extra, extra + n_k)
    f_c = np.array([c.f_c for c in combs])
    mix = np.stack([c.mix for c in combs], axis=1)
    d_c = np.array([c.d_c for c in combs])
    z = np.stack([c.y_wide for c in combs], axis=1)
    if clean:
        z = z - _leakage_all(grid, f_c, mix, np.stack([c.val for c in combs], axis=1),
                             np.stack([c.nu for c in combs], axis=1))
    y = z[:, :, k]
    delta, rate, y_sum = _newton_all(y, grid.tau, grid.tpow, comb.tone_spacing_hz / comb.carrier_hz,
                                     [c.doppler_hz for c in combs] - d_c, [c.rate for c in combs])
    doppler = d_c + delta
    # Amplitudes, noise and C/N0 as _fit, per comb.
    p_sum = _abs2(y_sum)
    energy = np.sum(_abs2(y), axis=0)
    resid = np.sort(np.maximum(energy - p_sum / grid.n_seg, 0.0), axis=1)
    sigma2 = (0.5 * (resid[:, (n_k - 1) // 2] + resid[:, n_k // 2])
              / ((grid.n_seg - 1) * grid.seg * grid.noise_gain))
    pos = sigma2 > 0
    s2 = np.where(pos, sigma2, 1.0)[:, None]
    cn0_k = np.where(pos[:, None], np.maximum(p_sum - n * s2, 0.0) / n**2 * fs / s2, np.inf)
    w = cn0_k @ comb.doppler_scale**2
    mean_cn0 = np.mean(cn0_k, axis=1)
    statistic = np.where(pos, np.mean(p_sum, axis=1) / (n * s2[:, 0]), np.inf)
    s = comb.doppler_scale
    phase = np.multiply.outer(grid.tau, doppler) + np.multiply.outer(0.5 * grid.tau**2, rate)  # (B, C)
    nu = comb.offsets_hz + (doppler + np.multiply.outer(grid.tau, rate))[:, :, None] * s
    # Tone k: k spacing tau + s_k phase = phase + k (spacing tau + ratio phase).
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    e = _comb_cis(phase, comb.tone_spacing_hz * grid.tau[:, None] + ratio * phase, n_k // 2)
    g = e * mix[:, :, k] * _dirichlet(nu - f_c[:, k], grid.counts[:, None, None], grid.fs)
    amp = np.sum(y * np.conj(g), axis=0) / np.sum(_abs2(g), axis=0)
    val = (e * amp).astype(np.complex64)
    with np.errstate(divide="ignore"):
        sigma_hz = np.where(w > 0, np.sqrt(crlb_frequency_hz2(10.0 * np.log10(np.where(w > 0, w, 1.0)), n, fs)), np.inf)
        cn0_dbhz = np.where(mean_cn0 > 0, 10.0 * np.log10(np.where(mean_cn0 > 0, mean_cn0, 1.0)), -np.inf)
    for j, c in enumerate(combs):
        c.z_wide = z[:, j]
        c.doppler_hz, c.rate = float(doppler[j]), float(rate[j])
        c.sigma_hz, c.cn0_dbhz, c.statistic = float(sigma_hz[j]), float(cn0_dbhz[j]), float(statistic[j])
        c.amp, c.val, c.nu = amp[j], val[:, j], nu[:, j]


def _decimate_all(grid, comb, combs, wide):
    """:func:`_decimate` for several combs at once."""
    f_c = np.array([_channels_hz(comb, c.d_c, wide) for c in combs])  # (C, W)
    mix = _cis(-np.multiply.outer(grid.t_abs, f_c))
    y = grid.channels(f_c.reshape(-1)).reshape(grid.n_seg, len(combs), -1)
    for j, c in enumerate(combs):
        c.f_c, c.mix, c.y_wide = f_c[j], mix[:, j], y[:, j]


def _dechirped_peaks(y, tau, rate, dt_dec):
    """:func:`~.doppler._dechirped_peak` of C combs at once: ``y`` (B, C, K), ``rate`` (C,). Returns (C,) [Hz]."""
    n_seg = y.shape[0]
    z = y.transpose(1, 2, 0) * _cis(-np.multiply.outer(0.5 * np.asarray(rate), tau**2))[:, None, :]
    n_fft = 2 * n_seg
    p = _trimmed_sum(_abs2(fft(z.astype(np.complex64), n_fft, scratch=True)))  # (C, n_fft)
    i = np.argmax(p, axis=1)
    rows = np.arange(p.shape[0])
    pm, p0, pp = p[rows, i - 1], p[rows, i], p[rows, (i + 1) % n_fft]
    den = pm - 2.0 * p0 + pp
    vertex = np.clip(0.5 * (pm - pp) / np.where(den != 0.0, den, -1.0), -0.5, 0.5) * (den != 0.0)
    return _wrap((i + vertex) / (n_fft * dt_dec), 1.0 / dt_dec)


def _track(grid, comb, pred, pred_rate, wide, max_rate, pfa):
    """Every predicted comb fitted at once from its own tones (no cancellation yet), the comb
    position checked as in :func:`_fit` (a shifted comb is refitted alone). Returns the combs."""
    half = comb.n_tones // 2
    extra = wide - half
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    combs = [_Comb(float(p), None, predicted_index=i) for i, p in enumerate(pred)]
    _decimate_all(grid, comb, combs, wide)
    y = np.stack([c.y_wide[:, extra:extra + comb.n_tones] for c in combs], axis=1)
    f_res = _dechirped_peaks(y, grid.tau, pred_rate, grid.seg / grid.fs)
    for c, f, r in zip(combs, f_res, pred_rate):
        c.doppler_hz, c.rate = c.d_c + f, float(r)
    _refine_all(grid, comb, combs, clean=False)
    if extra == 0:
        return combs
    delta = np.array([c.doppler_hz - c.d_c for c in combs])
    rate = np.array([c.rate for c in combs])
    phase = np.multiply.outer(grid.tau, delta) + np.multiply.outer(0.5 * grid.tau**2, rate)
    u = _comb_cis(-phase, -ratio * phase, wide)
    power = _abs2(np.sum(np.stack([c.y_wide for c in combs], axis=1) * u, axis=0))  # (C, W)
    box = np.cumsum(np.pad(power, ((0, 0), (1, 0))), axis=1)
    shift = np.argmax(box[:, comb.n_tones:] - box[:, :-comb.n_tones], axis=1) - extra
    for c, sh in zip(combs, shift):
        if sh:
            centre = c.doppler_hz
            c.d_c = centre + sh * comb.tone_spacing_hz * (1.0 + centre / comb.carrier_hz)
            _decimate(grid, comb, c, wide)
            _fit(grid, comb, c, c.y_wide.astype(complex), max_rate=max_rate, pfa=pfa, start=(0.0, c.rate),
                 resolve=False)
    return combs


def _spectrum_grid(n, target):
    """Segments B_s dividing n, nearest to ``target`` (n itself when n has no divisor in range)."""
    div = [b for b in range(max(16, target // 2), min(4 * target, n // 4) + 1) if n % b == 0]
    return min(div, key=lambda b: abs(b - target)) if div else n


def _subtract_spectrum(spectrum, comb, c, n, fs, n_seg_s):
    """Remove comb ``c`` from the block's FFT (in place) over ``n_seg_s`` bins around each tone."""
    seg = n // n_seg_s
    df = fs / n
    _, _, tau, _ = _segments(n, fs, n_seg_s, seg)
    cycles, nu = _tones(comb, c.doppler_hz, c.rate, tau)
    vals = (c.amp * _cis(cycles)).T  # (K, B_s)
    dft = fft(vals)
    nu0 = nu[n_seg_s // 2]
    b = np.round(nu0 / df).astype(int)[:, None] + np.arange(-(n_seg_s // 2), n_seg_s - n_seg_s // 2)
    # Sum over the segments of the segment-centre value times each segment's kernel and delay.
    weight = _dirichlet(nu0[:, None] - b * df, seg, fs) * _cis(-b * (0.5 * (seg - 1) / n))
    np.subtract.at(spectrum, b % n, (weight * dft[np.arange(comb.n_tones)[:, None], b % n_seg_s]).astype(spectrum.dtype))


def _another_comb(iq, fs, comb, found, smear, max_doppler_hz, pfa, centre_hz):
    """True when the block's spectrum, the combs ``found`` (Combs) removed, holds another comb.

    A detection within the coarse error (modulo the spacing) of a found comb
    is taken as its residue (the subtraction leaves a little of a strong,
    fast-chirping comb), not as another comb: a new comb hidden there is
    found by a later search, when the two have drifted apart.
    """
    n = iq.shape[-1]
    spectrum = fft(iq)
    if not np.isfinite(spectrum[0]):
        raise NonFiniteSamples("IQ samples contain NaN or inf")
    n_seg_s = _spectrum_grid(n, max(1024, int(8 * smear * n / fs)))
    for d, r, a in zip(found.doppler_hz, found.doppler_rate_hz_per_s, found.amplitudes):
        _subtract_spectrum(spectrum, comb, _Comb(d, None, doppler_hz=d, rate=r, amp=a), n, fs, n_seg_s)
    coarse = coarse_fft(spectrum, fs, comb, max_doppler_hz=max_doppler_hz, smear_hz=smear, pfa=pfa,
                        centre_hz=centre_hz)
    if not coarse.detected:
        return False
    dd = coarse.doppler_hz - found.doppler_hz
    dd -= comb.tone_spacing_hz * np.round(dd / comb.tone_spacing_hz)
    return not np.any(np.abs(dd) <= 0.5 * smear + 2.0 * fs / n)


#: Residues of found combs removed in one search before it gives up.
_MAX_RESIDUES = 3


def _duplicate(comb, c, combs, dur):
    """True when ``c`` lies within 2/T (modulo the spacing) and 4/T^2 of a comb already found."""
    sp = comb.tone_spacing_hz
    for o in combs:
        dd = c.doppler_hz - o.doppler_hz
        if abs(dd - sp * np.round(dd / sp)) < 2.0 / dur and abs(c.rate - o.rate) < 4.0 / dur**2:
            return True
    return False


def _check(iq, fs, predicted_hz, predicted_rate):
    if not np.isfinite(fs) or fs <= 0:
        raise InputError(f"sample_rate_hz={fs} must be a finite number > 0")
    iq = np.asarray(iq)
    if iq.ndim != 1 or not np.iscomplexobj(iq):
        raise InputError(f"IQ samples must be a 1-D complex array, got {iq.dtype} of shape {iq.shape}")
    p = np.atleast_1d(np.asarray([] if predicted_hz is None else predicted_hz, dtype=float))
    if p.ndim != 1:
        raise InputError(f"predicted_hz must be 1-D, got shape {p.shape}")
    pr = None
    if predicted_rate is not None:
        pr = np.broadcast_to(np.asarray(predicted_rate, dtype=float), p.shape)
    return iq, p, pr


def find_combs(iq, sample_rate_hz, *, comb=None, max_combs=10, pfa=PFA, max_doppler_hz=MAX_DOPPLER_HZ,
               max_rate_hz_per_s=MAX_RATE_HZ_PER_S, predicted_hz=None, predicted_rate_hz_per_s=None,
               gate_hz=None, search=True, n_refine=2, batch=True, lo_offset_hz=0.0, clean=True):
    """Doppler, rate and C/N0 of every pilot comb in one block.

    Parameters
    ----------
    iq : ndarray of complex, shape (n,)
    sample_rate_hz : float
    comb : PilotComb, optional
    max_combs : int
        Stop after this many combs.
    pfa : float
        False-alarm probability of each comb search (and of the rate
        transform's peak, as in ``fast``). A noise-only block gives a
        spurious comb with probability at most ``pfa``.
    max_doppler_hz, max_rate_hz_per_s : float
        Search limits (as :func:`~.doppler.estimate_block`).
    predicted_hz : array_like, shape (n_pred,), optional
        Tracking mode: central-tone Dopplers predicted from earlier blocks.
        Each is fitted from its own decimated tones (no spectrum search);
        kept when its coherent statistic passes the detector at ``pfa``.
    predicted_rate_hz_per_s : array_like, shape (n_pred,) or scalar, optional
        Predicted rates; given, the rate search is skipped (good to ~1/(2 T^2)).
    gate_hz : float, optional
        Half-width of the window around each prediction (default: the coarse
        error of the full search, half the rate smear plus 2 bins).
    search : bool
        Also search the spectrum for combs not predicted (costs one FFT of
        the block plus the searches).
    n_refine : int
        Re-estimation passes with all other combs removed.
    batch : bool
        Tracking with predicted rates: fit all predictions at once (default)
        rather than one at a time (see module docstring).
    lo_offset_hz : float
        The receiver's LO offset, common to all satellites (as well as it is
        known): the search is centred there (``max_doppler_hz`` either side)
        and the tone model scales only the Doppler beyond it
        (:meth:`~.pilot.PilotComb.through_lo`). Reported Dopplers include it.
    clean : bool
        Remove the block's DC offset, IQ imbalance and CW / narrowband
        interferers first (:func:`~.frontend.clean_block`; one FFT more).

    Returns
    -------
    Combs
        In detection order (see module docstring).
    """
    comb = comb or PilotComb()
    fs = float(sample_rate_hz)
    iq, pred, pred_rate = _check(iq, fs, predicted_hz, predicted_rate_hz_per_s)
    if not np.all(np.isfinite(pred)):
        raise InputError("predicted_hz contains NaN or inf")
    if clean:
        if not np.isfinite(iq.sum()):
            raise NonFiniteSamples("IQ samples contain NaN or inf")
        iq, _ = clean_block(iq, fs, comb)
    lo = float(lo_offset_hz)
    if lo:
        comb = comb.through_lo(lo)
    n = iq.shape[-1]
    dur = n / fs
    df = fs / n
    smear = max_rate_hz_per_s * dur
    error_hz = 0.5 * smear + 2.0 * df
    gate = error_hz if gate_hz is None else float(gate_hz)
    if search and pred_rate is not None and pred.size and batch:
        # The tracked combs first, in their narrow bands; the full search (wide
        # bands, every comb refitted) only when the spectrum without them holds
        # another comb, which is rare: a search block then costs little more
        # than a tracking one.
        kw = dict(comb=comb, max_combs=max_combs, pfa=pfa, max_doppler_hz=max_doppler_hz,
                  max_rate_hz_per_s=max_rate_hz_per_s, gate_hz=gate_hz, n_refine=n_refine, clean=False)
        tracked = find_combs(iq, fs, predicted_hz=pred, predicted_rate_hz_per_s=pred_rate, search=False, **kw)
        if tracked.n_found >= max_combs or not _another_comb(iq, fs, comb, tracked, smear, max_doppler_hz, pfa, lo):
            return tracked
    tracking = pred_rate is not None and pred.size > 0 and not search
    if tracking:
        # Every comb is near its prediction, chirping at its predicted rate: the
        # channels need only pass the gate and that chirp, and the comb position
        # (checked when the comb was found) needs no check.
        grid = _Grid(iq, fs, gate + 0.5 * float(np.max(np.abs(pred_rate[:max_combs]))) * dur + 2.0 * df,
                     oversample=_TRACK_OVERSAMPLE)
    else:
        grid = _Grid(iq, fs, max(error_hz, gate) + 0.5 * max_rate_hz_per_s * dur)
    half = comb.n_tones // 2
    wide = half if tracking else half + _EXTRA
    combs = []

    def fit_new(d_c, start, index):
        c = _Comb(d_c, None, predicted_index=index)
        _decimate(grid, comb, c, wide)
        combs.append(c)
        j = len(combs) - 1
        shift, centre = _fit(grid, comb, c, _cleaned(grid, comb, combs, j), max_rate=max_rate_hz_per_s,
                             pfa=pfa, start=start)
        if shift:
            c.d_c = centre + shift * comb.tone_spacing_hz * (1.0 + centre / comb.carrier_hz)
            _decimate(grid, comb, c, wide)
            _fit(grid, comb, c, _cleaned(grid, comb, combs, j), max_rate=max_rate_hz_per_s, pfa=pfa,
                 start=(0.0, c.rate if np.isfinite(c.rate) else 0.0) if start is not None else None,
                 resolve=False)
        return c

    # Tracking: each prediction from its own tones; kept if the coherent power passes the detector.
    n_cells = grid.n_seg * max(1, int(np.ceil(2.0 * max_rate_hz_per_s * dur**2)))
    thr = _threshold(comb.n_tones, n_cells, pfa)
    if pred_rate is not None and pred.size and batch:
        for c in _track(grid, comb, pred[:max_combs], pred_rate[:max_combs], wide, max_rate_hz_per_s, pfa):
            near = abs(c.doppler_hz - pred[c.predicted_index]) <= gate + 2.0 * df
            if c.statistic > thr and near and not _duplicate(comb, c, combs, dur):
                combs.append(c)
    else:
        for i, p in enumerate(pred[:max_combs]):
            start = (None, float(pred_rate[i])) if pred_rate is not None else None
            c = fit_new(float(p), start, i)
            near = abs(c.doppler_hz - p) <= gate + 2.0 * df
            if not (c.statistic > thr and near) or _duplicate(comb, c, combs[:-1], dur):
                combs.pop()

    if search and len(combs) < max_combs:
        spectrum = grid.spectrum.copy() if grid.n_fft == n else fft(iq)
        if not np.isfinite(spectrum[0]):
            raise NonFiniteSamples("IQ samples contain NaN or inf")
        n_seg_s = _spectrum_grid(n, max(1024, int(8 * smear * dur)))
        for c in combs:
            _subtract_spectrum(spectrum, comb, c, n, fs, n_seg_s)
        residues = 0
        while len(combs) < max_combs:
            coarse = coarse_fft(spectrum, fs, comb, max_doppler_hz=max_doppler_hz, smear_hz=smear, pfa=pfa,
                                centre_hz=lo)
            if not coarse.detected:
                break
            c = fit_new(coarse.doppler_hz, None, -1)
            if _duplicate(comb, c, combs[:-1], dur):
                # The residue of a comb already found (nearly coinciding tones are
                # not cancelled exactly): remove it too and search on, a few times
                # at most, rather than miss the weaker combs behind it.
                combs.pop()
                residues += 1
                if residues > _MAX_RESIDUES:
                    break
            _subtract_spectrum(spectrum, comb, c, n, fs, n_seg_s)

    for _ in range(n_refine if len(combs) > 1 else 0):
        _refine_all(grid, comb, combs)

    def col(name, dtype=float):
        return np.array([getattr(c, name) for c in combs], dtype=dtype)

    amps = np.array([c.amp for c in combs]) if combs else np.zeros((0, comb.n_tones), dtype=complex)
    return Combs(col("doppler_hz"), col("rate"), col("cn0_dbhz"), col("sigma_hz"), amps, col("statistic"),
                 col("predicted_index", int))
