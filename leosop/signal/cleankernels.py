"""Compiled (numba) passes over a block's samples for :mod:`leosop.signal.cleaning`; optional.

Imported only when numba is installed (``pip install leosop[fast]``); the
numpy code of :mod:`leosop.signal.cleaning` stays the fallback and the
reference. Each kernel fuses what numpy does in several passes (and
temporaries) into one pass over the samples:

* :func:`centre_moments` -- the block less its DC (the float32 subtraction
  of numpy, bit for bit) and the second moments ``sum I^2, Q^2, I Q`` of
  the result, accumulated in float64 (four partial sums each, so that the
  additions pipeline); the numpy path sums the same float64 products with
  BLAS, in another order: the two agree to ~1e-15 relative;
* :func:`correct_iq` -- :func:`leosop.signal.cleaning.correct_iq`'s
  float64 operations in numpy's order (no fast-math, so no fused
  multiply-adds), rounded to complex64 as ``astype`` does, in place:
  bit-identical, without numpy's four float64 temporaries.

``cache=True``: the machine code is kept under ``__pycache__`` (or
``NUMBA_CACHE_DIR``), so only the first run after an install compiles.
"""

import numba
import numpy as np

__all__ = ["centre_moments", "correct_iq"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def centre_moments(x, dc, out):
    """``out[:] = x - dc`` and the float64 sums of I^2, Q^2 and I Q of ``out``.

    Parameters
    ----------
    x, out : ndarray of complex64, (n,)
        ``out`` may be ``x``.
    dc : complex64

    Returns
    -------
    sum_ii, sum_qq, sum_iq : float
    """
    dc_i, dc_q = dc.real, dc.imag
    ii0 = ii1 = ii2 = ii3 = qq0 = qq1 = qq2 = qq3 = iq0 = iq1 = iq2 = iq3 = 0.0
    n = x.size
    whole = n - n % 4
    for k in range(0, whole, 4):
        i0, q0 = x[k].real - dc_i, x[k].imag - dc_q
        i1, q1 = x[k + 1].real - dc_i, x[k + 1].imag - dc_q
        i2, q2 = x[k + 2].real - dc_i, x[k + 2].imag - dc_q
        i3, q3 = x[k + 3].real - dc_i, x[k + 3].imag - dc_q
        out[k], out[k + 1], out[k + 2], out[k + 3] = complex(i0, q0), complex(i1, q1), complex(i2, q2), complex(i3, q3)
        i0, q0, i1, q1 = np.float64(i0), np.float64(q0), np.float64(i1), np.float64(q1)
        i2, q2, i3, q3 = np.float64(i2), np.float64(q2), np.float64(i3), np.float64(q3)
        ii0 += i0 * i0
        ii1 += i1 * i1
        ii2 += i2 * i2
        ii3 += i3 * i3
        qq0 += q0 * q0
        qq1 += q1 * q1
        qq2 += q2 * q2
        qq3 += q3 * q3
        iq0 += i0 * q0
        iq1 += i1 * q1
        iq2 += i2 * q2
        iq3 += i3 * q3
    for k in range(whole, n):
        i0, q0 = x[k].real - dc_i, x[k].imag - dc_q
        out[k] = complex(i0, q0)
        i0, q0 = np.float64(i0), np.float64(q0)
        ii0 += i0 * i0
        qq0 += q0 * q0
        iq0 += i0 * q0
    return (ii0 + ii1) + (ii2 + ii3), (qq0 + qq1) + (qq2 + qq3), (iq0 + iq1) + (iq2 + iq3)


@_jit
def correct_iq(x, g, sin_phi, cos_phi):
    """``Q = (Q' / g + I sin phi) / cos phi`` in float64, rounded to float32, I kept; in place in ``x``,
    complex64 (n,) (one array, so that the loop vectorises: written through a second array that may be the
    same, it took 4x as long)."""
    for k in range(x.size):
        z = x[k]
        q = (np.float64(z.imag) / g + np.float64(z.real) * sin_phi) / cos_phi
        x[k] = complex(z.real, np.float32(q))
