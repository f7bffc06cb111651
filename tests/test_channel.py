"""Channel: Doppler laws in the samples, and the site geometry against direct SGP4."""

import numpy as np
import pytest

from leosop.constants import C_MPS
from leosop.frames import geodetic_to_ecef, range_rate
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef
from leosop.signal.channel import SiteChannel, doppler_blocks, site_range_rates
from leosop.signal.pilot import PilotComb

FS = 1e6
START = np.datetime64("2025-01-01T19:40:00", "ns")
XIAN = geodetic_to_ecef(np.radians(34.342), np.radians(108.940), 400.0)


def _inst_freq_poly(x, fs, deg):
    """Polynomial fit of the unwrapped phase (cycles) of a single tone, about the block centre."""
    t = (np.arange(x.size) - (x.size - 1) / 2) / fs
    return np.polyfit(t, np.unwrap(np.angle(x)) / (2 * np.pi), deg)


def test_blocks_follow_doppler_law():
    one = PilotComb(n_tones=1)
    x = doppler_blocks(FS, 50_000, [1_234.5, -20_000.0], [3_000.0, -4_000.0], doppler_accel_hz_per_s2=[50.0, 0.0],
                       comb=one, dtype=np.complex128)
    for row, (d, r, a) in zip(x, [(1_234.5, 3_000.0, 50.0), (-20_000.0, -4_000.0, 0.0)]):
        p = _inst_freq_poly(row, FS, 3)  # cycles = a t^3/6 + r t^2/2 + d t + c
        # Noise-free phase: the fit is exact to float rounding (1e-9 relative).
        np.testing.assert_allclose(p[:3], [a / 6, r / 2, d], rtol=1e-7, atol=1e-6)


def test_site_channel_matches_sgp4():
    const = load_constellation().select_ids(["71585", "70524"])
    t_nodes, rr = site_range_rates(const, XIAN, START, 1.0)
    ch = SiteChannel(t_nodes, rr, FS, [45.0, 40.0], [3.0, 7.0])
    t = np.array([0.0137, 0.5003, 0.9871])  # between nodes
    pos, vel, _ = state_ecef(const, START + np.round(t * 1e9).astype("timedelta64[ns]"))
    direct = -range_rate(pos, vel, XIAN) * ch.comb.carrier_hz / C_MPS + np.array([[3.0], [7.0]])
    # Spline of range rate at 0.1 s nodes: interpolation error << 1 mm/s (0.04 Hz) ->
    # 1e-3 Hz is a 40x margin on a smooth LEO pass.
    np.testing.assert_allclose(ch.doppler_hz(t), direct, atol=1e-3)
    # The rate is the spline's derivative: compare with a central difference of SGP4.
    h = 0.05
    p2, v2, _ = state_ecef(const, START + np.round(np.array([0.5 - h, 0.5 + h]) * 1e9).astype("timedelta64[ns]"))
    d2 = -range_rate(p2, v2, XIAN) * ch.comb.carrier_hz / C_MPS
    # Central difference error h^2/6 * jerk (~40 Hz/s^2 -> 0.02 Hz/s): 0.1 Hz/s tolerance.
    np.testing.assert_allclose(ch.doppler_rate_hz_per_s([0.5])[:, 0], (d2[:, 1] - d2[:, 0]) / (2 * h), atol=0.1)


def test_samples_phase_is_integral_of_doppler():
    const = load_constellation().select_ids(["71585"])
    t_nodes, rr = site_range_rates(const, XIAN, START, 0.3)
    ch = SiteChannel(t_nodes, rr, FS, 45.0, 5.0, comb=PilotComb(n_tones=1))
    start, n = 100_000, 100_000
    x = np.concatenate([ch.samples(start, n // 2), ch.samples(start + n // 2, n // 2)])  # chunked
    p = _inst_freq_poly(x, FS, 3)
    t_c = (start + (n - 1) / 2) / FS
    # Noise-free: the phase fit's frequency equals the truth to 1e-6 Hz.
    assert p[2] == pytest.approx(ch.doppler_hz([t_c])[0, 0], abs=1e-6)
    assert 2 * p[1] == pytest.approx(ch.doppler_rate_hz_per_s([t_c])[0, 0], abs=1e-3)


def test_several_satellites_amplitudes():
    const = load_constellation().select_ids(["71585", "70524"])
    t_nodes, rr = site_range_rates(const, XIAN, START, 0.1)
    one = PilotComb(n_tones=1)
    both = SiteChannel(t_nodes, rr, FS, [45.0, 39.0], 0.0, comb=one).samples(0, 1000)
    a = SiteChannel(t_nodes, rr[:1], FS, 45.0, 0.0, comb=one).samples(0, 1000)
    b = SiteChannel(t_nodes, rr[1:], FS, 45.0, 0.0, comb=one).samples(0, 1000)
    # Sum with the weaker satellite 6 dB down (amplitude 10^(-6/20)).
    np.testing.assert_allclose(both, a + 10 ** (-6 / 20) * b, atol=1e-9)
