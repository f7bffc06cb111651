"""Cramér-Rao bounds for the frequency (and rate) of tones in white noise.

Model per tone: ``a exp(j psi(t)) + w``, complex white noise of density N0,
``N`` samples at ``fs``, unknown amplitude and phase per tone, a common
frequency ``f`` at the block centre (and optionally a common rate ``r``):
``psi = phi_k + 2 pi s_k (f tau + r tau^2 / 2)`` with ``tau`` centred on the
block. The Fisher information of each tone is ``2 (C/N0)_k / fs`` times the
sums of products of the phase derivatives over the samples (Rife and
Boorstyn 1974 for one tone; Peleg and Porat 1991 for polynomial phase).
Tones are independent, so informations add. Because ``tau`` is centred, the
frequency is decoupled from phase and rate: its bound is the same with or
without an unknown rate; the rate's bound couples with the phase.

Exact finite sums are used: sum tau^2 = N(N^2-1)/12 / fs^2 and
sum tau^4 = N(N^2-1)(3N^2-7)/240 / fs^4.
"""

import numpy as np

__all__ = ["crlb_frequency_hz2", "crlb_rate_hz2", "comb_snr_weights"]


def _sums(n_samples, sample_rate_hz):
    n = np.asarray(n_samples, dtype=float)
    fs = np.asarray(sample_rate_hz, dtype=float)
    s0 = n
    s2 = n * (n**2 - 1.0) / 12.0 / fs**2
    s4 = n * (n**2 - 1.0) * (3.0 * n**2 - 7.0) / 240.0 / fs**4
    return s0, s2, s4


def comb_snr_weights(cn0_dbhz, amplitudes=None, doppler_scale=None):
    """Sum over tones of (C/N0)_k s_k^2 [Hz].

    Parameters
    ----------
    cn0_dbhz : float or array_like
        C/N0 of a unit-amplitude tone [dB-Hz].
    amplitudes : array_like, shape (n_tones,), optional
        Tone amplitudes; default a single unit tone.
    doppler_scale : array_like, shape (n_tones,), optional
        s_k = f_k / f_c; default 1.
    """
    a = np.ones(1) if amplitudes is None else np.asarray(amplitudes, dtype=float)
    s = np.ones_like(a) if doppler_scale is None else np.asarray(doppler_scale, dtype=float)
    cn0 = 10.0 ** (np.asarray(cn0_dbhz, dtype=float) / 10.0)
    return cn0 * np.sum(a**2 * s**2)


def crlb_frequency_hz2(cn0_dbhz, n_samples, sample_rate_hz, *, amplitudes=None, doppler_scale=None):
    """Bound on the variance of the block-centre frequency [Hz^2].

    Valid with or without an unknown common rate (decoupled, see module).
    ``amplitudes=None`` gives the single-tone bound; pass the comb's
    amplitudes (and ``doppler_scale``) for the comb with unknown per-tone
    phases. Broadcasts over ``cn0_dbhz`` and ``n_samples``.
    """
    _, s2, _ = _sums(n_samples, sample_rate_hz)
    w = comb_snr_weights(cn0_dbhz, amplitudes, doppler_scale) / np.asarray(sample_rate_hz, dtype=float)
    return 1.0 / (2.0 * w * (2.0 * np.pi) ** 2 * s2)


def crlb_rate_hz2(cn0_dbhz, n_samples, sample_rate_hz, *, amplitudes=None, doppler_scale=None):
    """Bound on the variance of the common frequency rate [(Hz/s)^2].

    Per tone the (phase, rate) block of the Fisher matrix is
    ``2 snr [[N, pi s S2], [pi s S2, pi^2 s^2 S4]]`` and the phase is a
    nuisance, so the rate's information is ``2 snr pi^2 s^2 (S4 - S2^2/N)``.
    """
    s0, s2, s4 = _sums(n_samples, sample_rate_hz)
    w = comb_snr_weights(cn0_dbhz, amplitudes, doppler_scale) / np.asarray(sample_rate_hz, dtype=float)
    return 1.0 / (2.0 * w * np.pi**2 * (s4 - s2**2 / s0))
