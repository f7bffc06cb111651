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

import copy
import dataclasses
import math

import numpy as np
from scipy.signal import lfilter

from ..constants import G0_MPS2
from ..errors import InputError

__all__ = ["ImuErrors", "SHEN2024_TABLE1", "Corruption", "MeasuredIncrements", "corrupt"]

_DEG = math.pi / 180.0
#: Rows of normals drawn at a time when skipping ahead in a generator (bounds memory).
_SKIP_ROWS = 65_536


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
SHEN2024_TABLE1 = ImuErrors.from_quoted(gyro_bias_deg_per_h=0.03, gyro_arw_deg_per_rt_h=0.01, accel_bias_g=1e-4,
                                       accel_vrw_g_per_rt_hz=1e-5)


def _skip_normals(rng, n_rows):
    """Advance ``rng`` past ``n_rows`` rows of 3 standard normals, a block at a time."""
    for k0 in range(0, n_rows, _SKIP_ROWS):
        rng.standard_normal((min(_SKIP_ROWS, n_rows - k0), 3))


class Corruption:
    """:func:`corrupt`'s errors added to ``n`` increments one block after another, drawing the same numbers.

    :func:`corrupt` draws, per sensor (gyro, then accelerometer), the white
    noise of every interval, then with a Gauss-Markov bias its driving
    noise and its start. Here each of those blocks gets its own generator,
    a copy of ``rng`` placed at the block's start, and the Gauss-Markov
    filter and the quantizer carry their state from one block to the next;
    so any division of the ``n`` intervals into consecutive blocks gives
    bit for bit what :func:`corrupt` gives on the whole, while memory stays
    that of a block. ``rng`` is left after all the draws, as :func:`corrupt`
    leaves it.

    Parameters
    ----------
    errors : ImuErrors
    dt_s : float
        Sample interval [s].
    n : int
        Intervals in the whole series.
    rng : numpy.random.Generator
    """

    def __init__(self, errors, dt_s, n, rng):
        if not dt_s > 0:
            raise InputError(f"dt_s={dt_s} must be > 0")
        if not isinstance(rng, np.random.Generator):
            raise InputError("rng must be a numpy.random.Generator")
        e = errors
        self.dt_s, self.n = float(dt_s), int(n)
        self._sensors = []
        for M, bias, noise, sig, tau, q in (
            (e.gyro_scale_misalign, e.gyro_bias_rad_per_s, e.gyro_arw_rad_per_rt_s,
             e.gyro_bias_instability_rad_per_s, e.gyro_bias_corr_time_s, e.gyro_quantum_rad),
            (e.accel_scale_misalign, e.accel_bias_mps2, e.accel_vrw_mps_per_rt_s,
             e.accel_bias_instability_mps2, e.accel_bias_corr_time_s, e.accel_quantum_mps),
        ):
            noise_rng = copy.deepcopy(rng)
            _skip_normals(rng, self.n)
            gm = None
            if np.any(sig > 0):
                a = math.exp(-dt_s / tau)
                gm_rng = copy.deepcopy(rng)
                _skip_normals(rng, self.n)
                gm = (a, sig * math.sqrt(1.0 - a * a), gm_rng, rng.standard_normal(3) * sig)
            self._sensors.append((M, bias, noise * math.sqrt(dt_s), noise_rng, gm, q))
        self.reset()

    def reset(self):
        """Start again at the first interval (the same numbers again)."""
        self.done = 0
        self._rngs = [(copy.deepcopy(s[3]), None if s[4] is None else copy.deepcopy(s[4][2])) for s in self._sensors]
        self._gm_state = [np.zeros((1, 3)) for _ in self._sensors]
        self._sum = [np.zeros((1, 3)) for _ in self._sensors]
        self._total = [np.zeros((1, 3)) for _ in self._sensors]

    def apply(self, dtheta_b_rad, dvel_b_mps):
        """Measured increments of the next ``m`` intervals from their ideal ones, each shape (m, 3)."""
        th = np.asarray(dtheta_b_rad, dtype=float)
        dv = np.asarray(dvel_b_mps, dtype=float)
        if th.ndim != 2 or th.shape[1] != 3 or dv.shape != th.shape:
            raise InputError(f"dtheta_b_rad and dvel_b_mps must both have shape (n, 3), got {th.shape} and "
                             f"{dv.shape}")
        m = th.shape[0]
        if self.done + m > self.n:
            raise InputError(f"{self.done} + {m} intervals: more than the {self.n} this corruption was drawn for")
        out = []
        for i, (x, (M, bias, noise_rt, _, gm, q), (noise_rng, gm_rng)) in enumerate(
                zip((th, dv), self._sensors, self._rngs)):
            y = x + x @ M.T + bias * self.dt_s + noise_rng.standard_normal((m, 3)) * noise_rt
            if gm is not None:
                a, drive, _, start = gm
                w = gm_rng.standard_normal((m, 3)) * drive
                if self.done == 0 and m:
                    w[0] = start
                b, self._gm_state[i] = lfilter([1.0], [1.0, -a], w, axis=0, zi=self._gm_state[i])
                y += b * self.dt_s
            if q != 0.0 and m:
                # Integrating quantizer: multiples of the quantum, the residual carried (also across blocks).
                running = np.cumsum(np.concatenate([self._sum[i], y]), axis=0)[1:]
                total = np.rint(running / q)
                self._sum[i] = running[-1:]
                y = np.diff(np.concatenate([self._total[i], total]), axis=0) * q
                self._total[i] = total[-1:]
            out.append(y)
        self.done += m
        return out[0], out[1]


