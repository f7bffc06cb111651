"""Compiled (numba) synthesis of pilot combs from polynomial phases; optional.

Imported only when numba is installed (``pip install leosop[fast]``);
:func:`leosop.signal.pilot.comb_baseband`, summed satellite by satellite in
:meth:`leosop.signal.channel.SiteChannel.samples`, stays the fallback and the
reference. :mod:`leosop.signal.comb_phases` cuts a chunk into segments (its
part within one node interval of the range spline) over which both phases
of :func:`~leosop.signal.pilot.comb_baseband` are, for every satellite,
exact cubics in the sample index j, p(j) = a0 + a1 j + a2 j^2 + a3 j^3 [cycles]: the lead
psi = phi - h theta (carrier, clocks, common phase, minus h = n_tones // 2
times the comb phase) and the comb phase theta (z = exp(j 2 pi theta)).

A cubic phase needs no exponential per sample: exp(j 2 pi p(j + 1)) is
exp(j 2 pi p(j)) times r1(j) = exp(j 2 pi Delta p(j)), r1(j + 1) is
r1(j) r2(j), r2(j + 1) is r2(j) r3 with r3 = exp(j 2 pi 6 a3) constant: three
complex products per phase and sample, then Horner's rule over the tones as
in :func:`~leosop.signal.pilot.comb_baseband`. Every :data:`ANCHOR_SAMPLES`
the four rotations are computed afresh from the polynomial (float64, reduced
to [-0.5, 0.5] cycles). Between anchors each product adds a relative
rounding u ~ 1.1e-16; an error e in r3 reaches z as e K^3 / 6 after K
samples, in r2 as e K^2 / 2, in r1 as e K: at K = 512 the phase error stays
below ~u (K^3/6 + K^2/2 + K) ~ 2.5e-9 rad (measured on |x| of one tone:
2.4e-12), far below the 1e-4 of a tone that would matter beside the thermal
noise. The compiled and numpy samples differ more, by the float64 rounding
of the ~1000 km range (1.2e-10 m, 2.8e-8 rad at 11.3 GHz) that each path
does its own way: measured 4e-7 of a unit tone on 4 satellites x 9 tones
(tests/signal/test_channel.py), 7e-7 on 49 (tools/bench_generate.py).
Each step's work runs over the satellites and :data:`LANES` runs of
:data:`ANCHOR_SAMPLES` side by side in the innermost loops (real and
imaginary parts in separate rows), which the compiler turns into SIMD
instructions: ~4 ns per sample and satellite, 4x less CPU than one
satellite and sample after another with the same operations in the same
order (bit-identical results, measured), and still so with few satellites.
``cache=True`` writes the machine code next to this file (or under
``NUMBA_CACHE_DIR``).
"""

import math

import numba
import numpy as np

__all__ = ["ANCHOR_SAMPLES", "LANES", "add_comb_segments"]

#: Samples between exact evaluations of the rotations (error bound: module docstring).
ANCHOR_SAMPLES = 512
#: Runs of ANCHOR_SAMPLES advanced side by side, so that the vectors stay long with few satellites.
LANES = 8

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _cis(cycles):
    """cos and sin of 2 pi ``cycles`` after reducing it to [-0.5, 0.5]."""
    x = 2.0 * math.pi * (cycles - np.round(cycles))
    return math.cos(x), math.sin(x)


@_jit
def _anchor(a, j, rot, row, s):
    """exp(j 2 pi .) of p(j), Delta p(j), Delta^2 p(j), Delta^3 p into ``rot[row:row + 8, s]`` (re, im pairs),
    for p = a[0] + a[1] j + a[2] j^2 + a[3] j^3."""
    jf = float(j)
    p = a[0] + jf * (a[1] + jf * (a[2] + jf * a[3]))
    d1 = a[1] + a[2] * (2.0 * jf + 1.0) + a[3] * (3.0 * jf * jf + 3.0 * jf + 1.0)
    d2 = 2.0 * a[2] + a[3] * (6.0 * jf + 6.0)
    rot[row, s], rot[row + 1, s] = _cis(p)
    rot[row + 2, s], rot[row + 3, s] = _cis(d1)
    rot[row + 4, s], rot[row + 5, s] = _cis(d2)
    rot[row + 6, s], rot[row + 7, s] = _cis(6.0 * a[3])


