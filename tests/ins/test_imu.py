"""IMU error model: unit conversions and simulate-and-recover statistics."""

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.ins import imu

DEG_PER_H = np.pi / 180.0 / 3600.0


def test_shen2024_table1_in_si():
    e = imu.SHEN2024_TABLE1
    # 0.03 deg/h; 0.01 deg/sqrt(h) = 0.01 * pi/180 / 60 rad/sqrt(s); 1e-4 g; 1e-5 g/sqrt(Hz).
    np.testing.assert_allclose(e.gyro_bias_rad_per_s, 0.03 * DEG_PER_H, rtol=1e-15)
    np.testing.assert_allclose(e.gyro_arw_rad_per_rt_s, 0.01 * np.pi / 180.0 / 60.0, rtol=1e-15)
    np.testing.assert_allclose(e.accel_bias_mps2, 1e-4 * 9.80665, rtol=1e-15)
    np.testing.assert_allclose(e.accel_vrw_mps_per_rt_s, 1e-5 * 9.80665, rtol=1e-15)


def test_biases_and_random_walks_are_recovered():
    e = imu.SHEN2024_TABLE1
    n, dt = 400_000, 0.01
    th, dv = imu.corrupt(np.zeros((n, 3)), np.zeros((n, 3)), dt, e, np.random.default_rng(4))
    for x, bias, density in ((th, e.gyro_bias_rad_per_s, e.gyro_arw_rad_per_rt_s),
                             (dv, e.accel_bias_mps2, e.accel_vrw_mps_per_rt_s)):
        sigma = density * np.sqrt(dt)
        # Sample mean within 5 standard errors; sample std within 5 x 1/sqrt(2n) = 0.56 %.
        np.testing.assert_allclose(x.mean(axis=0) / dt, bias, atol=float(5 * sigma[0] / np.sqrt(n) / dt))
        np.testing.assert_allclose(x.std(axis=0), sigma, rtol=0.0056)


def test_gauss_markov_bias_instability():
    e = imu.ImuErrors.from_quoted(gyro_bias_instability_deg_per_h=10.0, gyro_bias_corr_time_s=1.0)
    n, dt = 400_000, 0.01
    th, _ = imu.corrupt(np.zeros((n, 3)), np.zeros((n, 3)), dt, e, np.random.default_rng(5))
    b = th / dt
    sigma = 10.0 * DEG_PER_H
    # 4000 correlation times: variance estimate std ~ sqrt(2 tau / T) = 2.2 %; 5 sigma = 11 %.
    np.testing.assert_allclose(b.var(axis=0), sigma**2, rtol=0.11)
    lag = 100  # one correlation time: autocorrelation exp(-1)
    rho = np.mean(b[lag:] * b[:-lag], axis=0) / b.var(axis=0)
    np.testing.assert_allclose(rho, np.exp(-1.0), atol=0.05)


def test_scale_factor_and_misalignment_are_exact():
    e = imu.ImuErrors.from_quoted(gyro_scale_factor_ppm=[100.0, -200.0, 300.0],
                                  gyro_misalignment_arcsec=[10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
                                  accel_scale_factor_ppm=500.0)
    x = np.random.default_rng(6).standard_normal((50, 3))
    th, dv = imu.corrupt(x, x, 0.01, e, np.random.default_rng(0))
    arcsec = np.pi / 180 / 3600
    M = np.array([[100e-6, 10 * arcsec, 20 * arcsec], [30 * arcsec, -200e-6, 40 * arcsec],
                  [50 * arcsec, 60 * arcsec, 300e-6]])
    np.testing.assert_allclose(th, x @ (np.eye(3) + M).T, rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(dv, x * (1 + 500e-6), rtol=1e-14)


def test_quantization_carries_the_residual():
    e = imu.ImuErrors.from_quoted(gyro_quantum_arcsec=0.1, accel_quantum_ug_s=125.0)
    x = np.random.default_rng(7).uniform(0, 3e-6, (1000, 3))
    th, dv = imu.corrupt(x, x * 100, 0.01, e, np.random.default_rng(0))
    q = 0.1 * np.pi / 180 / 3600
    counts = th / q
    np.testing.assert_allclose(counts, np.rint(counts), atol=1e-9)
    # Running sums never drift more than half a quantum from the truth.
    assert np.abs(np.cumsum(th, axis=0) - np.cumsum(x, axis=0)).max() <= 0.5 * q * (1 + 1e-9)
    qa = 125e-6 * 9.80665
    assert np.abs(np.cumsum(dv, axis=0) - np.cumsum(x * 100, axis=0)).max() <= 0.5 * qa * (1 + 1e-9)


def test_same_seed_same_noise_and_bad_input():
    x = np.zeros((10, 3))
    a = imu.corrupt(x, x, 0.01, imu.SHEN2024_TABLE1, np.random.default_rng(3))
    b = imu.corrupt(x, x, 0.01, imu.SHEN2024_TABLE1, np.random.default_rng(3))
    np.testing.assert_array_equal(a[0], b[0])
    with pytest.raises(InputError, match="Generator"):
        imu.corrupt(x, x, 0.01, imu.SHEN2024_TABLE1, 3)
    with pytest.raises(InputError, match="shape"):
        imu.corrupt(x[:, :2], x, 0.01, imu.SHEN2024_TABLE1, np.random.default_rng(3))
    with pytest.raises(InputError, match="corr_time"):
        imu.ImuErrors(gyro_bias_corr_time_s=0.0)


def test_corruption_in_blocks_is_identical_to_corrupt_on_the_whole():
    # Every error term on (Gauss-Markov biases, quantization, scale and misalignment): consecutive
    # blocks of any size must reproduce corrupt() bit for bit and leave the generator where it does.
    e = imu.ImuErrors.from_quoted(
        gyro_bias_deg_per_h=1.0, gyro_arw_deg_per_rt_h=0.1, gyro_bias_instability_deg_per_h=0.5,
        gyro_bias_corr_time_s=10.0, gyro_scale_factor_ppm=[100.0, -50.0, 30.0],
        gyro_misalignment_arcsec=[1, 2, 3, 4, 5, 6], gyro_quantum_arcsec=0.1, accel_bias_g=1e-3,
        accel_vrw_g_per_rt_hz=1e-4, accel_bias_instability_g=1e-4, accel_bias_corr_time_s=20.0,
        accel_scale_factor_ppm=40.0, accel_misalignment_arcsec=[3, 1, 2, 6, 5, 4], accel_quantum_ug_s=10.0)
    x = np.random.default_rng(1).standard_normal((1001, 3)) * 1e-3
    rng_whole, rng_blocks = np.random.default_rng(9), np.random.default_rng(9)
    whole = imu.corrupt(x, 10 * x, 0.01, e, rng_whole)
    c = imu.Corruption(e, 0.01, 1001, rng_blocks)
    for _ in range(2):  # and again after reset()
        parts = [c.apply(x[k0:k1], 10 * x[k0:k1]) for k0, k1 in ((0, 1), (1, 8), (8, 500), (500, 1001))]
        assert np.array_equal(whole[0], np.concatenate([p[0] for p in parts]))
        assert np.array_equal(whole[1], np.concatenate([p[1] for p in parts]))
        c.reset()
    assert rng_whole.standard_normal() == rng_blocks.standard_normal()
    with pytest.raises(InputError, match="more than"):
        c.apply(np.zeros((1002, 3)), np.zeros((1002, 3)))
