"""A block's Doppler status says ``ok`` only when the estimate can be vouched for (issue 20).

References: the closed-form single-tone bound (Rife and Boorstyn 1974), SGP4
orbits of the bundled constellation, and Monte Carlo against the truth of
simulated blocks. Each known wrong-``ok`` case of the issue is rebuilt.
"""

import numpy as np
import pytest

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef
from leosop.signal.channel import doppler_blocks
from leosop.signal.crlb import crlb_frequency_hz2
from leosop.signal.doppler import estimate_block, estimate_blocks
from leosop.signal.pilot import PilotComb
from leosop.signal.quality import (constant_tone_sigma_hz, position_margin_sigma, tone_spread,
                                   zenith_doppler_rate_hz_per_s)

FS = 1e6
BLOCK = 20_000  # 0.02 s, the snapshot length of the bundled recording
CARRIER_HZ = 11.325e9
SPACING_HZ = 43_949.5


def test_rate_bound_covers_the_bundled_constellation():
    # Doppler rate of every satellite above 10 deg over Xi'an for 30 min, from SGP4 states
    # differentiated numerically (1 s steps: the rate changes by < 40 Hz/s^2, error < 1 Hz/s).
    cons = load_constellation()
    times = np.datetime64("2025-01-01T19:40:00", "ns") + np.arange(1800) * np.timedelta64(1, "s")
    pos, vel, status = state_ecef(cons, times)
    rx = np.array(geodetic_to_ecef(np.radians(34.342), np.radians(108.94), 400.0))
    los = pos - rx
    rng = np.linalg.norm(los, axis=-1)
    up = rx / np.linalg.norm(rx)
    elev = np.degrees(np.arcsin(los @ up / rng))
    range_rate = np.sum(los * vel, axis=-1) / rng
    rate = -np.gradient(range_rate, 1.0, axis=1) * CARRIER_HZ / 299_792_458.0
    seen = (elev > 10.0) & (status == 0)
    bound = zenith_doppler_rate_hz_per_s(CARRIER_HZ, 550e3)
    assert bound == pytest.approx(4_140.0, abs=10.0)  # docstring value
    assert np.max(np.abs(rate[seen])) <= bound
    assert np.max(np.abs(rate[seen])) > 0.8 * bound  # some pass comes near the zenith
    assert zenith_doppler_rate_hz_per_s(CARRIER_HZ, 465e3) == pytest.approx(5_000.0, rel=0.01)  # the default bound


def test_constant_tone_sigma_is_the_single_tone_bound_without_a_chirp():
    for cn0 in (30.0, 45.0):
        exact = np.sqrt(crlb_frequency_hz2(cn0, BLOCK, FS))
        # 8192 points stand for 20,000 samples: the sums agree to (1/8192)^2.
        assert constant_tone_sigma_hz(BLOCK, FS, 0.0, cn0) == pytest.approx(exact, rel=1e-6)
    # A chirp of r T^2 = 1 widens the peak (sigma +4 %, checked by Monte Carlo in
    # test_ok_estimates_lie_within_three_sigma); near r T^2 = 5.4 the centre becomes a
    # local minimum of the periodogram (Fresnel ripple of the swept spectrum).
    assert constant_tone_sigma_hz(BLOCK, FS, 2_500.0, 40.0) > constant_tone_sigma_hz(BLOCK, FS, 0.0, 40.0)
    assert np.isfinite(constant_tone_sigma_hz(BLOCK, FS, 13_000.0, 40.0))
    assert constant_tone_sigma_hz(BLOCK, FS, 13_500.0, 40.0) == np.inf


