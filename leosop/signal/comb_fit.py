"""Pilot combs fitted on their decimated tones, one at a time or all at once.

The single-comb ``fast`` fine stage of :mod:`leosop.signal.fine` on the
channels of a :class:`~.comb_grid.DecimationGrid`, with the other combs'
contributions removed (:func:`cleaned_tones`): :func:`fit_comb` fits one comb
(rate search, frequency search, Newton on the joint ML cost, coherent check
of the comb position, tone amplitudes by least squares on the chirp model),
:func:`refine_combs` re-estimates every comb at once from the others'
previous estimates (Jacobi) and :func:`track_combs` fits predicted combs at
once. Used by :func:`~leosop.signal.multicomb.find_combs`.
"""

from dataclasses import dataclass

import numpy as np

from ..kernels import pick
from .coarse import abs2
from .comb_grid import channels_hz, cis, comb_cis, dirichlet, leakage, leakage_all, tone_phases
from .crlb import crlb_frequency_hz2
from .fft import empty_aligned, fft, ifft
from .fine import comb_phasors, dechirped_peak_hz, newton_comb, rate_dpt, rate_grid_search, trimmed_tone_sum, wrap_hz

__all__ = ["COMPILED_MIN_BLOCKS", "CombState", "Fit", "cleaned_tones", "cn0_sigma", "decimate", "decimate_combs",
           "fit_comb", "fit_kernel", "refine_arrays", "refine_combs", "track_arrays", "track_combs"]


@dataclass
class CombState:
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


def decimate(grid, comb, c, wide):
    """Fill ``c.y_wide``: integrate-and-dump outputs of tone positions -wide..wide, (n_seg, 2 wide + 1),
    and the channels' mixing frequencies and phasors at the segment centres."""
    c.f_c = channels_hz(comb, c.d_c, wide)
    c.mix = cis(-np.multiply.outer(grid.t_abs, c.f_c))
    c.y_wide = grid.channels(c.f_c)


def decimate_combs(grid, comb, combs, wide):
    """:func:`decimate` for several combs at once."""
    f_c = channels_hz(comb, np.array([c.d_c for c in combs])[:, None], wide)  # (C, W)
    mix = cis(-np.multiply.outer(grid.t_abs, f_c))
    y = grid.channels(f_c.reshape(-1)).reshape(grid.n_seg, len(combs), -1)
    for j, c in enumerate(combs):
        c.f_c, c.mix, c.y_wide = f_c[j], mix[:, j], y[:, j]


