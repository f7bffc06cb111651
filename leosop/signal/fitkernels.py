"""Compiled (numba) fits of a block's pilot combs; optional.

Imported only when numba is installed (``pip install leosop[fast]``); the
numpy paths of :mod:`leosop.signal.comb_fit` stay the fallback and the
reference.

- :func:`refine`: one pass of :func:`~leosop.signal.comb_fit.refine_combs`
  for every comb of a block: the other combs' leakage into its channels
  (:func:`~leosop.signal.comb_grid.leakage_all`), two Newton steps on the
  joint cost (:func:`~leosop.signal.comb_fit.newton_combs`), the noise, C/N0
  and detection statistic, and the tone amplitudes by least squares on the
  chirp model.
- :func:`fold`, :func:`channel_tones`, :func:`dechirped_peaks`: the rest of
  a tracking block (:func:`~leosop.signal.comb_fit.track_arrays`): the
  channels' decimation from the block's FFT, and each comb's dechirped peak.
- :func:`comb_segments`, :func:`subtract_windows`: found combs subtracted
  from a block's FFT before the search for more
  (:func:`~leosop.signal.multicomb.find_combs`).

On a tracking block (80 segments, 7 combs of 9 tones) the numpy path is a
few hundred calls on small arrays, mostly call overhead; :func:`refine`
takes ~0.2 ms (~0.3 ms cleaning). Its phasors at equally spaced segment
centres come by rotation (:func:`_quad_cis`) rather than a sine and cosine
each: 0.253 -> 0.207 ms a call (100 segments, 7 combs, calls recorded from
a 60 s replay). Over a 60 s replay (7 satellites, one
thread) the comb search averages 1.45 ms a block with the whole tracking
block compiled, 1.75 ms with only :func:`refine`.
The phasors are double precision (:func:`_cis`) where numpy's round the
phase to float32 (~1e-7 rad), and the moments are plain loops rather than
BLAS: the two paths differ by that rounding (tests/signal/test_multicomb.py
measures and bounds it). ``nogil``: the comb search of one thread runs
beside the block cleaning of another (:mod:`leosop.replay.stream`).
``cache=True`` writes the machine code next to this file (or under
``NUMBA_CACHE_DIR``).
"""

import numba
import numpy as np

