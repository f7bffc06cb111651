"""Pilot comb synthesis against a direct per-tone sum, and the noise scale."""

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.signal.pilot import PilotComb, add_noise, comb_baseband, noise_sigma


def _direct(comb, t, g, clock):
    """Second implementation: one complex exponential per tone (eq. 1 at baseband)."""
    out = np.zeros(np.shape(t), dtype=complex)
    for k, a, phi, f_rf in zip(comb.tone_index, comb.tone_amplitudes, comb.tone_phases_rad,
                               comb.carrier_hz + comb.offsets_hz):
        cycles = k * comb.tone_spacing_hz * t + f_rf / comb.carrier_hz * g + clock
        out += a * np.exp(1j * (phi + 2 * np.pi * cycles))
    return out


def test_comb_matches_direct_sum():
    rng = np.random.default_rng(1)
    comb = PilotComb(amplitudes=rng.uniform(0.5, 1.5, 9), phases_rad=rng.uniform(-3, 3, 9))
    t = np.arange(20_000) / 2.5e6
    g = 123_456.7 * t - 0.5 * 3_900.0 * t**2  # Doppler cycles with a LEO rate
    clock = 4.2 * t
    ours = comb_baseband(comb, t, g, clock)
    # Horner products accumulate ~9 roundings of 1e-16 on values of size <= 9.
    np.testing.assert_allclose(ours, _direct(comb, t, g, clock), rtol=0, atol=1e-11)


def test_comb_geometry():
    comb = PilotComb()
    assert comb.tone_index.tolist() == list(range(-4, 5))
    np.testing.assert_allclose(comb.offsets_hz[-1], 4 * 43_949.5)
    # s_k = f_k / f_c exactly (DESIGN 4.2: each tone's Doppler scales with its RF frequency).
    np.testing.assert_allclose(comb.doppler_scale * comb.carrier_hz, comb.carrier_hz + comb.offsets_hz, rtol=1e-15)


@pytest.mark.parametrize("kwargs", [dict(n_tones=8), dict(n_tones=0), dict(amplitudes=[1.0] * 3),
                                    dict(tone_spacing_hz=-1.0)])
def test_bad_comb(kwargs):
    with pytest.raises(InputError):
        PilotComb(**kwargs)


def test_noise_scale_matches_cn0():
    # C/N0 = A^2 / N0 and complex noise variance N0 * fs (pilot.noise_sigma).
    fs, cn0 = 1e6, 40.0
    rng = np.random.default_rng(2)
    noise = add_noise(np.zeros(200_000, dtype=complex), cn0, fs, rng)
    expected = fs / 10 ** (cn0 / 10)
    # Sample variance of 2e5 exponential powers: relative std 0.22 %; 1.5 % is > 6 sigma.
    assert np.mean(np.abs(noise) ** 2) == pytest.approx(expected, rel=0.015)
    assert noise_sigma(cn0, fs) ** 2 == pytest.approx(expected, rel=1e-12)
    # Circular: I and Q carry half each (same 6-sigma margin).
    assert np.var(noise.real) / np.var(noise.imag) == pytest.approx(1.0, rel=0.03)
