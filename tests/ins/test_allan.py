"""Allan deviation through allantools against a direct overlapping estimate and the white-noise closed form."""

import math

import numpy as np
import pytest

from leosop.ins import allan

RATE_HZ = 100.0
SIGMA = 0.01  # per-sample standard deviation of the white rate noise


def _direct_oadev(x, rate_hz, m):
    """Overlapping Allan deviation at m samples (IEEE Std 952, C.1): half the mean square of differences
    of adjacent overlapping m-sample averages, from the cumulative sum (the "phase")."""
    phase = np.r_[0.0, np.cumsum(x)] / rate_hz
    tau = m / rate_hz
    d = phase[2 * m:] - 2 * phase[m:-m] + phase[:-2 * m]
    return math.sqrt(np.mean(d**2) / (2 * tau**2))


def test_white_noise_matches_direct_estimate_and_closed_form():
    rng = np.random.default_rng(21)
    x = rng.normal(0.0, SIGMA, (100_000, 3))
    res = allan.allan(x, RATE_HZ)
    # allantools and the direct formula compute the same estimator: equal to rounding.
    for i in (0, 5, 10):
        m = int(round(res.tau_s[i] * RATE_HZ))
        assert res.adev[i, 0] == pytest.approx(_direct_oadev(x[:, 0], RATE_HZ, m), rel=1e-9)
    # White noise of density N = SIGMA / sqrt(rate): sigma^2(tau) = N^2 / tau. The estimate's relative
    # scatter at m samples is at most about 1 / sqrt(n / m) (less when overlapping): up to m = n / 1000 that is
    # 3 %, so 10 % is over 3 sigma.
    N = SIGMA / math.sqrt(RATE_HZ)
    short = res.tau_s * RATE_HZ <= x.shape[0] / 1000
    assert short.sum() >= 10
    assert np.allclose(res.adev[short], N / np.sqrt(res.tau_s[short, None]), rtol=0.10)
    # The read-off white density: within 2 % (averaged over the slope -1/2 region).
    assert np.allclose(res.white_density, N, rtol=0.02)


def test_bias_instability_of_a_random_walk_free_flat_floor():
    # White noise plus a constant bias: the bias drops out, the minimum is at the longest tau.
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, SIGMA, (50_000, 3)) + [1.0, -2.0, 0.5]
    res = allan.allan(x, RATE_HZ)
    assert np.all(res.tau_min_s == res.tau_s[-1])
    assert np.allclose(res.bias_instability * allan.BIAS_INSTABILITY_FACTOR, res.adev[-1])
    # No floor inside the log: the bias instability is flagged as an upper bound.
    assert not res.floor_reached.any()


def test_floor_of_a_rate_random_walk_is_reached_inside_the_log():
    # White noise plus a rate random walk K: sigma^2 = N^2 / tau + K^2 tau / 3 (IEEE Std 952, C.1), least at
    # tau* = sqrt(3) N / K = 1.7 s here, well inside the 50 s longest averaging time of 500 s at 100 Hz.
    rng = np.random.default_rng(7)
    n = 50_000
    N, K = SIGMA / math.sqrt(RATE_HZ), 1e-3
    x = rng.normal(0.0, SIGMA, (n, 3)) + np.cumsum(rng.normal(0.0, K / math.sqrt(RATE_HZ), (n, 3)), axis=0)
    res = allan.allan(x, RATE_HZ)
    assert res.floor_reached.all()
    # The least deviation within a factor 2 of tau* (octave grid, half-octave steps, estimate scatter).
    assert np.all(np.abs(np.log2(res.tau_min_s / (math.sqrt(3.0) * N / K))) <= 1.0)


def test_cli_reads_white_noise_density_and_its_spec_round_trips_into_fuse(tmp_path, capsys):
    """``leosop imu allan`` on a synthetic static log of known densities; its imu_spec.json read by fuse's reader."""
    import json

    from leosop.cli import main
    from leosop.fusion import real

    rng = np.random.default_rng(11)
    n, rate = 60_000, 100.0
    arw_deg_per_rt_h, vrw_ug_per_rt_hz = 0.5, 200.0
    # Per-sample sigma of a white rate of density N at rate f: N sqrt(f).
    gyro_deg_s = rng.normal(0.0, arw_deg_per_rt_h / 60.0 * math.sqrt(rate), (n, 3))
    acc_g = rng.normal(0.0, vrw_ug_per_rt_hz * 1e-6 * math.sqrt(rate), (n, 3)) + [0.0, 0.0, 1.0]
    t = 1.7e9 + np.arange(n) / rate
    path = tmp_path / "static.csv"
    np.savetxt(path, np.column_stack([t, acc_g, gyro_deg_s]), delimiter=",", fmt="%.9f")
    out = tmp_path / "out"
    cols = "t_gpst_s=0,ax_g=1,ay_g=2,az_g=3,gx_deg_per_s=4,gy_deg_per_s=5,gz_deg_per_s=6"
    assert main(["imu", "allan", str(path), "--imu-format", "csv", "--imu-columns", cols, "--json",
                 "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {p.name for p in out.iterdir()} == {"imu_spec.json", "allan.json", "allan.png"}
    # 600 s of white noise: the read-off densities within 5 % (the estimate's scatter over the slope -1/2
    # region is ~1-2 %, test_white_noise_matches_direct_estimate_and_closed_form).
    np.testing.assert_allclose(doc["gyro"]["white_density_deg_per_rt_h"], arw_deg_per_rt_h, rtol=0.05)
    # (ug of the reader's g and of the equator's normal gravity differ by 0.3 %, inside the 5 %.)
    np.testing.assert_allclose(doc["accel"]["white_density_ug_per_rt_hz"], vrw_ug_per_rt_hz, rtol=0.05)
    # 600 s of white noise: the deviation still falls at 60 s, so no floor and B an upper bound.
    assert doc["gyro"]["floor_reached"] == [False] * 3
    spec = real.imu_spec(str(out / "imu_spec.json"))  # what `leosop fuse --imu-spec FILE` calls
    assert spec == real.ImuSpec(**doc["imu_spec"])
    assert spec.gyro_arw_deg_per_rt_h == pytest.approx(max(doc["gyro"]["white_density_deg_per_rt_h"]), rel=1e-12)
