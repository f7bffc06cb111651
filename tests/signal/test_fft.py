"""FFTW wrapper against numpy.fft (an independent FFT implementation)."""

import numpy as np
import pytest

from leosop.signal.fft import empty_aligned, fft, ifft


@pytest.mark.parametrize("dtype, rtol", [(np.complex64, 1e-5), (np.complex128, 1e-12)])
def test_fft_matches_numpy(dtype, rtol):
    rng = np.random.default_rng(3)
    x = (rng.standard_normal(3000) + 1j * rng.standard_normal(3000)).astype(dtype)
    out = fft(x)
    assert out.dtype == dtype
    # Errors grow ~ eps * log2(n) relative to the largest bin (float32 eps 6e-8,
    # float64 1e-16; log2(3000) ~ 12): the tolerances leave a margin of ~10.
    scale = np.abs(np.fft.fft(x.astype(complex))).max()
    np.testing.assert_allclose(out, np.fft.fft(x.astype(complex)), rtol=0, atol=rtol * scale)


def test_batched_zero_padded_fft_matches_numpy():
    # The Doppler searches: (K, B) tones, zero-padded to 2B along the last axis.
    rng = np.random.default_rng(4)
    y = (rng.standard_normal((9, 600)) + 1j * rng.standard_normal((9, 600))).astype(np.complex64)
    ref = np.fft.fft(y.astype(complex), 1200, axis=-1)
    out = fft(y, 1200, scratch=True)
    assert out.shape == (9, 1200)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-5 * np.abs(ref).max())  # float32, as above
    # A second call with other data reuses the plan and its buffers.
    y2 = y[:, ::-1].copy()
    np.testing.assert_allclose(fft(y2, 1200), np.fft.fft(y2.astype(complex), 1200, axis=-1), rtol=0,
                               atol=1e-5 * np.abs(ref).max())


@pytest.mark.parametrize("dtype, rtol", [(np.complex64, 1e-5), (np.complex128, 1e-12)])
def test_ifft_matches_numpy(dtype, rtol):
    rng = np.random.default_rng(5)
    x = (rng.standard_normal(2500) + 1j * rng.standard_normal(2500)).astype(dtype)
    out = ifft(x)
    ref = np.fft.ifft(x.astype(complex))
    assert out.dtype == dtype
    np.testing.assert_allclose(out, ref, rtol=0, atol=rtol * np.abs(ref).max())  # as the forward FFT's
    np.testing.assert_allclose(ifft(fft(x)), x, rtol=0, atol=rtol * np.abs(x).max())  # a round trip


def test_aligned_input_is_read_where_it_lies():
    """An aligned input is transformed without a copy: by the same plan, so to the bit as through the plan's
    buffer; the input kept (FFTW keeps it out of place); the result the caller's (a later FFT leaves it)."""
    rng = np.random.default_rng(6)
    x = (rng.standard_normal(25_000) + 1j * rng.standard_normal(25_000)).astype(np.complex64)
    a = empty_aligned(x.size)
    a[:] = x
    through_buffer = fft(x[::-1].copy()[::-1])  # a copy of x that is not aligned the same way: copied in
    got = fft(a)
    assert np.array_equal(got, through_buffer) and np.array_equal(a, x)
    fft(a[::-1].copy())
    assert np.array_equal(got, through_buffer)


@pytest.mark.parametrize("dtype, rtol", [(np.complex64, 1e-5), (np.complex128, 1e-12)])
def test_fft_in_place_matches_numpy(dtype, rtol):
    """fft_in_place writes the FFT over its aligned input (the tolerances as above); other inputs refused."""
    from leosop.signal.fft import fft_in_place

    rng = np.random.default_rng(5)
    x = empty_aligned(3000, dtype=dtype)
    x[:] = rng.standard_normal(3000) + 1j * rng.standard_normal(3000)
    ref = np.fft.fft(x.astype(complex))
    assert fft_in_place(x) is x
    np.testing.assert_allclose(x, ref, rtol=0, atol=rtol * np.abs(ref).max())
    with pytest.raises(ValueError, match="empty_aligned"):
        fft_in_place(np.zeros(10))  # real
    with pytest.raises(ValueError, match="empty_aligned"):
        fft_in_place(empty_aligned(20)[::2])  # not contiguous
