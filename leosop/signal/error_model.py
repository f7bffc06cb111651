"""Error model of the Doppler estimators: the standard deviation of a block's estimate from its C/N0."""

import numpy as np

from .crlb import crlb_frequency_hz2
from .pilot import PilotComb

__all__ = ["doppler_sigma_hz"]


def doppler_sigma_hz(cn0_dbhz, block_s, *, comb=None, method="fast", sample_rate_hz=2.5e6):
    """Standard deviation of a block's Doppler estimate [Hz] (error model for measurement-level runs).

    Above threshold the estimators reach the Cramér-Rao bound (validated by
    tools/bench_doppler.py and tests/signal/test_doppler.py): ``fast`` the bound of
    the whole comb, ``ml`` and ``fmlef`` that of the central tone alone.
    Quantisation of ml/fmlef (their resolution / sqrt(12)) is not included.

    Parameters
    ----------
    cn0_dbhz : float or array_like
        C/N0 per unit-amplitude tone [dB-Hz].
    block_s : float or array_like
        Block length [s].

    Returns
    -------
    ndarray, broadcast shape of the inputs
    """
    comb = comb or PilotComb()
    n = np.round(np.asarray(block_s, dtype=float) * sample_rate_hz)
    if method == "fast":
        var = crlb_frequency_hz2(cn0_dbhz, n, sample_rate_hz, amplitudes=comb.tone_amplitudes,
                                 doppler_scale=comb.doppler_scale)
    else:
        a_c = comb.tone_amplitudes[comb.n_tones // 2]
        var = crlb_frequency_hz2(cn0_dbhz, n, sample_rate_hz, amplitudes=[a_c])
    return np.sqrt(var)
