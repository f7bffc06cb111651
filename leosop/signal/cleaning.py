"""What a recording's front end did, seen in its samples: the receiver's cleaning of a block.

The counterpart of :mod:`.frontend` (which models the impairments for the
generator): :func:`find_lines` finds CW / narrowband lines in a block's
power spectrum and tells a comb's tones from interferers,
:func:`iq_imbalance` and :func:`correct_iq` estimate and undo the IQ
imbalance, and :func:`clean_block` applies all of it (DC, IQ imbalance,
interferer excision) before the comb search (:func:`clean_spectrum`: the
same, giving only the cleaned block's FFT); ``leosop doctor`` reports what
it found.
"""

import threading
from dataclasses import dataclass, field

import numpy as np

from ..constants import C_MPS
from ..kernels import pick
from .comb_grid import NonFiniteSamples

__all__ = ["Cleaning", "LINE_PFA", "Line", "clean_block", "clean_spectrum", "correct_iq", "find_lines",
           "iq_imbalance"]

#: False-alarm probability of the line detector per block (a noise bin passes its threshold this often).
LINE_PFA = 1e-3
#: A line grows from its peak while the power smoothed over this many bins exceeds twice the noise mean,
#: so what is left of a strong line after excision (sidelobes) lies below that level.
_LINE_SMOOTH_BINS = 8
#: A line with at least this many partners (strong bins at whole tone spacings from it, of comparable power)
#: is a comb tone.
_COMB_PARTNERS = 2
#: Partners are looked for within the line's half-width plus this many bins of the exact multiple of the spacing,
#: plus the spread of the received spacing: a comb arrives scaled by its Doppler, ``sp (1 + doppler / f_c)`` with
#: the LO offset taken out (:meth:`~.pilot.PilotComb.through_lo`), and ``|doppler| / f_c`` stays below a range rate
#: of 8 km/s over c (0.9 bins of a 0.1 s block at the edge tones). The half-width covers a chirped tone's smear.
_PARTNER_BINS = 2
_PARTNER_SPACING_SPREAD = 8e3 / C_MPS
#: A partner's strongest bin is within this of the line's peak [dB]: a comb's tones have one C/N0 and one smear,
#: their peak bins differ by scalloping (3.9 dB at most) and noise. A 70 dB-Hz CW line is 25 dB above a
#: 45 dB-Hz comb's tones (issue 26: counted without power, they made it a comb tone).
_PARTNER_DB = 10.0
#: The reach of a line's skirt (:func:`_subtract_skirt`): as far from its peak as a pure tone of its energy E
#: leaks above this fraction of the noise (up to ``E / (pi^2 m^2)`` into the bin m bins away).
_SKIRT_FRACTION = 0.1
#: Each thread's power-spectrum buffer (:func:`_padded_buffer`).
_local = threading.local()


@dataclass(frozen=True)
class Line:
    """A narrowband line found in a block's spectrum.

    Attributes
    ----------
    frequency_hz : float
        Peak, baseband.
    power_dbhz : float
        Its power in the unit of a tone's C/N0 (power over the noise density).
    lo_bin, hi_bin : int
        Bins (FFT order, may be negative) excised for it, inclusive.
    """

    frequency_hz: float
    power_dbhz: float
    lo_bin: int
    hi_bin: int


@dataclass(frozen=True)
class Cleaning:
    """What :func:`clean_block` found and removed in one block.

    Attributes
    ----------
    dc : complex
        Block mean removed (sample units).
    dc_dbhz : float
        Its power over the noise density (the unit of a tone's C/N0).
    iq_gain_db, iq_phase_deg : float
        IQ imbalance estimated (Q over I; the model of :class:`FrontEnd`).
    iq_corrected : bool
        True when the imbalance was significant and undone.
    lines : tuple of Line
        CW / narrowband interferers excised (lines not part of a comb).
    noise_density : float
        Noise power per Hz in sample units (N0), from the spectrum's median.
    spectrum : ndarray of complex64, (n,) or None
        The cleaned block's FFT (:func:`~.fft.fft`), the one the cleaning
        made, with the excised lines' bins zeroed (the cleaned block is its
        inverse); the comb search reuses it (:func:`~.multicomb.find_combs`).
    """

    dc: complex
    dc_dbhz: float
    iq_gain_db: float
    iq_phase_deg: float
    iq_corrected: bool
    lines: tuple
    noise_density: float
    spectrum: np.ndarray | None = field(default=None, compare=False, repr=False)