def fit_comb(grid, comb, c, z_wide, *, max_rate, pfa, start=None, resolve=True):
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
            rate = rate_dpt(yt, dt_dec, pfa)
            if rate is None:
                rate, f_res = rate_grid_search(yt, tau, known, dt_dec, max_rate, dur)
        if f_res is None:
            f_res = dechirped_peak_hz(yt, tau, rate, known, dt_dec)
    else:
        f_res, rate = start
        if f_res is None:
            yt = np.ascontiguousarray(y.T, dtype=np.complex64)
            f_res = dechirped_peak_hz(yt, tau, rate, known, dt_dec)
    delta, rate, y_sum = newton_comb(y, tau, tpow, ratio, f_res, rate, known)
    if resolve and extra:
        phase = delta * tau + 0.5 * rate * tau**2
        power = abs2(np.sum(z_wide * comb_phasors(phase, ratio * phase, half + extra), axis=0))
        shift = int(np.argmax(np.convolve(power, np.ones(comb.n_tones), mode="valid"))) - extra
        if shift:
            return shift, c.d_c + delta
    n, fs = grid.n, grid.fs
    c.doppler_hz, c.rate = c.d_c + delta, rate
    energy = np.sum(abs2(y), axis=0)
    resid = np.sort(np.maximum(energy - abs2(y_sum) / grid.n_seg, 0.0))
    sigma2 = (0.5 * float(resid[(resid.size - 1) // 2] + resid[resid.size // 2])
              / ((grid.n_seg - 1) * grid.seg * grid.noise_gain))
    a2 = np.maximum(abs2(y_sum) - n * sigma2, 0.0) / n**2
    cn0_k = a2 * fs / sigma2 if sigma2 > 0 else np.full(comb.n_tones, np.inf)
    w = np.sum(cn0_k * comb.doppler_scale**2)
    c.sigma_hz = float(np.sqrt(crlb_frequency_hz2(10.0 * np.log10(w), n, fs))) if w > 0 else np.inf
    mean_cn0 = np.mean(cn0_k)
    c.cn0_dbhz = float(10.0 * np.log10(mean_cn0)) if mean_cn0 > 0 else -np.inf
    c.statistic = float(np.mean(abs2(y_sum)) / (n * sigma2)) if sigma2 > 0 else np.inf
    cycles, c.nu = tone_phases(comb, c.doppler_hz, c.rate, grid.tau)
    k = slice(extra, extra + comb.n_tones)
    e = cis(cycles)
    g = e * c.mix[:, k] * dirichlet(c.nu - c.f_c[k], grid.counts[:, None], grid.fs)
    c.amp = np.sum(y * np.conj(g), axis=0) / np.sum(abs2(g), axis=0)
    c.val = (e * c.amp).astype(np.complex64)  # leakage into other combs: 1e-7 relative
    return 0, None


def cleaned_tones(grid, comb, combs, j):
    """Decimated tones of comb ``j`` with every other comb's contribution removed."""
    c = combs[j]
    r = leakage(grid, combs[:j] + combs[j + 1:], c.f_c, c.mix)
    return c.y_wide.astype(complex) if r is None else c.y_wide - r


def _stacked(arrays):
    """C arrays (B, W) as one (B, C, W): np.stack(axis=1) without its wrappers (half the time on a comb's few tones)."""
    return np.concatenate(arrays, axis=1).reshape(arrays[0].shape[0], len(arrays), -1)


def newton_combs(y, tau, tpow, ratio, f, r, n_iter=2):
    """:func:`~.fine.newton_comb` for C combs at once (no known phase): ``y`` (B, C, K), ``f``, ``r`` (C,)
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
        u = comb_cis(-phase, -ratio * phase, half)
        u *= y
        m = (tpow.T @ u.reshape(n_seg, -1).view(float)).view(complex).reshape(5, n_c, n_k)
        y0, m1, m2 = m[0], m[1], m[2]
        q = m[1:] * np.conj(y0)
        g_f = 2.0 * (q[0].imag @ a)
        g_r = 2.0 * (q[1].imag @ b)
        h_ff = 2.0 * ((abs2(m1) - q[1].real) @ (a * a))
        h_fr = 2.0 * (((np.conj(m1) * m2).real - q[2].real) @ (a * b))
        h_rr = 2.0 * ((abs2(m2) - q[3].real) @ (b * b))
        det = h_ff * h_rr - h_fr * h_fr
        live &= np.isfinite(det) & (h_ff < 0.0) & (det > 0.0)
        safe = np.where(live, det, 1.0)
        step_f = np.where(live, -(h_rr * g_f - h_fr * g_r) / safe, 0.0)
        step_r = np.where(live, -(h_ff * g_r - h_fr * g_f) / safe, 0.0)
        f += step_f
        r += step_r
    return f, r, y0 - 1j * (step_f[:, None] * a * m1 + step_r[:, None] * b * m2)


#: Blocks a job needs before the compiled kernels pay for their one-off load: numba's import and its machine
#: code from the cache take 0.25-0.45 s per process (measured; even a trivial cached function's first call
#: takes 0.3 s); the fits (:mod:`.fitkernels`) save ~0.65 ms per tracking block (0.1 s, 7 combs), the
#: cleaning's line finding (:mod:`.cleankernels`) ~0.5 ms (0.65 against 0.17 ms).
COMPILED_MIN_BLOCKS = 500


def fit_kernel(n_blocks):
    """The ``kernel`` of a job of ``n_blocks`` blocks: "numpy" below :data:`COMPILED_MIN_BLOCKS`, else None
    (numba when installed). Decided by the job alone, so a recording's result does not depend on what the
    process ran before."""
    return "numpy" if n_blocks < COMPILED_MIN_BLOCKS else None


def refine_combs(grid, comb, combs, clean=True, *, kernel=None):
    """One pass of re-estimation of every comb (Newton from its estimate) with all the others removed
    (``clean``), all combs at once (each from the others' previous estimates).

    ``kernel``: "numpy", or "numba" (:mod:`.fitkernels`, one compiled call; agrees to float32 rounding);
    None: numba when installed.
    """
    n, fs, n_k = grid.n, grid.fs, comb.n_tones
    extra = (combs[0].f_c.size - n_k) // 2
    k = slice(extra, extra + n_k)
    f_c = np.array([c.f_c for c in combs])
    mix = _stacked([c.mix for c in combs])
    d_c = np.array([c.d_c for c in combs])
    z = _stacked([c.y_wide for c in combs])
    compiled = pick(kernel, "leosop.signal.fitkernels")
    if compiled is not None:
        val = _stacked([c.val for c in combs]) if clean else None
        nu = _stacked([c.nu for c in combs]) if clean else None
        fit = refine_arrays(compiled, grid, comb, z, extra, f_c, mix, d_c,
                            np.array([c.doppler_hz for c in combs]) - d_c, np.array([c.rate for c in combs]), val, nu)
        _store(combs, n, fs, fit)
        return
    if clean:
        z = z - leakage_all(grid, f_c, mix, _stacked([c.val for c in combs]), _stacked([c.nu for c in combs]))
    y = z[:, :, k]
    delta, rate, y_sum = newton_combs(y, grid.tau, grid.tpow, comb.tone_spacing_hz / comb.carrier_hz,
                                     [c.doppler_hz for c in combs] - d_c, [c.rate for c in combs])
    doppler = d_c + delta
    # Amplitudes, noise and C/N0 as fit_comb, per comb.
    p_sum = abs2(y_sum)
    energy = np.sum(abs2(y), axis=0)
    resid = np.sort(np.maximum(energy - p_sum / grid.n_seg, 0.0), axis=1)
    sigma2 = (0.5 * (resid[:, (n_k - 1) // 2] + resid[:, n_k // 2])
              / ((grid.n_seg - 1) * grid.seg * grid.noise_gain))
    pos = sigma2 > 0
    s2 = np.where(pos, sigma2, 1.0)[:, None]
    cn0_k = np.where(pos[:, None], np.maximum(p_sum - n * s2, 0.0) / n**2 * fs / s2, np.inf)
    w = cn0_k @ comb.doppler_scale**2
    mean_cn0 = cn0_k.sum(axis=1) / n_k  # np.mean's arithmetic without its wrappers
    statistic = np.where(pos, p_sum.sum(axis=1) / n_k / (n * s2[:, 0]), np.inf)
    s = comb.doppler_scale
    phase = np.multiply.outer(grid.tau, doppler) + np.multiply.outer(0.5 * grid.tau**2, rate)  # (B, C)
    nu = comb.offsets_hz + (doppler + np.multiply.outer(grid.tau, rate))[:, :, None] * s
    # Tone k: k spacing tau + s_k phase = phase + k (spacing tau + ratio phase).
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    e = comb_cis(phase, comb.tone_spacing_hz * grid.tau[:, None] + ratio * phase, n_k // 2)
    g = e * mix[:, :, k] * dirichlet(nu - f_c[:, k], grid.counts[:, None, None], grid.fs)
    amp = np.sum(y * np.conj(g), axis=0) / np.sum(abs2(g), axis=0)
    val = (e * amp).astype(np.complex64)
    _store(combs, n, fs, Fit(doppler, rate, w, mean_cn0, statistic, amp, val, nu, z))


@dataclass
class Fit:
    """One compiled fitting pass over C combs (:func:`refine_arrays`), arrays of shape (C,) unless stated.

    ``w`` (sum of tone C/N0 times Doppler scale squared) and ``mean_cn0`` (linear) give the Doppler sigma
    and the C/N0 (:func:`cn0_sigma`); ``amp`` (C, K) the tone amplitudes, ``val`` (B, C, K) complex64 and
    ``nu`` (B, C, K) the tones' values and frequencies at the segment centres, ``z`` (B, C, W) the tones
    the fit used (cleaned).
    """

    doppler_hz: np.ndarray
    rate: np.ndarray
    w: np.ndarray
    mean_cn0: np.ndarray
    statistic: np.ndarray
    amp: np.ndarray
    val: np.ndarray
    nu: np.ndarray
    z: np.ndarray

    def subset(self, keep):
        """The fit of the combs ``keep`` (indices) alone."""
        return Fit(self.doppler_hz[keep], self.rate[keep], self.w[keep], self.mean_cn0[keep], self.statistic[keep],
                   self.amp[keep], self.val[:, keep], self.nu[:, keep], self.z[:, keep])


def refine_arrays(compiled, grid, comb, z_in, extra, f_c, mix, d_c, f0, r0, val=None, nu=None):
    """One pass of :func:`refine_combs` in one compiled call (:func:`.fitkernels.refine`), on arrays.

    Parameters
    ----------
    compiled : module
        :mod:`.fitkernels`.
    grid : DecimationGrid
    comb : PilotComb
    z_in : ndarray of complex128, (B, C, W)
        Raw decimated tones of each comb's W channels; the comb's are ``extra .. extra + K - 1``.
    extra : int
    f_c : (C, W); mix : (B, C, W) complex128
        Channel mixing frequencies and phasors.
    d_c, f0, r0 : (C,)
        Mixing centres, Doppler offsets from them and rates to start from.
    val, nu : ndarray, (B, C, K), optional
        The combs' previous tone values and frequencies: given, each comb's channels are cleaned of
        the others' tones first.

    Returns
    -------
    Fit
    """
    n_seg, n_c, _ = z_in.shape
    n_k = comb.n_tones
    clean = val is not None
    if not clean:
        val, nu = np.zeros((n_seg, n_c, n_k), np.complex64), np.zeros((n_seg, n_c, n_k))
    out_z = np.empty_like(z_in)
    doppler, rate, w, mean_cn0, statistic = np.empty((5, n_c))
    amp = np.empty((n_c, n_k), dtype=complex)
    val_out, nu_out = np.empty((n_seg, n_c, n_k), np.complex64), np.empty((n_seg, n_c, n_k))
    compiled.refine(z_in, clean, extra, n_k, grid.tau, grid.tpow, comb.tone_spacing_hz / comb.carrier_hz,
                    comb.tone_spacing_hz, comb.offsets_hz, comb.doppler_scale, f_c, mix, val, nu,
                    grid.counts.astype(float), grid.fs, grid.reach_hz, d_c, f0, r0, grid.n, grid.seg,
                    grid.noise_gain, out_z, doppler, rate, w, mean_cn0, statistic, amp, val_out, nu_out)
    return Fit(doppler, rate, w, mean_cn0, statistic, amp, val_out, nu_out, out_z)


def cn0_sigma(w, mean_cn0, n, fs):
    """Doppler sigma [Hz] and C/N0 [dB-Hz] of combs from :class:`Fit`'s ``w`` and ``mean_cn0`` (C,), for
    blocks of ``n`` samples at ``fs``: the Cramér-Rao bound of the tones' C/N0s, inf (-inf dB-Hz) without
    signal."""
    with np.errstate(divide="ignore"):
        sigma_hz = np.where(w > 0, np.sqrt(crlb_frequency_hz2(10.0 * np.log10(np.where(w > 0, w, 1.0)), n, fs)), np.inf)
        cn0_dbhz = np.where(mean_cn0 > 0, 10.0 * np.log10(np.where(mean_cn0 > 0, mean_cn0, 1.0)), -np.inf)
    return sigma_hz, cn0_dbhz


def _store(combs, n, fs, fit):
    """:func:`refine_combs`' results (a :class:`Fit`) written to its combs."""
    sigma_hz, cn0_dbhz = cn0_sigma(fit.w, fit.mean_cn0, n, fs)
    for j, c in enumerate(combs):
        c.z_wide = fit.z[:, j]
        c.doppler_hz, c.rate = float(fit.doppler_hz[j]), float(fit.rate[j])
        c.sigma_hz, c.cn0_dbhz, c.statistic = float(sigma_hz[j]), float(cn0_dbhz[j]), float(fit.statistic[j])
        c.amp, c.val, c.nu = fit.amp[j], fit.val[:, j], fit.nu[:, j]


def dechirped_peaks_hz(y, tau, rate, dt_dec):
    """:func:`~.fine.dechirped_peak_hz` of C combs at once: ``y`` (B, C, K), ``rate`` (C,). Returns (C,) [Hz]."""
    n_seg = y.shape[0]
    z = y.transpose(1, 2, 0) * cis(-np.multiply.outer(0.5 * np.asarray(rate), tau**2))[:, None, :]
    n_fft = 2 * n_seg
    p = trimmed_tone_sum(abs2(fft(z.astype(np.complex64), n_fft, scratch=True)))  # (C, n_fft)
    i = np.argmax(p, axis=1)
    rows = np.arange(p.shape[0])
    pm, p0, pp = p[rows, i - 1], p[rows, i], p[rows, (i + 1) % n_fft]
    den = pm - 2.0 * p0 + pp
    vertex = np.clip(0.5 * (pm - pp) / np.where(den != 0.0, den, -1.0), -0.5, 0.5) * (den != 0.0)
    return wrap_hz((i + vertex) / (n_fft * dt_dec), 1.0 / dt_dec)


def track_combs(grid, comb, pred, pred_rate, wide, max_rate, pfa, kernel=None):
    """Every predicted comb fitted at once from its own tones (no cancellation yet), the comb
    position checked as in :func:`fit_comb` (a shifted comb is refitted alone). Returns the combs.
    ``kernel``: :func:`refine_combs`'."""
    half = comb.n_tones // 2
    extra = wide - half
    ratio = comb.tone_spacing_hz / comb.carrier_hz
    combs = [CombState(float(p), None, predicted_index=i) for i, p in enumerate(pred)]
    decimate_combs(grid, comb, combs, wide)
    y = _stacked([c.y_wide[:, extra:extra + comb.n_tones] for c in combs])
    f_res = dechirped_peaks_hz(y, grid.tau, pred_rate, grid.seg / grid.fs)
    for c, f, r in zip(combs, f_res, pred_rate):
        c.doppler_hz, c.rate = c.d_c + f, float(r)
    refine_combs(grid, comb, combs, clean=False, kernel=kernel)
    if extra == 0:
        return combs
    delta = np.array([c.doppler_hz - c.d_c for c in combs])
    rate = np.array([c.rate for c in combs])
    phase = np.multiply.outer(grid.tau, delta) + np.multiply.outer(0.5 * grid.tau**2, rate)
    u = comb_cis(-phase, -ratio * phase, wide)
    power = abs2(np.sum(_stacked([c.y_wide for c in combs]) * u, axis=0))  # (C, W)
    box = np.cumsum(np.pad(power, ((0, 0), (1, 0))), axis=1)
    shift = np.argmax(box[:, comb.n_tones:] - box[:, :-comb.n_tones], axis=1) - extra
    for c, sh in zip(combs, shift):
        if sh:
            centre = c.doppler_hz
            c.d_c = centre + sh * comb.tone_spacing_hz * (1.0 + centre / comb.carrier_hz)
            decimate(grid, comb, c, wide)
            fit_comb(grid, comb, c, c.y_wide.astype(complex), max_rate=max_rate, pfa=pfa, start=(0.0, c.rate),
                 resolve=False)
    return combs


def track_arrays(compiled, grid, comb, pred, pred_rate):
    """:func:`track_combs` of a tracking block (each comb's own channels, no position check) in compiled
    calls and two FFTs, on arrays.

    Every predicted comb is decimated (:func:`.fitkernels.fold`, the channels' inverse FFTs,
    :func:`.fitkernels.channel_tones`), started at its dechirped peak (:func:`.fitkernels.dechirped_peaks`)
    and fitted by one pass of :func:`refine_arrays` without cleaning. A tracking block of 7 combs
    takes a few numpy calls where :func:`track_combs` makes some two hundred, and most of it runs
    without the GIL.

    Parameters
    ----------
    compiled : module
        :mod:`.fitkernels`.
    grid : DecimationGrid
    comb : PilotComb
    pred, pred_rate : ndarray, (C,)
        Predicted central-tone Dopplers [Hz] and rates [Hz/s].

    Returns
    -------
    fit : Fit
    channels : tuple
        ``(z, f_c, mix, d_c)``: the raw decimated tones (B, C, K) complex128, the channels' mixing
        frequencies (C, K) and phasors (B, C, K), and the mixing centres (C,), for
        :func:`refine_arrays`' further passes.
    """
    n_c, n_k, n_seg = pred.size, comb.n_tones, grid.n_seg
    d_c = np.asarray(pred, dtype=float)
    f_c = channels_hz(comb, d_c[:, None], n_k // 2)
    df = grid.fs / grid.n_fft
    bins = np.round(f_c.reshape(-1) / df).astype(np.int64)
    k0 = int(grid.k[0])
    folded = empty_aligned((n_c * n_k, n_seg), dtype=np.complex64)
    compiled.fold(grid.spectrum, bins, k0, grid.weights, folded)
    z = np.empty((n_seg, n_c, n_k), dtype=complex)
    mix = np.empty_like(z)
    zd = empty_aligned((n_c, n_k, 2 * n_seg), dtype=np.complex64)
    rate = np.asarray(pred_rate, dtype=float)
    compiled.channel_tones(ifft(folded), bins, df, k0, f_c, grid.t_abs, grid.tau, rate, z, mix, zd)
    f0 = np.empty(n_c)
    compiled.dechirped_peaks(fft(zd, scratch=True), grid.seg / grid.fs, f0)
    return refine_arrays(compiled, grid, comb, z, 0, f_c, mix, d_c, f0, rate), (z, f_c, mix, d_c)
