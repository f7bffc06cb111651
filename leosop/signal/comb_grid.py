"""Frequency-domain decimation of one block into comb channels, and the leakage of combs between channels.

:class:`DecimationGrid` turns one FFT of a block into the integrate-and-dump
outputs of any channel (the decimated tones of
:func:`~leosop.signal.multicomb.find_combs`). Contributions of one comb to
another's decimated tones are closed forms (:func:`leakage`,
:func:`leakage_all`): a tone at local frequency nu in segment m, seen by a
channel mixed at f_c, gives its value at the segment centre times the
Dirichlet kernel ``sin(pi (nu - f_c) L / fs) / sin(pi (nu - f_c) / fs)``
(:func:`dirichlet`) and the channel's mixing phase. Only tones within
``_LEAK_BANDS`` decimated bands of a channel are counted, the reach of the
frequency-domain decimation: farther tones reach the channel only through
their own spectral sidelobes. Transcendentals are single precision (1e-7 rad).
"""

from functools import lru_cache

import numpy as np

from ..errors import InputError
from .fft import fft, ifft
from .fine import decimation_size, segment_grid

__all__ = ["ALIAS_BANDS", "DecimationGrid", "NonFiniteSamples", "channels_hz", "cis", "comb_cis", "dirichlet",
           "leakage", "leakage_all", "tone_phases"]

#: Aliases either side of a channel kept by the frequency-domain decimation (whole decimated bands;
#: half a band more is kept, so the reach is ``_LEAK_BANDS``): what is decimated is what is modelled.
#: Two bands: RMSE/CRLB as with four (0.96 on 7-comb blocks), half the work.
ALIAS_BANDS = 2
#: Channels count another comb's tone within this many decimated bandwidths.
_LEAK_BANDS = ALIAS_BANDS + 0.5


class NonFiniteSamples(InputError):
    """The block holds NaN or inf samples (seen in its FFT: every bin turns NaN)."""


