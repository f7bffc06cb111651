"""Doppler estimators: simulate and recover (noise-free and Monte Carlo against the CRLB)."""

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.signal.channel import doppler_blocks
from leosop.signal.crlb import crlb_frequency_hz2
from leosop.signal.doppler import estimate_block, estimate_blocks
from leosop.signal.error_model import doppler_sigma_hz
from leosop.signal.fine import interleaved_matrix, comb_phasors, cubic_bias_hz, fine_fmlef, fine_ml, periodogram_grid
from leosop.signal.pilot import PilotComb

FS = 1e6          # Hz: holds the comb (+-176 kHz) and +-300 kHz of Doppler
N = 100_000       # 0.1 s blocks, the CLI default
NOISE_FREE_HZ = 1e-3  # the noise-free requirement


@pytest.mark.parametrize("doppler_hz, rate", [(12_345.678, 0.0), (-150_000.3, 3_800.0), (201_234.5, -4_200.0),
                                              (43_949.5 * 2 + 3.0, 1_000.0)])
def test_fast_noise_free(doppler_hz, rate):
    x = doppler_blocks(FS, N, doppler_hz, rate)[0]
    est = estimate_block(x, FS)
    assert est["detected"]
    # The last case sits two tone spacings away: a strongest-peak search is
    # ambiguous there; the comb search must still return the central tone.
    assert est["doppler_hz"] == pytest.approx(doppler_hz, abs=NOISE_FREE_HZ)
    # Rate: Newton converges to ~1e-3 Hz/s noise-free (complex64 samples).
    assert est["doppler_rate_hz_per_s"] == pytest.approx(rate, abs=0.05)


def test_fast_rate_change_is_corrected():
    # A LEO rate change of -37 Hz/s^2 biases a (f, r) fit by a T^2 / 40.
    accel, n = -37.0, 1_000_000
    x = doppler_blocks(FS, n, 5_000.0, -2_600.0, doppler_accel_hz_per_s2=accel)[0]
    raw = estimate_block(x, FS)["doppler_hz"]
    # Closed form a T^2 / 40 holds while the cubic phase a T^3 / 48 is << 1 cycle;
    # here it is 0.77 cycle, so only the sign and size are checked (10 %).
    assert raw - 5_000.0 == pytest.approx(accel * (n / FS) ** 2 / 40, rel=0.1)
    short = estimate_block(x[:100_000], FS)["doppler_hz"]  # 0.1 s: 8e-4 cycle, linear regime
    truth_short = 5_000.0 + (-2_600.0) * (-0.45) + accel / 2 * 0.45**2  # its centre is 0.45 s early
    assert short - truth_short == pytest.approx(float(cubic_bias_hz(accel, 100_000, FS)), abs=2e-4)
    fixed = estimate_block(x, FS, doppler_accel_hz_per_s2=accel)["doppler_hz"]
    assert fixed == pytest.approx(5_000.0, abs=NOISE_FREE_HZ)
    assert float(cubic_bias_hz(accel, n, FS)) == pytest.approx(accel / 40 * (n / FS) ** 2, rel=1e-9)


def test_paper_methods_noise_free():
    comb = PilotComb()
    x = doppler_blocks(FS, N, 7_654.3219, 0.0, comb=comb)[0]
    assert fine_fmlef(x, FS, 7_650.0, 1e-4, 1.0) == pytest.approx(7_654.3219, abs=NOISE_FREE_HZ)
    # Grid ML is quantised to its resolution.
    assert fine_ml(x, FS, 7_650.0, 0.01, 10.0) == pytest.approx(7_654.3219, abs=0.005 + 1e-9)
    est = estimate_block(x, FS, method="fmlef", resolution_hz=1e-4)
    assert est["doppler_hz"] == pytest.approx(7_654.3219, abs=NOISE_FREE_HZ)


def test_periodogram_is_eq2():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(500) + 1j * rng.standard_normal(500)
    freqs = 1234.5 + 0.37 * np.arange(7)
    direct = [abs(np.sum(x * np.exp(-2j * np.pi * f * np.arange(500) / FS))) ** 2 / 500 for f in freqs]
    np.testing.assert_allclose(periodogram_grid(x, FS, freqs[0], 0.37, 7), direct, rtol=1e-10)


def _monte_carlo(method, cn0, rate_max, trials, seed, **kw):
    rng = np.random.default_rng(seed)
    d = rng.uniform(-2e5, 2e5, trials)
    r = rng.uniform(-rate_max, rate_max, trials)
    x = doppler_blocks(FS, N, d, r, cn0, rng=rng)
    est = estimate_blocks(x, FS, method=method, **kw)
    assert np.all(est.detected)
    return est, est.doppler_hz - d, est.doppler_rate_hz_per_s - r