def iq_imbalance(iq):
    """Q-over-I gain [dB] and phase error [deg] of a block (DC removed first), and their 1-sigma [dB, deg].

    For a circular received signal (noise, tones off 0 Hz) ``E[I^2] = E[Q^2]``
    and ``E[I Q] = 0``; the model ``Q' = g (Q cos phi - I sin phi)`` gives
    ``g^2 = E[Q'^2] / E[I^2]`` and ``sin phi = -E[I Q'] / sqrt(E[I^2] E[Q'^2])``.
    Each moment ratio has a spread of ~1/sqrt(n).
    """
    x = np.asarray(iq)
    return _imbalance(x - x.mean())


def _imbalance(y):
    """:func:`iq_imbalance` of samples ``y`` (n,) whose mean is removed.

    The moments come from two complex dot products, one pass over the
    samples each: ``sum |y|^2 = sum I^2 + Q^2`` and
    ``sum y^2 = sum I^2 - Q^2 + 2j I Q`` (0.06 ms for 2.5e5 complex64
    samples; three float32 dot products of I and Q took 0.31 ms). Their
    float32 sums lose ~4e-6 of the moments over 2.5e5 samples: up to
    5e-4 dB and 1e-4 deg, 1/30 and 1/1000 of the estimate's own sigma.
    """
    power = float(np.vdot(y, y).real)
    square = complex(np.dot(y, y))
    pi, pq, piq = 0.5 * (power + square.real), 0.5 * (power - square.real), 0.5 * square.imag
    if pi <= 0 or pq <= 0:
        return 0.0, 0.0, np.inf, np.inf
    gain_db = 10.0 * np.log10(pq / pi)
    phase_deg = float(np.degrees(np.arcsin(np.clip(-piq / np.sqrt(pi * pq), -1.0, 1.0))))
    n = y.size
    return gain_db, phase_deg, float(20.0 / np.log(10.0) / np.sqrt(n)), float(np.degrees(1.0 / np.sqrt(n)))


def correct_iq(iq, gain_db, phase_deg, *, out=None):
    """Undo the IQ imbalance of :class:`FrontEnd` (``Q = (Q'/g + I sin phi) / cos phi``), complex64 (n,).

    ``out``: a complex64 array (n,) to write into (may be ``iq``); default a new one.
    """
    x = np.asarray(iq)
    g = 10.0 ** (gain_db / 20.0)
    phi = np.radians(phase_deg)
    q = x.imag / g + x.real * np.sin(phi)  # float64 (np.sin's result is)
    q /= np.cos(phi)
    if out is None:
        out = np.empty(x.shape, dtype=np.complex64)
    if out is not x:
        out.real = x.real
    out.imag = q
    return out