__all__ = ["channel_tones", "comb_segments", "dechirped_peaks", "fold", "refine", "subtract_windows"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _cis(cycles):
    """exp(j 2 pi cycles) in double precision, from the phase reduced to [-0.5, 0.5] cycles
    (:func:`~.comb_grid.cis` rounds it to float32: ~1e-7 rad)."""
    x = 2.0 * np.pi * (cycles - np.rint(cycles))
    return complex(np.cos(x), np.sin(x))


@_jit
def _comb_from(e0, z, half, out):
    """``e0 z^k``, k = -half..half, into ``out`` (2 half + 1,)."""
    zc = z.conjugate()
    out[half] = e0
    for k in range(1, half + 1):
        out[half + k] = out[half + k - 1] * z
        out[half - k] = out[half - k + 1] * zc


@_jit
def _comb_cis(a_cycles, b_cycles, half, out):
    """exp(j 2 pi (a + k b)), k = -half..half, into ``out`` (2 half + 1,): :func:`~.comb_grid.comb_cis`."""
    _comb_from(_cis(a_cycles), _cis(b_cycles), half, out)


@_jit
def _quad_cis(c1, c2, tau0, dt, out):
    """exp(j 2 pi (c1 tau_b + c2 tau_b^2)) at ``tau_b = tau0 + b dt`` into ``out`` (n,): two rotations a
    step in place of a sine and cosine (the phase's first and second differences; ~1e-14 rad after
    100 steps, against :func:`_cis`' ~1e-16)."""
    e = _cis(c1 * tau0 + c2 * tau0 * tau0)
    d = _cis(c1 * dt + c2 * dt * (2.0 * tau0 + dt))
    dd = _cis(2.0 * c2 * dt * dt)
    for b in range(out.size):
        out[b] = e
        e *= d
        d *= dd


@_jit
def _dirichlet(delta_hz, count, fs):
    """:func:`~.comb_grid.dirichlet` of one tone and segment, in double precision."""
    x = delta_hz * (np.pi / fs)
    return _dirichlet_of(np.sin(x * count), x, count)


@_jit
def _dirichlet_of(sin_xl, x, count):
    """:func:`_dirichlet` from its numerator ``sin(x L)`` and ``x = pi delta / fs``."""
    den = x * (1.0 - x * x * (1.0 / 6.0))
    if den == 0.0:
        return count
    return sin_xl / den


@_jit
def _leakage(z, f_c, mix, val, nu, counts, fs, reach_hz, out):
    """``out = z - leakage_all(...)``: every comb's channels less the other combs' tones within reach."""
    n_seg, n_c, n_w = mix.shape
    n_k = val.shape[2]
    mid = n_seg // 2
    out[:] = z
    src_i = np.empty(n_c * n_k, dtype=np.int64)
    src_k = np.empty(n_c * n_k, dtype=np.int64)
    for j in range(n_c):
        for w in range(n_w):
            fc = f_c[j, w]
            n_src = 0
            for i in range(n_c):
                for k in range(n_k):
                    if i != j and abs(nu[mid, i, k] - fc) < reach_hz:
                        src_i[n_src], src_k[n_src] = i, k
                        n_src += 1
            if n_src == 0:
                continue
            for b in range(n_seg):
                acc = 0j
                for s in range(n_src):
                    i, k = src_i[s], src_k[s]
                    acc += val[b, i, k] * _dirichlet(nu[b, i, k] - fc, counts[b], fs)
                out[b, j, w] -= acc * mix[b, j, w]


@_jit
def refine(z_in, clean, k0, n_k, tau, tpow, ratio, spacing_hz, offsets_hz, scale_hz, f_c, mix, val, nu, counts,
           fs, reach_hz, d_c, f0, r0, n, seg, noise_gain, z, doppler, rate, w, mean_cn0, statistic, amp,
           val_out, nu_out):
    """One pass of :func:`~leosop.signal.comb_fit.refine_combs` over C combs (outputs written in place).

    Parameters
    ----------
    z_in : ndarray of complex128, (B, C, W)
        Raw decimated tones of every comb's W channels.
    clean : bool
        Remove the other combs' leakage (``val``, ``nu``) first.
    k0, n_k : int
        The comb's tones are channels ``k0 .. k0 + n_k - 1``.
    tau : (B,); tpow : (B, 5)
        Segment centres from the block centre and their powers 0..4.
    ratio, spacing_hz : float
        Tone spacing over carrier; tone spacing.
    offsets_hz, scale_hz : (K,)
        The comb's tone offsets and Doppler scale factors.
    f_c : (C, W); mix : (B, C, W) complex128
        Channel mixing frequencies and phasors.
    val : (B, C, K) complex64; nu : (B, C, K)
        Each comb's previous tone values and frequencies (read when ``clean``).
    counts : (B,) float64; fs, reach_hz : float
        Samples per segment, sample rate, leakage reach.
    d_c, f0, r0 : (C,)
        Mixing centres, Doppler offsets from them and rates to start from.
    n, seg : int; noise_gain : float
        Block length, segment length, the grid's decimated-noise fraction.
    z : (B, C, W) complex128
        Out: the tones the fit used (cleaned).
    doppler, rate, w, mean_cn0, statistic : (C,)
        Out: Doppler and rate; C/N0-weighted scale sum, mean C/N0 (linear) and statistic.
    amp : (C, K) complex128; val_out : (B, C, K) complex64; nu_out : (B, C, K)
        Out: tone amplitudes, values and frequencies at the segment centres.
    """
    n_seg, n_c, n_w = z_in.shape
    half = n_k // 2
    last = n_seg - 1
    if clean:
        _leakage(z_in, f_c, mix, val, nu, counts, fs, reach_hz, z)
    else:
        z[:] = z_in
    a = np.empty(n_k)
    bq = np.empty(n_k)
    for k in range(n_k):
        s = 1.0 + ratio * (k - half)
        a[k] = 2.0 * np.pi * s
        bq[k] = np.pi * s
    u = np.empty((n_seg, n_k), dtype=np.complex128)
    m = np.empty((5, n_k), dtype=np.complex128)
    y_sum = np.empty(n_k, dtype=np.complex128)
    resid = np.empty(n_k)
    cn0_k = np.empty(n_k)
    e_col = np.empty((n_seg, n_k), dtype=np.complex128)
    eb = np.empty(n_seg, dtype=np.complex128)
    zb = np.empty(n_seg, dtype=np.complex128)
    # The phasors of the leading segments of equal length (equally spaced centres) by rotation.
    n_uni = 1
    while n_uni < n_seg and counts[n_uni] == counts[0]:
        n_uni += 1
    dt = tau[1] - tau[0] if n_seg > 1 else 0.0
    for j in range(n_c):
        f, r = f0[j], r0[j]
        step_f = step_r = 0.0
        live = True
        for _ in range(2):
            _quad_cis(-f, -0.5 * r, tau[0], dt, eb[:n_uni])
            _quad_cis(-ratio * f, -0.5 * ratio * r, tau[0], dt, zb[:n_uni])
            for b in range(n_uni):
                _comb_from(eb[b], zb[b], half, u[b])
            for b in range(n_uni, n_seg):
                phase = tau[b] * f + 0.5 * tpow[b, 2] * r
                _comb_cis(-phase, -ratio * phase, half, u[b])
            for k in range(n_k):  # the moments sum_b tau^p u z, p = 0..4, in registers
                m0 = m1 = m2 = m3 = m4 = 0j
                for b in range(n_seg):
                    v = u[b, k] * z[b, j, k0 + k]
                    m0 += v
                    m1 += tpow[b, 1] * v
                    m2 += tpow[b, 2] * v
                    m3 += tpow[b, 3] * v
                    m4 += tpow[b, 4] * v
                m[0, k], m[1, k], m[2, k], m[3, k], m[4, k] = m0, m1, m2, m3, m4
            g_f = g_r = h_ff = h_fr = h_rr = 0.0
            for k in range(n_k):
                y0c = m[0, k].conjugate()
                q0, q1, q2, q3 = m[1, k] * y0c, m[2, k] * y0c, m[3, k] * y0c, m[4, k] * y0c
                m1, m2 = m[1, k], m[2, k]
                g_f += q0.imag * a[k]
                g_r += q1.imag * bq[k]
                h_ff += (m1.real * m1.real + m1.imag * m1.imag - q1.real) * (a[k] * a[k])
                h_fr += ((m1.conjugate() * m2).real - q2.real) * (a[k] * bq[k])
                h_rr += (m2.real * m2.real + m2.imag * m2.imag - q3.real) * (bq[k] * bq[k])
            g_f, g_r, h_ff, h_fr, h_rr = 2.0 * g_f, 2.0 * g_r, 2.0 * h_ff, 2.0 * h_fr, 2.0 * h_rr
            det = h_ff * h_rr - h_fr * h_fr
            live = live and np.isfinite(det) and h_ff < 0.0 and det > 0.0
            if live:
                step_f = -(h_rr * g_f - h_fr * g_r) / det
                step_r = -(h_ff * g_r - h_fr * g_f) / det
            else:
                step_f = step_r = 0.0
            f += step_f
            r += step_r
        for k in range(n_k):
            y_sum[k] = m[0, k] - 1j * (step_f * a[k] * m[1, k] + step_r * bq[k] * m[2, k])
        dop = d_c[j] + f
        doppler[j], rate[j] = dop, r
        # Noise from the median residual energy of the tones, C/N0 per tone, the statistic.
        for k in range(n_k):
            e = 0.0
            for b in range(n_seg):
                v = z[b, j, k0 + k]
                e += v.real * v.real + v.imag * v.imag
            p_sum = y_sum[k].real * y_sum[k].real + y_sum[k].imag * y_sum[k].imag
            resid[k] = max(e - p_sum / n_seg, 0.0)
        resid.sort()
        sigma2 = 0.5 * (resid[(n_k - 1) // 2] + resid[n_k // 2]) / ((n_seg - 1) * seg * noise_gain)
        w_j = cn0_sum = p_tot = 0.0
        for k in range(n_k):
            p_sum = y_sum[k].real * y_sum[k].real + y_sum[k].imag * y_sum[k].imag
            p_tot += p_sum
            if sigma2 > 0:
                cn0_k[k] = max(p_sum - n * sigma2, 0.0) / n**2 * fs / sigma2
            else:
                cn0_k[k] = np.inf
            w_j += cn0_k[k] * (scale_hz[k] * scale_hz[k])
            cn0_sum += cn0_k[k]
        w[j], mean_cn0[j] = w_j, cn0_sum / n_k
        statistic[j] = p_tot / n_k / (n * sigma2) if sigma2 > 0 else np.inf
        # Tone amplitudes by least squares on the chirp model. The Dirichlet kernels' numerators
        # sin(x L) follow the equally spaced segment centres (all but the last) as a rotation (~1e-15 rad).
        _quad_cis(dop, 0.5 * r, tau[0], dt, eb[:n_uni])
        _quad_cis(spacing_hz + ratio * dop, 0.5 * ratio * r, tau[0], dt, zb[:n_uni])
        for b in range(n_uni):
            _comb_from(eb[b], zb[b], half, e_col[b])
        for b in range(n_uni, n_seg):
            phase = tau[b] * dop + 0.5 * tau[b] ** 2 * r
            _comb_cis(phase, spacing_hz * tau[b] + ratio * phase, half, e_col[b])
        for k in range(n_k):
            kk = k0 + k
            rot = _cis(0.5 * counts[0] / fs * (offsets_hz[k] + (dop + tau[0] * r) * scale_hz[k] - f_c[j, kk]))
            step = _cis(0.5 * counts[0] / fs * r * scale_hz[k] * (tau[1] - tau[0])) if n_seg > 1 else rot
            num = 0j
            den = 0.0
            for b in range(n_seg):
                f_t = offsets_hz[k] + (dop + tau[b] * r) * scale_hz[k]
                nu_out[b, j, k] = f_t
                x = (f_t - f_c[j, kk]) * (np.pi / fs)
                if b < last and counts[b] == counts[0]:
                    d = _dirichlet_of(rot.imag, x, counts[b])
                else:
                    d = _dirichlet_of(np.sin(x * counts[b]), x, counts[b])
                rot *= step
                g = e_col[b, k] * mix[b, j, kk] * d
                num += z[b, j, kk] * g.conjugate()
                den += g.real * g.real + g.imag * g.imag
            amp[j, k] = num / den
        for b in range(n_seg):
            for k in range(n_k):
                val_out[b, j, k] = np.complex64(e_col[b, k] * amp[j, k])


@_jit
def fold(spectrum, bins, k0, weights, out):
    """The alias sums of :meth:`~.comb_grid.DecimationGrid.channels` for channels at FFT bins ``bins``.

    ``out[c, q] = sum_p spectrum[(bins[c] + k0 + q + p B) mod n] weights[q + p B]``: the
    (n_ch, B) input of the channels' B-point inverse FFTs.

    Parameters
    ----------
    spectrum : ndarray of complex64, (n,)
    bins : ndarray of int64, (n_ch,)
    k0 : int
        The grid's first bin offset (``grid.k[0]``).
    weights : ndarray of complex64, (R B,)
        The grid's alias weights.
    out : ndarray of complex64, (n_ch, B)
    """
    n = spectrum.size
    n_ch, n_seg = out.shape
    n_alias = weights.size // n_seg
    for c in range(n_ch):
        start = bins[c] + k0
        for q in range(n_seg):
            acc = 0j
            for p in range(n_alias):
                acc += spectrum[(start + q + p * n_seg) % n] * weights[q + p * n_seg]
            out[c, q] = acc


@_jit
def channel_tones(y_t, bins, df, k0, f_c, t_abs, tau, rate, z, mix, zd):
    """A tracking block's decimated tones from the channels' inverse FFTs, and what their fits need.

    The phase ramp and off-bin rotation of :meth:`~.comb_grid.DecimationGrid.channels`, the
    channels' mixing phasors (:func:`~.comb_fit.decimate_combs`) and the tones dechirped at their
    predicted rates for :func:`~.comb_fit.dechirped_peaks_hz`. Phasors along the segments and the tones
    are products of two exponentials (segment centres equally spaced but the last): ~1e-15 rad.

    Parameters
    ----------
    y_t : ndarray of complex64, (C K, B)
        Inverse FFTs of :func:`fold`'s output, comb by comb, tone by tone.
    bins : (C K,) int64; df : float; k0 : int
        Their FFT bins, the bin spacing and the grid's first bin offset.
    f_c : (C, K)
        Channel mixing frequencies (:func:`~.comb_grid.channels_hz`), linear in the tone.
    t_abs, tau : (B,)
        Segment centres from the first sample and from the block centre.
    rate : (C,)
        Predicted rates [Hz/s].
    z : (B, C, K) complex128
        Out: the decimated tones.
    mix : (B, C, K) complex128
        Out: ``exp(-j 2 pi f_c t_abs)``.
    zd : (C, K, 2 B) complex64
        Out: the tones times ``exp(-j pi rate tau^2)``, zero-padded.
    """
    n_c, n_k = f_c.shape
    n_seg = tau.size
    last = n_seg - 1
    zd[:] = 0.0
    dechirp = np.empty(n_seg, dtype=np.complex128)
    for j in range(n_c):
        step_hz = f_c[j, 1] - f_c[j, 0] if n_k > 1 else 0.0
        for m in range(n_seg):
            e0 = _cis(-t_abs[m] * f_c[j, 0])
            z_k = _cis(-t_abs[m] * step_hz)
            for k in range(n_k):
                mix[m, j, k] = e0
                e0 *= z_k
            dechirp[m] = _cis(-0.5 * rate[j] * tau[m] * tau[m])
        for k in range(n_k):
            c = j * n_k + k
            off_hz = f_c[j, k] - bins[c] * df
            ramp = _cis(-t_abs[0] * off_hz)
            step = _cis(k0 / n_seg - (t_abs[1] - t_abs[0]) * off_hz) if n_seg > 1 else ramp
            for m in range(n_seg):
                if m == last and m > 0:
                    ramp = _cis(k0 / n_seg * m - t_abs[m] * off_hz)
                v = complex(y_t[c, m]) * ramp
                z[m, j, k] = v
                zd[j, k, m] = v * dechirp[m]
                ramp *= step


@_jit
def dechirped_peaks(spec, dt_dec, out):
    """:func:`~.comb_fit.dechirped_peaks_hz` from the FFTs of :func:`channel_tones`' ``zd``.

    Parameters
    ----------
    spec : ndarray of complex64, (C, K, n_fft)
    dt_dec : float
        Segment length [s].
    out : ndarray, (C,)
        Out: each comb's peak frequency [Hz], the parabola's vertex between bins, within +-1 / (2 dt_dec).
    """
    n_c, n_k, n_fft = spec.shape
    p = np.empty(n_fft)
    fs_dec = 1.0 / dt_dec
    for j in range(n_c):
        best, i_best = -np.inf, 0
        for i in range(n_fft):
            s = top = 0.0
            for k in range(n_k):
                v = spec[j, k, i]
                a = float(v.real) * float(v.real) + float(v.imag) * float(v.imag)
                s += a
                top = max(top, a)
            p[i] = s - top if n_k >= 5 else s  # trimmed_tone_sum
            if p[i] > best:
                best, i_best = p[i], i
        pm, p0, pp = p[i_best - 1], p[i_best], p[(i_best + 1) % n_fft]
        den = pm - 2.0 * p0 + pp
        vertex = min(max(0.5 * (pm - pp) / den, -0.5), 0.5) if den != 0.0 else 0.0
        f = (i_best + vertex) / (n_fft * dt_dec)
        out[j] = (f + 0.5 * fs_dec) % fs_dec - 0.5 * fs_dec


@_jit
def comb_segments(tau, offsets_hz, scale_hz, doppler, rate, amp, out):
    """Each comb's tones at the segment centres: ``amp[c, k] exp(j 2 pi (tau off_k + s_k (d_c tau + r_c tau^2 / 2)))``.

    The first step of :func:`~leosop.signal.multicomb._subtract_spectrum` (whose FFT over the
    segments follows). The phase is linear in the tone and, over equally spaced segments,
    quadratic in the segment: each comb's two phasors follow the segments by products, recomputed
    exactly every 64 segments (~1e-14 rad).

    Parameters
    ----------
    tau : (B,)
        Segment centres from the block centre [s], equally spaced.
    offsets_hz, scale_hz : (K,)
        Tone offsets and Doppler scale factors (both linear in the tone).
    doppler, rate : (C,)
    amp : (C, K) complex
    out : ndarray of complex64, (C, K, B)
    """
    n_c, n_k, n_seg = out.shape
    d_off = offsets_hz[1] - offsets_hz[0] if n_k > 1 else 0.0
    d_scale = scale_hz[1] - scale_hz[0] if n_k > 1 else 0.0
    dt = tau[1] - tau[0] if n_seg > 1 else 0.0
    for c in range(n_c):
        # first(b) = tau off_0 + ph s_0 and step(b) = tau d_off + ph d_scale, ph = d tau + r tau^2 / 2:
        # both quadratic in b, so each phasor's ratio between segments changes by a fixed factor.
        for b in range(n_seg):
            if b % 64 == 0:
                t0, t1 = tau[b], tau[b] + dt
                ph0 = doppler[c] * t0 + 0.5 * rate[c] * t0 * t0
                ph1 = doppler[c] * t1 + 0.5 * rate[c] * t1 * t1
                e = _cis(t0 * offsets_hz[0] + ph0 * scale_hz[0])
                z = _cis(t0 * d_off + ph0 * d_scale)
                # Ratios to the next segment, and their change per segment (rate dt^2 in ph).
                e_step = _cis((t1 - t0) * offsets_hz[0] + (ph1 - ph0) * scale_hz[0])
                z_step = _cis((t1 - t0) * d_off + (ph1 - ph0) * d_scale)
                e_curve = _cis(rate[c] * dt * dt * scale_hz[0])
                z_curve = _cis(rate[c] * dt * dt * d_scale)
            v = e
            for k in range(n_k):
                out[c, k, b] = amp[c, k] * v
                v *= z
            e *= e_step
            z *= z_step
            e_step *= e_curve
            z_step *= z_curve


@_jit
def subtract_windows(spectrum, dft, nu0_hz, fs, seg):
    """The second step of :func:`~leosop.signal.multicomb._subtract_spectrum`: each tone's model
    subtracted from the block's FFT over a window of B bins around it, in place, tone after tone.

    Bin b of tone (c, k) loses ``D(nu0 - b df) exp(-j 2 pi b (L - 1) / (2 n)) dft[c, k, b mod B]``,
    D the Dirichlet kernel of a segment of L samples. Along the window both factors rotate by a
    fixed step (recomputed exactly every 64 bins: ~1e-14 rad).

    Parameters
    ----------
    spectrum : ndarray of complex64, (n,)
    dft : ndarray of complex64, (C, K, B)
        FFTs over the segments of :func:`comb_segments`' output.
    nu0_hz : (C, K)
        The tones' frequencies at the middle segment.
    fs : float
    seg : int
        Samples per segment (L).
    """
    n = spectrum.size
    n_c, n_k, n_seg = dft.shape
    df = fs / n
    dx = np.pi / n  # x = pi (nu0 - b df) / fs falls by this per bin
    step_num = _cis(-0.5 * seg * dx / np.pi)
    step_rot = _cis(-(seg - 1) / (2.0 * n))
    for c in range(n_c):
        for k in range(n_k):
            b0 = int(np.rint(nu0_hz[c, k] / df)) - n_seg // 2
            x0 = np.pi * (nu0_hz[c, k] - b0 * df) / fs
            i, q = b0 % n, b0 % n_seg  # the bin and its column of dft
            num = rot = 0j
            for j in range(n_seg):
                x = x0 - j * dx
                if j % 64 == 0:
                    num = _cis(0.5 * seg * x / np.pi)
                    rot = _cis(-(b0 + j) * (seg - 1) / (2.0 * n))
                spectrum[i] -= np.complex64(_dirichlet_of(num.imag, x, seg) * rot * dft[c, k, q])
                num *= step_num
                rot *= step_rot
                i = i + 1 if i + 1 < n else 0
                q = q + 1 if q + 1 < n_seg else 0