class MeasuredIncrements:
    """A series of measured increments made on demand, a block at a time: ideal ones from a source, corrupted.

    Only one block is held. :attr:`dtheta_b_rad` and :attr:`dvel_b_mps`
    act as (n, 3) arrays read forward by slices, as the fusion engine's INS
    reads them (:func:`leosop.fusion.engine.run`); reading an earlier
    slice starts the series again (same numbers: the corruption is reset).

    Parameters
    ----------
    ideal : callable
        ``ideal(k0, k1)``: the ideal ``dtheta_b_rad, dvel_b_mps`` of intervals
        ``k0 .. k1 - 1``, each shape (k1 - k0, 3) (e.g.
        :meth:`leosop.ins.trajectory.Flight.increments`).
    corruption : Corruption
        Its ``n`` is the length of the series.
    block : int
        Intervals made at a time.
    """

    def __init__(self, ideal, corruption, block):
        if int(block) != block or block < 1:
            raise InputError(f"block={block} must be a positive integer")
        self.ideal, self.corruption, self.block = ideal, corruption, int(block)
        self.n = corruption.n
        self.dtheta_b_rad, self.dvel_b_mps = _Column(self, 0), _Column(self, 1)
        self._restart()

    def _restart(self):
        self.corruption.reset()
        self._b0 = self._b1 = 0
        self._held = (np.empty((0, 3)), np.empty((0, 3)))

    def read(self, start, stop):
        """Measured ``dtheta_b_rad, dvel_b_mps`` of intervals ``start .. stop - 1``, each (stop - start, 3)."""
        if not 0 <= start <= stop <= self.n:
            raise InputError(f"intervals {start}..{stop}: outside 0..{self.n}")
        if start < self._b0:
            self._restart()
        while self._b1 < stop:
            k1 = min(self._b1 + self.block, self.n)
            new = self.corruption.apply(*self.ideal(self._b1, k1))
            keep = min(max(start, self._b0), self._b1) - self._b0
            self._held = tuple(np.concatenate([h[keep:], x]) for h, x in zip(self._held, new))
            self._b0, self._b1 = self._b0 + keep, k1
        return tuple(h[start - self._b0: stop - self._b0] for h in self._held)

    def blocks(self, stop):
        """The measured increments of intervals ``0 .. stop - 1``, a block (a pair of (m, 3) arrays) at a time."""
        for k0 in range(0, stop, self.block):
            yield self.read(k0, min(k0 + self.block, stop))


class _Column:
    """One of :class:`MeasuredIncrements`' two series, as an (n, 3) array read by forward slices."""

    def __init__(self, source, index):
        self._source, self._index = source, index
        self.shape = (source.n, 3)

    def __getitem__(self, sl):
        if not isinstance(sl, slice) or sl.step not in (None, 1):
            raise TypeError("measured increments are read by contiguous slices only")
        start, stop, _ = sl.indices(self.shape[0])
        return self._source.read(start, max(start, stop))[self._index]


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
    return Corruption(errors, dt_s, th.shape[0] if th.ndim == 2 else 0, rng).apply(th, dvel_b_mps)
