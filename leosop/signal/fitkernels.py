"""Compiled (numba) batched re-estimation of pilot combs; optional.

Imported only when numba is installed (``pip install leosop[fast]``);
:func:`leosop.signal.comb_fit.refine_combs`' numpy path stays the fallback
and the reference. One call of :func:`refine` is that function's numerics
for every comb of a block: the other combs' leakage into its channels
(:func:`~leosop.signal.comb_grid.leakage_all`), two Newton steps on the joint
cost (:func:`~leosop.signal.comb_fit.newton_combs`), the noise, C/N0 and
detection statistic, and the tone amplitudes by least squares on the chirp
model. On a tracking block (80 segments, 7 combs of 9 tones) the numpy path
is a few hundred calls on small arrays, ~0.55 ms, mostly call overhead;
this one takes ~0.2 ms, the call with its arrays ~0.3 ms (one thread).
The phasors are double precision (:func:`_cis`) where numpy's
round the phase to float32 (~1e-7 rad), and the moments are plain loops
rather than BLAS: the two paths differ by that rounding
(tests/signal/test_multicomb.py measures and bounds it). ``nogil``: the comb
search of one thread runs beside the block cleaning of another
(:mod:`leosop.replay.stream`). ``cache=True`` writes the machine code next
to this file (or under ``NUMBA_CACHE_DIR``).
"""

import numba
import numpy as np

__all__ = ["refine"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _cis(cycles):
    """exp(j 2 pi cycles) in double precision, from the phase reduced to [-0.5, 0.5] cycles
    (:func:`~.comb_grid.cis` rounds it to float32: ~1e-7 rad)."""
    x = 2.0 * np.pi * (cycles - np.rint(cycles))
    return complex(np.cos(x), np.sin(x))


@_jit
def _comb_cis(a_cycles, b_cycles, half, out):
    """exp(j 2 pi (a + k b)), k = -half..half, into ``out`` (2 half + 1,): :func:`~.comb_grid.comb_cis`."""
    e0, z = _cis(a_cycles), _cis(b_cycles)
    zc = z.conjugate()
    out[half] = e0
    for k in range(1, half + 1):
        out[half + k] = out[half + k - 1] * z
        out[half - k] = out[half - k + 1] * zc


@_jit
def _dirichlet(delta_hz, count, fs):
    """:func:`~.comb_grid.dirichlet` of one tone and segment, in double precision."""
    x = delta_hz * (np.pi / fs)
    den = x * (1.0 - x * x * (1.0 / 6.0))
    if den == 0.0:
        return count
    return np.sin(x * count) / den


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
    u = np.empty(n_k, dtype=np.complex128)
    m = np.empty((5, n_k), dtype=np.complex128)
    y_sum = np.empty(n_k, dtype=np.complex128)
    resid = np.empty(n_k)
    cn0_k = np.empty(n_k)
    g_col = np.empty((n_seg, n_k), dtype=np.complex128)
    e_col = np.empty((n_seg, n_k), dtype=np.complex128)
    for j in range(n_c):
        f, r = f0[j], r0[j]
        step_f = step_r = 0.0
        live = True
        for _ in range(2):
            m[:] = 0.0
            for b in range(n_seg):
                phase = tau[b] * f + 0.5 * tpow[b, 2] * r
                _comb_cis(-phase, -ratio * phase, half, u)
                for k in range(n_k):
                    v = u[k] * z[b, j, k0 + k]
                    for p in range(5):
                        m[p, k] += tpow[b, p] * v
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
        # Tone amplitudes by least squares on the chirp model.
        for b in range(n_seg):
            phase = tau[b] * dop + 0.5 * tau[b] ** 2 * r
            _comb_cis(phase, spacing_hz * tau[b] + ratio * phase, half, e_col[b])
            for k in range(n_k):
                f_t = offsets_hz[k] + (dop + tau[b] * r) * scale_hz[k]
                nu_out[b, j, k] = f_t
                g_col[b, k] = e_col[b, k] * mix[b, j, k0 + k] * _dirichlet(f_t - f_c[j, k0 + k], counts[b], fs)
        for k in range(n_k):
            num = 0j
            den = 0.0
            for b in range(n_seg):
                g = g_col[b, k]
                num += z[b, j, k0 + k] * g.conjugate()
                den += g.real * g.real + g.imag * g.imag
            amp[j, k] = num / den
        for b in range(n_seg):
            for k in range(n_k):
                val_out[b, j, k] = np.complex64(e_col[b, k] * amp[j, k])