def test_position_margin_and_tone_spread_tables():
    comb = np.full(9, 51.0)  # lambda = 50 per tone: (50) / sqrt(2 + 100) = 4.95 sigma
    clean = np.concatenate([[1.0, 1.0], comb, [1.0, 1.0]])
    assert position_margin_sigma(clean, 9) == pytest.approx(50.0 / np.sqrt(2.0 + 100.0))
    # Another satellite's tone as strong as the comb's just outside it: no margin.
    assert position_margin_sigma(np.concatenate([[1.0, 1.0], comb, [51.0, 1.0]]), 9) == pytest.approx(0.0)
    amp = np.sqrt(comb)
    assert tone_spread(amp, np.ones(9), 1.0, 1e-3) == 0.0
    uneven = amp.copy()
    uneven[:4] *= 2.0  # four tones carry a second comb
    assert tone_spread(uneven, np.ones(9), 1.0, 1e-3) > 1.0


@pytest.mark.parametrize("method", ["fast", "fmlef"])
def test_ok_estimates_lie_within_three_sigma(method):
    # 120 blocks of 0.02 s at 38 dB-Hz per tone, rates up to the LEO bound: the
    # ok estimates' errors over their sigma are unit normal (fraction within 3 sigma
    # 0.9973; at least 0.96 here, a 4-block excess having probability < 1e-3).
    rng = np.random.default_rng(20)
    d = rng.uniform(-2e5, 2e5, 120)
    r = rng.uniform(-4_000.0, 0.0, 120)
    est = estimate_blocks(doppler_blocks(FS, BLOCK, d, r, 38.0, rng=rng), FS, method=method, resolution_hz=0.01)
    ok = est.status == "ok"
    assert ok.mean() > 0.9
    z = (est.doppler_hz - d)[ok] / est.sigma_hz[ok]
    assert np.mean(np.abs(z) < 3.0) >= 0.96
    assert np.all(np.abs(z) < 5.0)
    # C/N0 (fast: mean of nine tones, sd 0.4 dB at 0.02 s; fmlef: the central tone, sd 0.55 dB): within 2.5 dB.
    assert np.all(np.abs(est.cn0_dbhz[ok] - 38.0) < 2.5)


def test_fmlef_from_a_side_tone_is_not_ok():
    # The one-spacing error: the paper's estimator started on tone +1.
    x = doppler_blocks(FS, BLOCK, 12_345.0, -2_600.0, 40.0, rng=np.random.default_rng(1))[0]
    est = estimate_block(x, FS, method="fmlef", coarse_hz=12_345.0 + SPACING_HZ, coarse_error_hz=100.0)
    assert abs(est["doppler_hz"] - 12_345.0 - SPACING_HZ) < 60.0  # it did lock on the side tone
    assert est["status"] == "disagrees with the comb fit"


def test_overlapping_combs_are_not_ok():
    # Two combs one spacing apart and 5 Hz off: their tones coincide but for the edges, and the
    # strongest "comb" mixes both (the 20-satellite case, 13 kHz off, was ok).
    comb = PilotComb()
    rng = np.random.default_rng(2)
    a = doppler_blocks(FS, BLOCK, 50_000.0, -2_600.0, comb=comb)[0]
    b = doppler_blocks(FS, BLOCK, 50_000.0 + SPACING_HZ + 5.0, -2_700.0, comb=comb)[0]
    sigma = np.sqrt(FS / 10 ** 4.0) / np.sqrt(2.0)  # 40 dB-Hz per unit tone
    x = a + 0.8 * b + sigma * (rng.standard_normal(BLOCK) + 1j * rng.standard_normal(BLOCK))
    est = estimate_block(x, FS)
    assert est["detected"] and est["status"] != "ok"


def test_rate_beyond_the_bound_is_not_ok():
    x = doppler_blocks(FS, BLOCK, 12_345.0, -2_600.0, 45.0, rng=np.random.default_rng(3))[0]
    assert estimate_block(x, FS)["status"] == "ok"
    # The same block with a 1 kHz/s bound: Newton still finds -2.6 kHz/s, beyond it.
    assert estimate_block(x, FS, max_rate_hz_per_s=1_000.0)["status"] == "implausible rate"
