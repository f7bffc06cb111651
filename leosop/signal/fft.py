"""FFTs through FFTW (pyfftw) with a small plan cache.

Plans are made with FFTW_ESTIMATE: at N = 3e5 it runs within ~15 % of an
FFTW_MEASURE plan, whose planning takes seconds, and blocks of one size
reuse the same plan. Measured (one thread, N = 3e5 complex64): FFTW 1.2 ms,
scipy.fft 4.7 ms, numpy.fft 12 ms; batches of short zero-padded FFTs (the
Doppler searches, 9 x 1200 points) run 1.7x faster than through scipy.fft.
For the STFT (scipy's ShortTimeFFT, 4096-point frames) routing scipy.fft
through FFTW gained only 2 %, so the STFT keeps scipy's own engine.

Threads: each thread has its own plans (a plan's buffers are filled and
executed in place, so two threads must not share one; a thread's plans go
with it). pyfftw executes without the GIL, so FFTs in different threads run
in parallel (``leosop replay --threads``). FFTW's own threads are not used:
a plan with ``threads=2`` took 3x the wall time of a one-thread plan at
N = 2.5e5 on a 2-core machine under load (10 ms against 3.2 ms), and
replay's second thread has other work.

An input the caller owns that is aligned as the plan's buffers are
(:func:`empty_aligned`) and needs no padding is transformed where it lies,
into a new aligned output (the plan executed on those arrays: the same
codelets, the same bits): no copy in, none out. FFTW's complex transforms
out of place keep their input (``FFTW_PRESERVE_INPUT`` is its default).
"""

import threading
from functools import lru_cache

import numpy as np
import pyfftw

__all__ = ["aligned", "empty_aligned", "fft", "fft_in_place", "ifft"]

#: Each thread's plan cache (``plans``: _new_plan behind its own lru_cache).
_local = threading.local()


def _new_plan(shape, n, dtype_str, inverse, in_place=False):
    buf = pyfftw.empty_aligned(shape, dtype=dtype_str)
    if in_place:
        return pyfftw.FFTW(buf, buf, direction="FFTW_BACKWARD" if inverse else "FFTW_FORWARD",
                           flags=("FFTW_ESTIMATE",), threads=1)
    build = pyfftw.builders.ifft if inverse else pyfftw.builders.fft
    return build(buf, n, threads=1, planner_effort="FFTW_ESTIMATE", avoid_copy=False)


def _plan(shape, n, dtype_str, inverse=False, in_place=False):
    """This thread's plan for ``shape``, ``n``, type, direction and placement (made on first use, 16 kept per
    thread)."""
    plans = getattr(_local, "plans", None)
    if plans is None:
        plans = _local.plans = lru_cache(maxsize=16)(_new_plan)
    return plans(shape, n, dtype_str, inverse, in_place)


def empty_aligned(shape, dtype=np.complex64):
    """An uninitialised array aligned as FFTW's SIMD codelets want (what :func:`fft` takes without a copy)."""
    return pyfftw.empty_aligned(shape, dtype=dtype)


def fft(x, n=None, *, scratch=False):
    """FFT along the last axis of a complex array (complex64 stays complex64).

    ``n`` zero-pads (or truncates) the last axis to ``n`` points. With
    ``scratch=True`` the result is the plan's own output buffer, valid until
    the next FFT of the same shape, ``n`` and type in the same thread (saves
    a copy); otherwise the caller owns a new array. A C-contiguous
    ``x`` from :func:`empty_aligned` of ``n`` points is read where it lies.
    """
    return _transform(x, n, scratch, inverse=False)


def aligned(x):
    """Whether ``x``'s data start where FFTW's SIMD codelets want them (as :func:`empty_aligned`'s)."""
    return pyfftw.is_byte_aligned(x, pyfftw.simd_alignment)


def fft_in_place(x):
    """FFT along the last axis of ``x``, written over it; returns ``x``.

    ``x``: complex64 or complex128, C-contiguous, from :func:`empty_aligned`
    (else ValueError). One buffer instead of two: a block's FFT stays in
    the cache it was written to. Measured at N = 2.5e5 complex64, eight
    blocks in turn as a replay's blocks come: 1.01 ms in place against
    1.25 ms into a second buffer.
    """
    if x.dtype not in (np.complex64, np.complex128) or not x.flags.c_contiguous or not aligned(x):
        raise ValueError("fft_in_place needs a C-contiguous complex array from empty_aligned")
    return _execute_on(_plan(x.shape, x.shape[-1], x.dtype.str, in_place=True), x, x)


def ifft(x):
    """Inverse FFT along the last axis, scaled by 1/n as numpy.fft.ifft (complex64 stays complex64); the caller
    owns the result. A C-contiguous ``x`` from :func:`empty_aligned` is read where it lies."""
    out = _transform(x, None, False, inverse=True)
    return np.multiply(out, 1.0 / out.shape[-1], out=out)


def _transform(x, n, scratch, inverse):
    """:func:`fft` (or, unscaled, :func:`ifft`) of ``x``."""
    x = np.asarray(x)
    dtype = np.complex64 if x.dtype == np.complex64 else np.complex128
    n = int(n or x.shape[-1])
    plan = _plan(x.shape, n, np.dtype(dtype).str, inverse)
    if not scratch and n == x.shape[-1] and x.dtype == dtype and x.flags.c_contiguous \
            and aligned(x):
        return _execute_on(plan, x)
    # Filled and executed directly: the plan's __call__ checks and copies the
    # input again (~0.4 ms of a 1.4 ms FFT at N = 2.5e5).
    buf = plan.input_array
    m = min(n, x.shape[-1])
    buf[..., :m] = x[..., :m]
    if m < n:
        buf[..., m:] = 0
    plan.execute()
    out = plan.output_array
    return out if scratch else out.copy()


def _execute_on(plan, x, out=None):
    """``plan`` executed on ``x`` into ``out`` (default a new aligned array; ``x`` itself for an in-place
    plan); the plan's own buffers restored after."""
    own_in, own_out = plan.input_array, plan.output_array
    if out is None:
        out = pyfftw.empty_aligned(own_out.shape, dtype=own_out.dtype)
    plan.update_arrays(x, out)
    try:
        plan.execute()
    finally:
        plan.update_arrays(own_in, own_out)
    return out
