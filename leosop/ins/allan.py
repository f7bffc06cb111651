"""Allan deviation of a static IMU log and the noise terms read off it (IEEE Std 952-1997, annex C).

The overlapping Allan deviation comes from the ``allantools`` package
(Wallin et al.) on the rate samples (``data_type="freq"``), at octave-spaced
averaging times. On a log-log plot each noise has its slope:

* white rate noise (angle / velocity random walk, density ``N``):
  ``sigma(tau) = N / sqrt(tau)``, slope -1/2, read as ``N = sigma(tau) sqrt(tau)``
  averaged (weights 1 / tau) over the averaging times whose local slope is
  within :data:`SLOPE_TOL` of -1/2 (the shortest averaging time when none is);
* bias instability ``B``: the flat floor, ``B = min sigma / 0.664``
  (the flicker-noise constant ``sqrt(2 ln 2 / pi)``). When the least
  deviation is at the longest averaging time the floor is not reached (a
  short log, white noise still falling): ``B`` is then an upper bound
  (``floor_reached`` False).

A log of a still IMU also holds the Earth rate and gravity; they are
constant and do not enter an Allan deviation.
"""

import dataclasses
import math

import numpy as np

__all__ = ["BIAS_INSTABILITY_FACTOR", "SLOPE_TOL", "AllanResult", "allan"]

#: Local log-log slopes within this of -1/2 count as white noise.
SLOPE_TOL = 0.1
#: ``sigma_min = 0.664 B`` for flicker (bias instability) noise: ``sqrt(2 ln 2 / pi)`` (IEEE Std 952, C.1.4).
BIAS_INSTABILITY_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


@dataclasses.dataclass(frozen=True)
class AllanResult:
    """Allan deviation of the three axes of one sensor and its noise terms.

    Attributes
    ----------
    tau_s : ndarray, (k,)
    adev : ndarray, (k, 3)
        Overlapping Allan deviation per axis, in the unit of the samples.
    white_density : ndarray, (3,)
        ``N``: the unit of the samples times sqrt(s) (rad/s/sqrt(Hz) = rad/sqrt(s) for a gyro).
    bias_instability : ndarray, (3,)
        ``B``, in the unit of the samples.
    tau_min_s : ndarray, (3,)
        Where the Allan deviation is least.
    floor_reached : ndarray of bool, (3,)
        False when that is the longest averaging time: ``bias_instability`` is an upper bound.
    """

    tau_s: np.ndarray
    adev: np.ndarray
    white_density: np.ndarray
    bias_instability: np.ndarray
    tau_min_s: np.ndarray
    floor_reached: np.ndarray


def allan(samples, rate_hz, *, points_per_octave=2):
    """Overlapping Allan deviation of rate samples and the white-noise and bias-instability terms.

    Parameters
    ----------
    samples : ndarray, (n, 3)
        Rates (gyro) or specific forces (accelerometer), one row per sample.
    rate_hz : float
        Sample rate.
    points_per_octave : int
        Averaging times per factor of two, from one sample to a tenth of the log.

    Returns
    -------
    AllanResult
    """
    import allantools

    x = np.asarray(samples, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] < 100:
        raise ValueError(f"samples must be (n >= 100, 3), got {x.shape}")
    n = x.shape[0]
    m = np.unique(np.round(2.0 ** np.arange(0, math.log2(n / 10.0), 1.0 / points_per_octave)).astype(int))
    taus_req = m / rate_hz
    out = []
    for k in range(3):
        tau, adev, _, _ = allantools.oadev(x[:, k], rate=rate_hz, data_type="freq", taus=taus_req)
        out.append((tau, adev))
    tau = out[0][0]
    adev = np.stack([a for _, a in out], axis=-1)
    slope = np.gradient(np.log(adev), np.log(tau), axis=0)
    white = np.empty(3)
    for k in range(3):
        sel = np.abs(slope[:, k] + 0.5) < SLOPE_TOL
        # Weights 1 / tau: the estimate at tau averages about n / (tau rate) independent differences.
        white[k] = (np.average((adev[:, k] * np.sqrt(tau))[sel], weights=1.0 / tau[sel]) if sel.any()
                    else adev[0, k] * math.sqrt(tau[0]))
    i_min = np.argmin(adev, axis=0)
    return AllanResult(tau, adev, white, adev[i_min, np.arange(3)] / BIAS_INSTABILITY_FACTOR, tau[i_min],
                       i_min < tau.size - 1)
