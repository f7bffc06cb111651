"""IMU error model: what a real gyro and accelerometer triad add to ideal increments.

Per sample interval ``dt`` the measured increments are

    dtheta~ = (I + M_g) dtheta + (b_g + m_g(t)) dt + n_g,
    dv~     = (I + M_a) dv     + (b_a + m_a(t)) dt + n_a,

with ``M`` the scale-factor (diagonal) and misalignment (off-diagonal)
matrix, ``b`` a constant bias, ``m`` a first-order Gauss-Markov bias
(bias instability ``sigma``, correlation time ``tau``, stationary start),
and ``n`` white increments of standard deviation ``arw * sqrt(dt)`` (angle
random walk) or ``vrw * sqrt(dt)`` (velocity random walk); finally optional
quantization to a quantum with the residual carried over, as an integrating
IMU does. :class:`ImuErrors` holds everything in SI;
:meth:`ImuErrors.from_quoted` takes the units of data sheets and papers.
"""

import dataclasses
import math

import numpy as np
from scipy.signal import lfilter

from ..constants import G0_MPS2
from ..errors import InputError

__all__ = ["ImuErrors", "SEED004_TABLE1", "corrupt"]

_DEG = math.pi / 180.0


def _vec(x, name):
    v = np.broadcast_to(np.asarray(x, dtype=float), (3,)).copy()
    if not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be finite, got {x}")
    return v


def _scale_misalign(scale_ppm, misalign_arcsec):
    """``M`` from per-axis scale factors [ppm] and a (3, 3) or 6-term misalignment [arcsec]."""
    M = np.diag(_vec(scale_ppm, "scale_factor_ppm") * 1e-6)
    mis = np.asarray(misalign_arcsec, dtype=float) * (_DEG / 3600.0)
    if mis.shape == (3, 3):
        M += mis - np.diag(np.diag(mis))
    elif mis.shape == (6,):  # [xy, xz, yx, yz, zx, zy]
        M[[0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]] += mis
    elif mis.shape != ():
        raise InputError(f"misalignment_arcsec must be a scalar 0, 6 terms or a (3, 3) matrix, got {mis.shape}")
    elif mis != 0.0:
        raise InputError("misalignment_arcsec as a scalar must be 0; give 6 terms or a (3, 3) matrix")
    return M


@dataclasses.dataclass(frozen=True)
class ImuErrors:
    """IMU error parameters in SI units (all default to zero: an ideal IMU).

    Attributes
    ----------
    gyro_bias_rad_per_s, accel_bias_mps2 : ndarray, shape (3,)
        Constant biases.
    gyro_arw_rad_per_rt_s, accel_vrw_mps_per_rt_s : ndarray, shape (3,)
        White-noise densities (angle / velocity random walk).
    gyro_bias_instability_rad_per_s, accel_bias_instability_mps2 : ndarray, shape (3,)
        Standard deviation of the Gauss-Markov biases.
    gyro_bias_corr_time_s, accel_bias_corr_time_s : float
        Their correlation times.
    gyro_scale_misalign, accel_scale_misalign : ndarray, shape (3, 3)
        ``M``: scale-factor errors on the diagonal, misalignments off it.
    gyro_quantum_rad, accel_quantum_mps : float
        Output quanta; 0 for no quantization.
    """

    gyro_bias_rad_per_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    gyro_arw_rad_per_rt_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    gyro_bias_instability_rad_per_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    gyro_bias_corr_time_s: float = 3600.0
    gyro_scale_misalign: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((3, 3)))
    gyro_quantum_rad: float = 0.0
    accel_bias_mps2: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    accel_vrw_mps_per_rt_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    accel_bias_instability_mps2: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    accel_bias_corr_time_s: float = 3600.0
    accel_scale_misalign: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((3, 3)))
    accel_quantum_mps: float = 0.0

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = np.asarray(getattr(self, f.name), dtype=float)
            if f.name.endswith("scale_misalign"):
                v = np.broadcast_to(v, (3, 3)).copy()
            elif f.type is np.ndarray:
                v = _vec(v, f.name)
            elif v.shape != () or not np.isfinite(v) or v < 0:
                raise InputError(f"{f.name}={v} must be a finite number >= 0")
            else:
                v = float(v)
            if f.name.endswith("corr_time_s") and not v > 0:
                raise InputError(f"{f.name}={v} must be > 0")
            object.__setattr__(self, f.name, v)

    @classmethod
    def from_quoted(cls, *, gyro_bias_deg_per_h=0.0, gyro_arw_deg_per_rt_h=0.0,
                    gyro_bias_instability_deg_per_h=0.0, gyro_bias_corr_time_s=3600.0, gyro_scale_factor_ppm=0.0,
                    gyro_misalignment_arcsec=0.0, gyro_quantum_arcsec=0.0, accel_bias_g=0.0,
                    accel_vrw_g_per_rt_hz=0.0, accel_bias_instability_g=0.0, accel_bias_corr_time_s=3600.0,
                    accel_scale_factor_ppm=0.0, accel_misalignment_arcsec=0.0, accel_quantum_ug_s=0.0):
        """Errors in the units people quote.

        Biases in deg/h and g (per axis or one value for all three), random
        walks in deg/sqrt(h) and g/sqrt(Hz), scale factors in ppm,
        misalignments in arcsec (6 terms ``[xy, xz, yx, yz, zx, zy]`` or a
        (3, 3) matrix), quanta in arcsec and ug*s (the PSINS units).
        """
        return cls(
            gyro_bias_rad_per_s=_vec(gyro_bias_deg_per_h, "gyro_bias_deg_per_h") * (_DEG / 3600.0),
            gyro_arw_rad_per_rt_s=_vec(gyro_arw_deg_per_rt_h, "gyro_arw_deg_per_rt_h") * (_DEG / 60.0),
            gyro_bias_instability_rad_per_s=_vec(gyro_bias_instability_deg_per_h, "gyro_bias_instability_deg_per_h")
            * (_DEG / 3600.0),
            gyro_bias_corr_time_s=gyro_bias_corr_time_s,
            gyro_scale_misalign=_scale_misalign(gyro_scale_factor_ppm, gyro_misalignment_arcsec),
            gyro_quantum_rad=float(gyro_quantum_arcsec) * _DEG / 3600.0,
            accel_bias_mps2=_vec(accel_bias_g, "accel_bias_g") * G0_MPS2,
            accel_vrw_mps_per_rt_s=_vec(accel_vrw_g_per_rt_hz, "accel_vrw_g_per_rt_hz") * G0_MPS2,
            accel_bias_instability_mps2=_vec(accel_bias_instability_g, "accel_bias_instability_g") * G0_MPS2,
            accel_bias_corr_time_s=accel_bias_corr_time_s,
            accel_scale_misalign=_scale_misalign(accel_scale_factor_ppm, accel_misalignment_arcsec),
            accel_quantum_mps=float(accel_quantum_ug_s) * 1e-6 * G0_MPS2,
        )