@_jit
def add_comb_segments(coef, poly, amp, offset, length, out):
    """Add the combs of every satellite over every segment to ``out``.

    Parameters
    ----------
    coef : ndarray of complex128, (n_tones,)
        Tone amplitude times exp(j phase), lowest tone first.
    poly : ndarray, (n_segments, n_sats, 2, 4)
        Coefficients a0..a3 [cycles] of the lead psi (row 0) and the comb
        phase theta (row 1) in the segment's sample index.
    amp : ndarray, (n_segments, n_sats, 2)
        Tone amplitude at the segment's first sample and its change per sample.
    offset, length : ndarray of int, (n_segments,)
        First sample of each segment in ``out`` and its number of samples.
    out : ndarray of complex128, (n,)
    """
    n_sats, n_coef = poly.shape[1], coef.size
    c_re, c_im = coef.real.copy(), coef.imag.copy()
    width = LANES * n_sats  # vector element v = lane * n_sats + satellite
    rot = np.empty((16, width))  # lead, its three rotations, z, its three: (re, im) rows
    acc_re, acc_im = np.empty(width), np.empty(width)
    for g in range(offset.size):
        for b0 in range(0, length[g], LANES * ANCHOR_SAMPLES):
            n_lanes = min(LANES, (length[g] - b0 + ANCHOR_SAMPLES - 1) // ANCHOR_SAMPLES)
            n_vec = n_lanes * n_sats
            for lane in range(n_lanes):
                for s in range(n_sats):
                    _anchor(poly[g, s, 0], b0 + lane * ANCHOR_SAMPLES, rot, 0, lane * n_sats + s)
                    _anchor(poly[g, s, 1], b0 + lane * ANCHOR_SAMPLES, rot, 8, lane * n_sats + s)
            for step in range(min(ANCHOR_SAMPLES, length[g] - b0)):
                z_re, z_im = rot[8], rot[9]
                acc_re[:n_vec] = c_re[n_coef - 1]
                acc_im[:n_vec] = c_im[n_coef - 1]
                for k in range(n_coef - 2, -1, -1):  # Horner over the tones, each satellite's z
                    ck_re, ck_im = c_re[k], c_im[k]  # (hoisted by hand: the stores below might alias them)
                    for v in range(n_vec):
                        re = acc_re[v] * z_re[v] - acc_im[v] * z_im[v] + ck_re
                        acc_im[v] = acc_re[v] * z_im[v] + acc_im[v] * z_re[v] + ck_im
                        acc_re[v] = re
                for lane in range(n_lanes):
                    j = b0 + lane * ANCHOR_SAMPLES + step
                    if j >= length[g]:
                        break
                    tot_re = tot_im = 0.0
                    for s in range(n_sats):
                        v = lane * n_sats + s
                        m = amp[g, s, 0] + amp[g, s, 1] * j
                        tot_re += m * (rot[0, v] * acc_re[v] - rot[1, v] * acc_im[v])
                        tot_im += m * (rot[0, v] * acc_im[v] + rot[1, v] * acc_re[v])
                    out[offset[g] + j] += complex(tot_re, tot_im)
                for w in range(2):  # phase, Delta, Delta^2 each times the next: one sample on
                    b = 8 * w
                    for v in range(n_vec):
                        r0, i0, r1, i1 = rot[b, v], rot[b + 1, v], rot[b + 2, v], rot[b + 3, v]
                        r2, i2, r3, i3 = rot[b + 4, v], rot[b + 5, v], rot[b + 6, v], rot[b + 7, v]
                        rot[b, v] = r0 * r1 - i0 * i1
                        rot[b + 1, v] = r0 * i1 + i0 * r1
                        rot[b + 2, v] = r1 * r2 - i1 * i2
                        rot[b + 3, v] = r1 * i2 + i1 * r2
                        rot[b + 4, v] = r2 * r3 - i2 * i3
                        rot[b + 5, v] = r2 * i3 + i2 * r3
