"""Cramér-Rao bounds against a numerical Fisher matrix of the signal model."""

import numpy as np
import pytest

from leosop.signal.crlb import crlb_frequency_hz2, crlb_rate_hz2
from leosop.signal.pilot import PilotComb


def _numeric_crlb(n, fs, cn0_dbhz, amplitudes, scale, with_rate, offsets_hz=None):
    """Invert the Fisher matrix 2/sigma^2 Re(J^H J) of the comb model, by central differences.

    Parameters: per tone amplitude and phase, then f and (optionally) r.
    """
    sigma2 = fs / 10 ** (cn0_dbhz / 10)
    tau = (np.arange(n) - (n - 1) / 2) / fs
    k = len(amplitudes)
    offsets = np.zeros(k) if offsets_hz is None else np.asarray(offsets_hz)

    def model(theta):
        a, phi, f = theta[:k], theta[k:2 * k], theta[2 * k]
        r = theta[2 * k + 1] if with_rate else 0.0
        psi = phi[:, None] + 2 * np.pi * (offsets[:, None] * tau + scale[:, None] * (f * tau + 0.5 * r * tau**2))
        return np.sum(a[:, None] * np.exp(1j * psi), axis=0)

    theta0 = np.concatenate([amplitudes, np.zeros(k), [3.0], [100.0] if with_rate else []])
    jac = []
    for i in range(theta0.size):
        h = 1e-6 * max(1.0, abs(theta0[i]))
        d = np.zeros_like(theta0)
        d[i] = h
        jac.append((model(theta0 + d) - model(theta0 - d)) / (2 * h))
    jac = np.array(jac)
    fim = 2.0 / sigma2 * np.real(np.conj(jac) @ jac.T)
    cov = np.linalg.inv(fim)
    return cov[2 * k, 2 * k], (cov[2 * k + 1, 2 * k + 1] if with_rate else None)


@pytest.mark.parametrize("with_rate", [False, True])
def test_single_tone_matches_fisher(with_rate):
    n, fs, cn0 = 400, 1e4, 30.0
    var_f, var_r = _numeric_crlb(n, fs, cn0, np.ones(1), np.ones(1), with_rate)
    # Central differences of a smooth model: ~1e-8 relative; 1e-5 is generous.
    assert crlb_frequency_hz2(cn0, n, fs) == pytest.approx(var_f, rel=1e-5)
    if with_rate:
        assert crlb_rate_hz2(cn0, n, fs) == pytest.approx(var_r, rel=1e-5)


def test_comb_matches_fisher_and_rife_boorstyn():
    comb = PilotComb(carrier_hz=1e6, tone_spacing_hz=5e3, n_tones=3, amplitudes=[0.5, 1.0, 1.5])  # exaggerated s_k
    n, fs, cn0 = 4000, 4e4, 35.0
    var_f, var_r = _numeric_crlb(n, fs, cn0, comb.tone_amplitudes, comb.doppler_scale, True, comb.offsets_hz)
    kw = dict(amplitudes=comb.tone_amplitudes, doppler_scale=comb.doppler_scale)
    # The analytic bound treats tones as independent; tones 500 cycles apart over
    # the block have cross terms of relative size ~1/(2 pi 500)^2 -> 1e-3 is ample.
    assert crlb_frequency_hz2(cn0, n, fs, **kw) == pytest.approx(var_f, rel=1e-3)
    assert crlb_rate_hz2(cn0, n, fs, **kw) == pytest.approx(var_r, rel=1e-3)
    # Rife and Boorstyn (1974) for one tone: (1974): var f >= 6 fs^2 / ((2 pi)^2 SNR N (N^2 - 1)), SNR = C/N0 / fs.
    snr = 10 ** (cn0 / 10) / fs
    assert crlb_frequency_hz2(cn0, n, fs) == pytest.approx(6 * fs**2 / ((2 * np.pi) ** 2 * snr * n * (n**2 - 1)),
                                                          rel=1e-12)