@pytest.mark.parametrize("rate_max", [0.0, 4_000.0])
def test_fast_reaches_comb_crlb(rate_max):
    trials = 150
    est, err, _ = _monte_carlo("fast", 40.0, rate_max, trials, seed=10 + int(rate_max))
    bound = doppler_sigma_hz(40.0, N / FS, sample_rate_hz=FS)
    ratio = np.sqrt(np.mean(err**2)) / bound
    # RMSE of 150 Gaussian errors has relative std 1/sqrt(300) = 5.8 %: at the
    # bound the ratio lies in [0.83, 1.17] with 3-sigma confidence.
    assert 0.83 < ratio < 1.17
    # The per-block sigma and C/N0 come from the fit: within 10 % / 0.5 dB.
    assert np.median(est.sigma_hz) == pytest.approx(bound, rel=0.1)
    assert np.median(est.cn0_dbhz) == pytest.approx(40.0, abs=0.5)


def test_fmlef_reaches_single_tone_crlb():
    trials = 60
    _, err, _ = _monte_carlo("fmlef", 40.0, 0.0, trials, seed=3, resolution_hz=1e-3)
    bound = doppler_sigma_hz(40.0, N / FS, method="fmlef", sample_rate_hz=FS)
    # 60 trials: relative std of the RMSE 9 %; 3 sigma -> [0.73, 1.27].
    assert 0.73 < np.sqrt(np.mean(err**2)) / bound < 1.27
    # It uses one tone of nine: its bound is 3x the comb's (equal amplitudes).
    assert bound == pytest.approx(3 * doppler_sigma_hz(40.0, N / FS, sample_rate_hz=FS), rel=1e-4)


def test_error_model_is_crlb():
    comb = PilotComb()
    var = crlb_frequency_hz2(45.0, 250_000, 2.5e6, amplitudes=comb.tone_amplitudes,
                             doppler_scale=comb.doppler_scale)
    assert doppler_sigma_hz(45.0, 0.1) == pytest.approx(np.sqrt(var), rel=1e-12)
    # sigma ~ T^-3/2 and (C/N0)^-1/2 (closed form scaling of the bound).
    assert doppler_sigma_hz(35.0, 0.4) / doppler_sigma_hz(45.0, 0.1) == pytest.approx(np.sqrt(10) / 8, rel=1e-4)


@pytest.mark.parametrize("dtype, rtol", [(np.complex128, 1e-12), (np.complex64, 1e-5)])
def test_decimation_product_matches_direct_sum(dtype, rtol):
    # fast's one full-length pass (phasors by recurrence, a real product on
    # interleaved samples) against the direct sum of x exp(-j 2 pi (a + k b)).
    rng = np.random.default_rng(7)
    # Phases as in a block: up to ~50 cycles per segment (Doppler and tone offsets).
    a, b = rng.uniform(-50.0, 50.0, 500), rng.uniform(-10.0, 10.0, 500)
    mix = comb_phasors(a, b, 4)
    direct = np.exp(-2j * np.pi * (a[:, None] + np.arange(-4, 5) * b[:, None]))
    # Arguments up to ~600 rad carry ~1e-13 rad of rounding; four recurrence
    # products add a few ulps.
    np.testing.assert_allclose(mix, direct, rtol=0, atol=1e-12)
    x = (rng.standard_normal((600, 500)) + 1j * rng.standard_normal((600, 500))).astype(dtype)
    xr = x.view(x.real.dtype)
    y = (xr @ interleaved_matrix(mix, xr.dtype)).view(dtype)
    # Sums of 500 unit terms: rounding of order eps * sqrt(500) relative to
    # the typical |y| ~ sqrt(500) (float32: eps 6e-8; float64: 1e-16).
    np.testing.assert_allclose(y, x.astype(complex) @ direct, rtol=0, atol=rtol * np.sqrt(500))


def test_no_signal_gives_nan():
    rng = np.random.default_rng(5)
    noise = (rng.standard_normal((3, N)) + 1j * rng.standard_normal((3, N))).astype(np.complex64)
    est = estimate_blocks(noise, FS)
    assert not np.any(est.detected)
    assert np.all(np.isnan(est.doppler_hz)) and np.all(np.isnan(est.sigma_hz))


def test_bad_input():
    x = doppler_blocks(FS, 1000, 0.0)[0]
    x[10] = np.nan
    with pytest.raises(InputError, match="NaN"):
        estimate_block(x, FS)
    with pytest.raises(InputError, match="sample_rate_hz"):
        estimate_block(x, 0.0)
    with pytest.raises(InputError, match="method"):
        estimate_block(x, FS, method="music")
    with pytest.raises(InputError, match="does not fit"):
        estimate_block(doppler_blocks(4e5, 4000, 0.0)[0], 4e5)
