"""Compiled (numba) synthesis of pilot combs from polynomial phases; optional.

Imported only when numba is installed (``pip install leosop[fast]``);
:func:`leosop.signal.pilot.comb_baseband`, summed satellite by satellite in
:meth:`leosop.signal.channel.SiteChannel.samples`, stays the fallback and the
reference. :mod:`leosop.signal.comb_phases` cuts a chunk into pieces (one
satellite, one node interval of the range spline) over which both phases of
:func:`~leosop.signal.pilot.comb_baseband` are exact cubics in the sample
index j, p(j) = a0 + a1 j + a2 j^2 + a3 j^3 [cycles]: the lead
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
``cache=True`` writes the machine code next to this file (or under
``NUMBA_CACHE_DIR``).
"""

import math

import numba
import numpy as np

__all__ = ["ANCHOR_SAMPLES", "add_comb_pieces"]

#: Samples between exact evaluations of the rotations (error bound: module docstring).
ANCHOR_SAMPLES = 512

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _cis(cycles):
    """exp(j 2 pi cycles) after reducing ``cycles`` to [-0.5, 0.5]."""
    x = 2.0 * math.pi * (cycles - np.round(cycles))
    return complex(math.cos(x), math.sin(x))


@_jit
def _rotations(a, j):
    """exp(j 2 pi .) of p(j), Delta p(j), Delta^2 p(j), Delta^3 p for p = a[0] + a[1] j + a[2] j^2 + a[3] j^3."""
    jf = float(j)
    p = a[0] + jf * (a[1] + jf * (a[2] + jf * a[3]))
    d1 = a[1] + a[2] * (2.0 * jf + 1.0) + a[3] * (3.0 * jf * jf + 3.0 * jf + 1.0)
    d2 = 2.0 * a[2] + a[3] * (6.0 * jf + 6.0)
    return _cis(p), _cis(d1), _cis(d2), _cis(6.0 * a[3])


@_jit
def add_comb_pieces(coef, poly, amp, offset, length, out):
    """Add the comb of every piece to ``out``.

    Parameters
    ----------
    coef : ndarray of complex128, (n_tones,)
        Tone amplitude times exp(j phase), lowest tone first.
    poly : ndarray, (n_pieces, 2, 4)
        Coefficients a0..a3 [cycles] of the lead psi (row 0) and the comb
        phase theta (row 1) in the piece's sample index.
    amp : ndarray, (n_pieces, 2)
        Tone amplitude at the piece's first sample and its change per sample.
    offset, length : ndarray of int, (n_pieces,)
        First sample of each piece in ``out`` and its number of samples.
    out : ndarray of complex128, (n,)
    """
    n_coef = coef.size
    for p in range(offset.size):
        for j0 in range(0, length[p], ANCHOR_SAMPLES):
            lead, l1, l2, l3 = _rotations(poly[p, 0], j0)
            z, z1, z2, z3 = _rotations(poly[p, 1], j0)
            for j in range(j0, min(j0 + ANCHOR_SAMPLES, length[p])):
                acc = coef[n_coef - 1]
                for k in range(n_coef - 2, -1, -1):
                    acc = acc * z + coef[k]
                out[offset[p] + j] += (amp[p, 0] + amp[p, 1] * j) * (lead * acc)
                lead *= l1
                l1 *= l2
                l2 *= l3
                z *= z1
                z1 *= z2
                z2 *= z3