@lru_cache(maxsize=16)
def _alias_weights(n_fft, n_seg, seg):
    """Bin offsets from a channel, (R,), the integrate-and-dump response there over ``seg`` (R,)
    complex, and the fraction of the decimated noise they keep (see :class:`DecimationGrid`)."""
    k = np.arange(-(ALIAS_BANDS * n_seg + n_seg // 2), (ALIAS_BANDS + 1) * n_seg - n_seg // 2)
    x = np.pi * k / n_fft
    sin_x = np.sin(x)
    safe = np.where(sin_x == 0.0, 1.0, sin_x)
    g = np.where(sin_x == 0.0, float(seg), np.sin(seg * x) / safe) * np.exp(1j * (seg - 1) * x)
    noise_gain = float(np.sum(np.abs(g) ** 2) / (n_fft * seg))
    g = (g / seg).astype(np.complex64)
    for a in (k, g):
        a.flags.writeable = False
    return k, g, noise_gain


class DecimationGrid:
    """Shared decimation grid of one block (integrate-and-dump into ``n_seg`` segments).

    Channels are decimated in the frequency domain from one FFT of the
    block: a channel mixed at bin b and summed over segments of L samples
    has as n_seg-point spectrum, at q, the sum over p of the block's bins
    ``b + q + p n_seg`` times the segment's response ``G`` there, over L
    (exact over all p). Only ``ALIAS_BANDS`` aliases either side are kept:
    tones beyond them reach a channel through the response's sidelobes
    alone, which the leakage model leaves out too, and the noise there is
    dropped (``noise_gain``, the fraction kept, corrects the noise
    estimates). A channel frequency off the bin grid by ``eps`` (< half a
    bin) is mixed at the bin and rotated by ``eps`` at the segment centres
    (exact to ``(pi eps L / fs)^2 / 6``, ~1e-6). One FFT and a short inverse
    FFT per channel replace a product of the block with every channel's
    mixer (~10x less work with 7 combs).

    ``spectrum``, the block's :func:`~.fft.fft` (n,) when known (the
    cleaning's, :class:`~.cleaning.Cleaning`), is that FFT when the grid
    needs no zero-padding (n_seg * seg = n, as for blocks of round sizes).
    Given, ``iq`` may be None: the block in time is then its inverse FFT,
    made only for a grid that pads.
    """

    def __init__(self, iq, fs, bw_hz, oversample=8.0, *, spectrum=None):
        n = iq.shape[-1] if iq is not None else spectrum.shape[-1]
        self.n, self.fs = n, fs
        self.n_seg, self.seg = decimation_size(n, int(np.ceil(oversample * bw_hz * n / fs)))
        self.t_l, self.t_m, self.tau, self.tpow = segment_grid(n, fs, self.n_seg, self.seg)
        self.counts = np.minimum(self.seg, n - np.arange(self.n_seg) * self.seg)
        self.t_abs = self.tau + 0.5 * (n - 1) / fs  # segment centres from the first sample
        self.n_fft = self.n_seg * self.seg
        self.k, self.weights, self.noise_gain = _alias_weights(self.n_fft, self.n_seg, self.seg)
        self._iq = iq if iq is not None else ifft(spectrum) if self.n_fft != n else None
        self._spectrum = spectrum if spectrum is not None and self.n_fft == n else None

    @property
    def fs_dec(self):
        return self.n_seg * self.fs / self.n

    @property
    def reach_hz(self):
        """How far from a channel another comb's tone leaks into it [Hz] (``_LEAK_BANDS`` decimated bands)."""
        return _LEAK_BANDS * self.fs_dec

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
        # Each channel's run of len(k) bins from bin b + k[0] (circular), gathered alone: copying the
        # whole spectrum into a wrapped one cost more than the few channels a block needs.
        z = np.take(self.spectrum, np.add.outer(b, self.k), mode="wrap") * self.weights
        z = z.reshape(f_c.size, -1, self.n_seg).sum(axis=1)  # column c: spectral index k[0] + c (mod n_seg)
        y = np.fft.ifft(z, axis=1).T
        # The first column's index k[0] as a phase ramp, and the rotation by the off-bin part.
        return y * cis((self.k[0] / self.n_seg) * np.arange(self.n_seg)[:, None]
                        - np.multiply.outer(self.t_abs, f_c - b * df))


def channels_hz(comb, d_c, wide):
    """Mixing frequency of tone positions -wide..wide of a comb whose central tone is at ``d_c``."""
    k = np.arange(-wide, wide + 1)
    return k * comb.tone_spacing_hz * (1.0 + d_c / comb.carrier_hz) + d_c


def tone_phases(comb, doppler_hz, rate, tau):
    """Phase [cycles] and frequency [Hz] of every tone at times ``tau`` from the block centre, (len(tau), K)."""
    k_hz = comb.offsets_hz
    s = comb.doppler_scale
    cycles = np.multiply.outer(tau, k_hz) + np.multiply.outer(doppler_hz * tau + 0.5 * rate * tau**2, s)
    nu = k_hz + np.multiply.outer(doppler_hz + rate * tau, s)
    return cycles, nu


def _frac(c):
    return c - np.rint(c)  # np.round without its wrappers (same half-to-even rounding)


def cis(cycles):
    """exp(j 2 pi cycles), complex128, from single-precision cosine and sine of the reduced phase
    (~1e-7 rad; float64 complex exponentials cost 9x more)."""
    ph = (2.0 * np.pi * _frac(cycles)).astype(np.float32)
    out = np.empty(ph.shape, dtype=complex)
    out.real = np.cos(ph)
    out.imag = np.sin(ph)
    return out


def comb_cis(a_cycles, b_cycles, half):
    """exp(j 2 pi (a + k b)) for k = -half..half, shape a.shape + (2 half + 1,): two :func:`cis`
    calls and a product per further tone (as :func:`~.fine.comb_phasors`, single-precision phases)."""
    e0, z = cis(a_cycles), cis(b_cycles)
    out = np.empty(a_cycles.shape + (2 * half + 1,), dtype=complex)
    out[..., half] = e0
    zc = np.conj(z)
    for k in range(1, half + 1):
        np.multiply(out[..., half + k - 1], z, out=out[..., half + k])
        np.multiply(out[..., half - k + 1], zc, out=out[..., half - k])
    return out


def dirichlet(delta_hz, counts, fs):
    """sum over a segment of ``counts`` samples, centred, of exp(j 2 pi delta t): real, float32.

    Single precision (~1e-7 relative, far below the noise of any segment;
    float64 sines cost 5x more): ``sin(x L) / sin(x)`` with x = pi delta / fs,
    here |x| <= ~0.05 and |x L| <= ~15 (tones within a few decimated bands),
    the denominator by its Taylor series to x^5.
    """
    x = (delta_hz * (np.pi / fs)).astype(np.float32)
    counts = np.asarray(counts, dtype=np.float32)
    num = np.sin(x * counts)
    den = x * (1.0 - x * x * np.float32(1.0 / 6.0))
    out = np.empty(num.shape, dtype=np.float32)
    out[...] = counts  # the limit at delta = 0 (np.broadcast_to's wrappers cost more than the kernel)
    return np.divide(num, den, out=out, where=den != 0.0)


def leakage(grid, sources, f_c, mix):
    """Decimated outputs that the combs ``sources`` put into channels mixed at ``f_c`` (mixing
    phasors ``mix``, (n_seg, len(f_c))), in one product over all their tones: None when no tone
    is within reach. Returns (n_seg, len(f_c))."""
    have = [o for o in sources if o.val is not None]
    if not have:
        return None
    nu_mid = np.concatenate([o.nu[grid.n_seg // 2] for o in have])
    near = np.abs(nu_mid[:, None] - f_c) < grid.reach_hz
    jj, ii = np.nonzero(near.T)  # pairs grouped by channel
    if ii.size == 0:
        return None
    val = np.hstack([o.val for o in have])[:, ii]
    nu = np.hstack([o.nu for o in have])[:, ii]
    val *= dirichlet(nu - f_c[jj], grid.counts[:, None], grid.fs)
    first = np.flatnonzero(np.concatenate(([True], jj[1:] != jj[:-1])))
    out = np.zeros((grid.n_seg, f_c.size), dtype=complex)
    out[:, jj[first]] = np.add.reduceat(val, first, axis=1) * mix[:, jj[first]]
    return out


def leakage_all(grid, f_c, mix, val, nu):
    """What every comb's channels receive from all the other combs' tones, in one product.

    ``f_c`` (C, W) mixing frequencies, ``mix`` (B, C, W) their phasors, ``val`` and
    ``nu`` (B, C, K) tone values and frequencies at the segment centres. Returns (B, C, W).
    """
    n_seg, n_c, n_w = mix.shape
    n_k = val.shape[2]
    fc = f_c.reshape(-1)
    near = np.abs(nu[n_seg // 2].reshape(-1) - fc[:, None]) < grid.reach_hz  # (C W, C K)
    near &= np.repeat(np.arange(n_c), n_w)[:, None] != np.repeat(np.arange(n_c), n_k)
    jj, ii = np.nonzero(near)  # pairs grouped by channel
    out = np.zeros((n_seg, n_c * n_w), dtype=complex)
    if ii.size:
        v = val.reshape(n_seg, -1)[:, ii] * dirichlet(nu.reshape(n_seg, -1)[:, ii] - fc[jj], grid.counts[:, None],
                                                        grid.fs)
        first = np.flatnonzero(np.concatenate(([True], jj[1:] != jj[:-1])))
        out[:, jj[first]] = np.add.reduceat(v, first, axis=1) * mix.reshape(n_seg, -1)[:, jj[first]]
    return out.reshape(n_seg, n_c, n_w)