#: [Shen 2024] Table 1: gyro constant drift 0.03 deg/h, gyro random walk
#: 0.01 deg/sqrt(h), accelerometer constant bias 1e-4 g, accelerometer random
#: walk 1e-5 g/sqrt(Hz), on every axis.
SEED004_TABLE1 = ImuErrors.from_quoted(gyro_bias_deg_per_h=0.03, gyro_arw_deg_per_rt_h=0.01, accel_bias_g=1e-4,
                                       accel_vrw_g_per_rt_hz=1e-5)


def _gauss_markov(n, dt_s, sigma, tau_s, rng):
    """Stationary first-order Gauss-Markov sequences, shape (n, 3)."""
    a = math.exp(-dt_s / tau_s)
    w = rng.standard_normal((n, 3)) * (sigma * math.sqrt(1.0 - a * a))
    w[0] = rng.standard_normal(3) * sigma
    return lfilter([1.0], [1.0, -a], w, axis=0)


def _quantize(x, quantum):
    """Integrating quantizer: output multiples of the quantum, carrying the residual."""
    if quantum == 0.0:
        return x
    total = np.rint(np.cumsum(x, axis=0) / quantum)
    return np.diff(total, axis=0, prepend=np.zeros((1, 3))) * quantum


def corrupt(dtheta_b_rad, dvel_b_mps, dt_s, errors, rng):
    """Add IMU errors to ideal increments.

    Parameters
    ----------
    dtheta_b_rad, dvel_b_mps : array_like, shape (n, 3)
        Ideal increments (e.g. :attr:`Trajectory.dtheta_b_rad`).
    dt_s : float
        Sample interval [s].
    errors : ImuErrors
    rng : numpy.random.Generator
        The only source of randomness.

    Returns
    -------
    dtheta_b_rad, dvel_b_mps : ndarray, shape (n, 3)
    """
    th = np.asarray(dtheta_b_rad, dtype=float)
    dv = np.asarray(dvel_b_mps, dtype=float)
    if th.ndim != 2 or th.shape[1] != 3 or dv.shape != th.shape:
        raise InputError(f"dtheta_b_rad and dvel_b_mps must both have shape (n, 3), got {th.shape} and {dv.shape}")
    if not dt_s > 0:
        raise InputError(f"dt_s={dt_s} must be > 0")
    if not isinstance(rng, np.random.Generator):
        raise InputError("rng must be a numpy.random.Generator")
    e = errors
    n = th.shape[0]
    rt = math.sqrt(dt_s)
    out = []
    for x, M, bias, noise, sig, tau, q in (
        (th, e.gyro_scale_misalign, e.gyro_bias_rad_per_s, e.gyro_arw_rad_per_rt_s,
         e.gyro_bias_instability_rad_per_s, e.gyro_bias_corr_time_s, e.gyro_quantum_rad),
        (dv, e.accel_scale_misalign, e.accel_bias_mps2, e.accel_vrw_mps_per_rt_s,
         e.accel_bias_instability_mps2, e.accel_bias_corr_time_s, e.accel_quantum_mps),
    ):
        y = x + x @ M.T + bias * dt_s + rng.standard_normal((n, 3)) * (noise * rt)
        if np.any(sig > 0):
            y += _gauss_markov(n, dt_s, sig, tau, rng) * dt_s
        out.append(_quantize(y, q))
    return out[0], out[1]