def find_lines(power, fs, comb, *, pfa=LINE_PFA, kernel=None):
    """Strong narrow lines of a block's power spectrum that belong to no comb; the noise mean per bin.

    A bin beyond ``-ln(pfa / n)`` noise means (exponential power) starts a
    line; the line spans the run of bins around it whose power, smoothed over
    ``_LINE_SMOOTH_BINS``, exceeds twice the noise mean. A line with at least
    ``_COMB_PARTNERS`` partners is a comb's tone and kept: whole tone
    spacings m = +-1..+-(n_tones-1) from its peak (within the line's
    half-width plus ``_PARTNER_BINS`` and the spacing's Doppler spread)
    where a strong bin lies within ``_PARTNER_DB`` of the peak's power. A
    strong CW line among combs has strong bins at its spacings (other combs'
    tones) but none of its power.

    Parameters
    ----------
    power : ndarray, (n,)
        |FFT|^2 of the block, FFT order.
    fs : float
    comb : PilotComb
    pfa : float
    kernel : {None, "numba", "numpy"}
        The runs, peaks and partners compiled (:mod:`.cleankernels`) or
        numpy; None: numba when installed (the same lines either way).

    Returns
    -------
    lines : list of Line
        Strongest first.
    noise_bin : float
        Noise mean per bin (median / ln 2 over a subsample).
    """
    n = power.size
    padded = np.zeros(n + _LINE_SMOOTH_BINS - 1, dtype=power.dtype)
    p = padded[_LINE_SMOOTH_BINS // 2:][:n]
    p[:n // 2] = power[n - n // 2:]
    p[n // 2:] = power[:n - n // 2]
    return _lines(padded, _noise_bin(power[::_noise_step(n)]), fs, comb, pfa, kernel)


def _noise_step(n):
    """Stride of the bins whose median gives the noise mean (~16k of them)."""
    return max(1, n // 16384)


def _noise_bin(sub):
    """Noise mean per bin from a subsample of a spectrum's bins: their median / ln 2 (exponential power)."""
    return float(np.partition(sub, sub.size // 2)[sub.size // 2]) / np.log(2.0)


def _lines(padded, noise, fs, comb, pfa, kernel=None):
    """:func:`find_lines` of a power spectrum in fftshift order, zero-padded (``padded``, (n + L - 1,), as
    np.convolve's "same" mode pads: L // 2 zeros before, L // 2 - 1 after), and its noise mean per bin."""
    if noise <= 0:
        return [], noise
    # In fftshift order 0 Hz is in the middle: runs never wrap except at the band's edges. The smoothing
    # is computed only near the strong bins (_strong_runs).
    n = padded.size - _LINE_SMOOTH_BINS + 1
    p = padded[_LINE_SMOOTH_BINS // 2:][:n]
    threshold = -np.log(pfa / n) * noise
    strong = np.flatnonzero(p > threshold)
    if not strong.size:
        return [], noise
    m = np.concatenate([np.arange(-(comb.n_tones - 1), 0), np.arange(1, comb.n_tones)])
    spacing_bins = comb.tone_spacing_hz * n / fs
    half_extra = _PARTNER_BINS + int(np.ceil((comb.n_tones - 1) * spacing_bins * _PARTNER_SPACING_SPREAD))
    floor_ratio = 10.0 ** (-_PARTNER_DB / 10.0)
    compiled = pick(kernel, "leosop.signal.cleankernels")
    if compiled is not None:
        lo, hi, peak, partners = compiled.line_runs(padded, strong, _LINE_SMOOTH_BINS, threshold, 2.0 * noise,
                                                    m * spacing_bins, half_extra, floor_ratio)
    else:
        lo, hi = _strong_runs(padded, strong, 2.0 * noise)
        # Each run's peak: the first bin of its largest power (as argmax).
        idx, first = _ranges(lo, hi + 1)
        vals = p[idx]
        hit = np.flatnonzero(vals == np.repeat(np.maximum.reduceat(vals, first), hi - lo + 1))
        peak = idx[hit[np.searchsorted(hit, first)]]
        half = (hi - lo) // 2 + half_extra
        centre = np.round(peak[:, None] + m * spacing_bins).astype(np.int64)  # (runs, 2 K - 2)
        window_max = _window_max(p, centre - half[:, None], centre + half[:, None])
        floor = np.maximum(threshold, p[peak] * floor_ratio)  # (runs,)
        partners = np.sum(window_max > floor[:, None], axis=1)
    lines = []
    for i in np.flatnonzero(partners < _COMB_PARTNERS):
        # A tone of amplitude A puts A^2 n^2 into its bins; the noise n N0 fs into each.
        power_dbhz = 10.0 * np.log10(float(np.sum(p[lo[i]:hi[i] + 1])) * fs / (n * noise))
        k0 = -(n // 2)  # signed frequency bin of shifted index 0
        lines.append(Line((peak[i] + k0) * fs / n, power_dbhz, int(lo[i] + k0), int(hi[i] + k0)))
    lines.sort(key=lambda ln: -ln.power_dbhz)
    return lines, noise


def _subtract_skirt(spectrum, line, noise_bin, fs):
    """Take a pure tone's leakage out of the bins beside a line's run, in place.

    A CW line between two bins leaks ``E / (pi^2 m^2)`` of its energy E into the bin m bins away: a
    75 dB-Hz line still holds twice the noise 5 kHz out, past its excised run (which ends where the
    smoothed power falls to twice the noise). A comb tone on that skirt lifts a noise cell of the comb
    search over its threshold: weak spurious combs beside every CW line off the bin grid. The tone's
    frequency comes from its peak bin and neighbours ([Candan 2011], for the rectangular window),
    its amplitude from the peak bin; its Dirichlet kernel is subtracted over the bins within
    :data:`_SKIRT_FRACTION`'s reach either side of the run, unless that leaves them with more power
    than before (a line that is not one steady tone).

    Parameters
    ----------
    spectrum : ndarray of complex, (n,)
        The block's FFT (FFT order).
    line : Line
    noise_bin : float
        Noise mean per bin of ``|spectrum|^2``.
    fs : float
    """
    n = spectrum.size
    if not noise_bin > 0:
        return
    kp = int(round(line.frequency_hz * n / fs))
    x_m, x_0, x_p = (complex(spectrum[k % n]) for k in (kp - 1, kp, kp + 1))
    den = 2.0 * x_0 - x_m - x_p
    if den == 0:
        return
    delta = float(np.clip(((x_m - x_p) / den).real * np.tan(np.pi / n) / (np.pi / n), -0.5, 0.5))

    def kernel(k):  # sum_t exp(j 2 pi (f - k) t / n), t = 0..n-1, f = kp + delta
        u = kp + delta - k
        return np.exp(1j * np.pi * u * (n - 1) / n) * np.sin(np.pi * u) / np.sin(np.pi * u / n)

    with np.errstate(invalid="ignore", divide="ignore"):
        amp = x_0 / kernel(kp)  # not finite for a line exactly on its bin (delta 0): no skirt then
    if not np.isfinite(amp):
        return
    reach = int(np.ceil(np.sqrt(abs(amp) ** 2 * n * n / (_SKIRT_FRACTION * noise_bin)) / np.pi))
    k = np.concatenate([np.arange(line.lo_bin - reach, line.lo_bin),
                        np.arange(line.hi_bin + 1, line.hi_bin + reach + 1)])
    k = k[np.abs(k - kp) < n // 2]  # once round the circle at most
    idx = k % n
    before = spectrum[idx].astype(complex)
    after = before - amp * kernel(k)
    if np.sum(np.abs(after) ** 2) < np.sum(np.abs(before) ** 2):
        spectrum[idx] = after


def _strong_runs(padded, strong, level):
    """The runs of bins holding a strong bin where the power smoothed over ``_LINE_SMOOTH_BINS`` exceeds ``level``.

    A run is a maximal range of bins each strong or above ``level`` once
    smoothed (``np.convolve(p, ones / L, mode="same")``, which
    zero-pads); only runs holding a strong bin are returned. The smoothing
    is computed in windows around the strong bins (a few percent of the
    spectrum), widened until every run ends inside its window: each
    smoothed bin is the same dot product of the same ``L`` bins as over the
    whole spectrum, so the runs are those of the whole spectrum.

    Parameters
    ----------
    padded : ndarray, (n + L - 1,)
        The power spectrum (fftshift order) with ``L // 2`` zeros before and ``L // 2 - 1`` after.
    strong : ndarray of int, (n_strong,)
        Indices of the strong bins, increasing (they are in runs whatever the smoothing).
    level : float

    Returns
    -------
    lo, hi : ndarray of int, (n_runs,)
        First and last bin of each run, increasing.
    """
    L = _LINE_SMOOTH_BINS
    n = padded.size - L + 1
    kernel = np.full(L, 1.0 / L)
    half = 4 * L
    while True:
        # Windows [a, b) round the strong bins, merged where they overlap.
        a, b = np.maximum(strong - half, 0), np.minimum(strong + half + 1, n)
        new = np.concatenate(([True], a[1:] > b[:-1]))
        a, b = a[new], np.maximum.reduceat(b, np.flatnonzero(new))
        # Each window's bins with L - 1 more of padding, gathered: smoothed bin i of a window is the dot
        # product of padded[i:i + L] (np.convolve's "valid" outputs whose inputs lie in one window).
        rel, first = _ranges(a, b + L - 1)  # bins of padded; where each window starts in them
        smooth = np.convolve(padded[rel], kernel, mode="valid")
        keep = np.ones(smooth.size, bool)  # drop outputs that straddle two windows
        keep[(first[1:, None] - L + 1 + np.arange(L - 1)).ravel()] = False
        bins = rel[:smooth.size][keep]  # the smoothed bins
        above = smooth[keep] > level
        above[np.searchsorted(bins, strong)] = True
        # Runs of ``above`` within each window (a new window breaks a run).
        step = np.diff(bins) != 1
        start = above & np.concatenate(([True], ~above[:-1] | step))
        end = above & np.concatenate((~above[1:] | step, [True]))
        lo, hi = bins[start], bins[end]
        holds = np.searchsorted(strong, lo) < np.searchsorted(strong, hi, side="right")
        lo, hi = lo[holds], hi[holds]
        # A run that reaches its window's edge (not the spectrum's) may go on beyond it: widen.
        w = np.searchsorted(a, lo, side="right") - 1  # each run's window
        if not np.any(((lo == a[w]) & (a[w] > 0)) | ((hi + 1 == b[w]) & (b[w] < n))):
            return lo, hi
        half *= 4


def _ranges(a, b):
    """The indices ``a[k] .. b[k] - 1`` of every range, concatenated, (sum(b - a),), and where each range
    starts among them, (n_ranges,); ``b >= a``."""
    size = b - a
    first = np.cumsum(size) - size
    return np.arange(first[-1] + size[-1] if size.size else 0) - np.repeat(first - a, size), first


def _window_max(p, a, b):
    """Largest ``p[a:b + 1]`` per window (0 where a window lies outside ``p``), shape of ``a``.

    Only the windows' own bins are read (they are a few percent of ``p``).
    """
    n, shape = p.size, np.shape(a)
    a, b = np.clip(a, 0, n).ravel(), np.clip(b + 1, 0, n).ravel()  # half-open, within [0, n]
    full = b > a
    out = np.zeros(a.size)
    if full.any():
        idx, first = _ranges(a[full], b[full])
        out[full] = np.maximum.reduceat(p[idx], first)
    return out.reshape(shape)


def _padded_buffer(n):
    """This thread's float32 buffer for :func:`_lines` of an n-bin spectrum (its padding zero), reused by the
    blocks of one size (a worker thread of :mod:`leosop.replay.stream` cleans one block at a time)."""
    buf = getattr(_local, "padded", None)
    if buf is None or buf.size != n + _LINE_SMOOTH_BINS - 1:
        buf = _local.padded = np.zeros(n + _LINE_SMOOTH_BINS - 1, dtype=np.float32)
    return buf


def clean_block(iq, fs, comb, *, pfa=LINE_PFA, kernel=None):
    """A block with its DC, IQ imbalance and CW / narrowband interferers removed, and what was removed.

    1. The block mean (DC offset) is subtracted.
    2. The IQ imbalance is estimated (:func:`iq_imbalance`) and undone when
       beyond 5 sigma of its estimate (a comb's image, ``image_rejection_db``
       below it, would otherwise look like a satellite at minus its Doppler).
    3. Lines that no comb explains (:func:`find_lines`) are zeroed in the
       block's spectrum (excision) and the block transformed back.

    A clean block comes back as it was, less its mean (one FFT spent; one
    more, inverse, when lines are excised). A block holding NaN or inf
    raises NonFiniteSamples (an InputError). :func:`clean_spectrum` is the
    same cleaning for a caller that needs only the cleaned block's FFT.

    Parameters
    ----------
    iq : ndarray of complex, (n,)
    fs : float
    comb : PilotComb
    pfa : float
    kernel : {None, "numba", "numpy"}
        As :func:`find_lines`'; a job of many blocks picks it with
        :func:`~.comb_fit.fit_kernel`.

    Returns
    -------
    iq : ndarray of complex64, (n,)
    cleaning : Cleaning
    """
    return _clean(iq, fs, comb, pfa, kernel, in_place=False)


def clean_spectrum(iq, fs, comb, *, pfa=LINE_PFA, kernel=None, overwrite_iq=False):
    """:func:`clean_block`'s cleaning, for a caller that needs only the cleaned block's FFT.

    ``overwrite_iq``: ``iq`` (an aligned complex64 array, :func:`~.fft.empty_aligned`) may be
    overwritten, and becomes the spectrum: no copy of the block is made.

    The FFT is made in place over the block's DC-free copy (one buffer
    instead of two) and the lines are zeroed in it; the cleaned block in
    time is not made (no inverse FFT when lines are excised). What
    ``find_combs(None, ..., clean=False, spectrum=...)`` takes, as
    :mod:`leosop.replay.stream` prepares its blocks. The FFT differs from
    :func:`clean_block`'s by FFTW's rounding (~1e-7 of the block's largest
    bin before excision; tests/signal/test_frontend.py). Measured on a
    replay's 250,000-point blocks, the FFT in place takes 1.01 ms against
    1.25 ms into a second buffer (:func:`~.fft.fft_in_place`).

    Returns
    -------
    Cleaning
        Its ``spectrum`` is the cleaned block's FFT, complex64 (n,).
    """
    return _clean(iq, fs, comb, pfa, kernel, in_place=True, overwrite=overwrite_iq)[1]


def _clean(iq, fs, comb, pfa, kernel, in_place, overwrite=False):
    """:func:`clean_block` (``in_place`` False) or :func:`clean_spectrum` (True: the returned block is None;
    ``overwrite``: its FFT made in ``iq`` itself where it can be)."""
    from .fft import aligned, empty_aligned, fft, fft_in_place, ifft

    x = np.asarray(iq, dtype=np.complex64)
    n = x.size
    total = x.sum()
    if not np.isfinite(total):  # the callers' check for NaN or inf: one pass over the samples less
        raise NonFiniteSamples("IQ samples contain NaN or inf")
    dc = complex(np.complex64(total / np.intp(n)))  # x.mean(), bit for bit (its division in double)
    into = x if overwrite and x is iq and x.flags.c_contiguous and aligned(x) else empty_aligned(n)
    x = np.subtract(x, np.complex64(dc), out=into)  # the FFT reads it where it lies
    # What is left of the mean in x (a few ulp of the float32 DC) adds n mean^2 to the moments: ~1e-12 of them.
    gain_db, phase_deg, s_gain, s_phase = _imbalance(x)
    corrected = abs(gain_db) > 5.0 * s_gain or abs(phase_deg) > 5.0 * s_phase
    if corrected:
        correct_iq(x, gain_db, phase_deg, out=x)
    spectrum = fft_in_place(x) if in_place else fft(x)
    # |X|^2 straight into this thread's zero-padded buffer in fftshift order (find_lines' layout).
    padded = _padded_buffer(n)
    p = padded[_LINE_SMOOTH_BINS // 2:][:n]
    np.abs(spectrum[n - n // 2:], out=p[:n // 2])
    np.abs(spectrum[:n - n // 2], out=p[n // 2:])
    np.square(p, out=p)
    lines, noise_bin = _lines(padded, _noise_bin(np.square(np.abs(spectrum[::_noise_step(n)]))), fs, comb, pfa,
                              kernel)
    n0 = noise_bin / (n * fs) if noise_bin > 0 else np.nan  # |X|^2 of white noise: n * sigma^2 = n * N0 * fs
    dc_dbhz = 10.0 * np.log10(abs(dc) ** 2 / n0) if abs(dc) > 0 and n0 > 0 else -np.inf
    for ln in lines:
        _subtract_skirt(spectrum, ln, noise_bin, fs)
        spectrum[np.arange(ln.lo_bin, ln.hi_bin + 1) % n] = 0.0
    if in_place:
        x = None
    elif lines:
        x = ifft(spectrum)
    return x, Cleaning(dc, dc_dbhz, gain_db, phase_deg, bool(corrected), tuple(lines), n0, spectrum)
