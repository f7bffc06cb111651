"""What the INS filter of :mod:`leosop.fusion.engine` estimates and assumes: noise, options, optional states.

:class:`EngineSettings` (noise model and filter options), the layout of
the optional sensor-error states after the 15 INS errors
(:func:`state_slices`, :func:`cross_slice`, :func:`initial_covariance`)
and the start of the yaw from the course over ground
(:class:`CourseAlignment`, :func:`course_sigma_rad`).
"""

import dataclasses
import math

import numpy as np

from .common import GATE_PROBABILITY, N_INS

__all__ = ["CROSS_IJ", "CourseAlignment", "EngineSettings", "course_sigma_rad", "cross_slice", "initial_covariance",
           "state_slices"]


@dataclasses.dataclass(frozen=True)
class EngineSettings:
    """Noise model and filter options, in the units the names carry.

    ``gyro_arw_rad_per_rt_s`` and ``accel_vrw_mps_per_rt_s`` are the white
    noise densities of the increments; ``*_bias_rw_*`` the random walks of the
    biases (rad/s/sqrt(s), m/s^2/sqrt(s)). ``step_s`` is the longest interval
    of one covariance propagation. Innovations of gated aids (``aid.gated``)
    beyond the ``gate_probability`` chi-square quantile are rejected, unless
    ``reopen_after`` aids of that kind in a row were (the INS, not the aids,
    is then wrong); with ``reopen_inflates`` the re-opening aid first raises
    the covariance of the INS errors it measures by its innovation squared,
    ``P += H+ diag(z^2) H+^T`` (``H+`` the pseudo-inverse of its INS columns),
    so that it can pull a confidently wrong INS back (the LEO fix's rule).
    ``scale_sigma``: initial sigmas of the gyro and
    accelerometer scale-factor errors (dimensionless; None: no such states);
    ``time_offset_sigma_s`` the initial sigma of the IMU time offset (None: no
    such state, the offset is taken as known) and
    ``time_offset_rw_s_per_rt_s`` its random walk. ``gyro_cross_sigma``:
    initial sigma of the six cross-axis (misalignment) terms of the gyro,
    ``M`` in ``measured = (I + diag(s) + M) true + bias`` with ``M`` zero on
    its diagonal (dimensionless; None: no such states). ``correction_period_s``:
    an aid less than this after the last update is not applied (it still
    names its state blocks), except at the time of that update (all aids of
    one epoch make one correction; 0: every aid). ``record_every``: the result
    holds the start and every ``record_every``-th INS update;
    ``record_cov_ins``: with the covariance of the 15 INS errors.
    """

    gyro_arw_rad_per_rt_s: float
    accel_vrw_mps_per_rt_s: float
    gyro_bias_rw_rad_per_s_per_rt_s: float
    accel_bias_rw_mps2_per_rt_s: float
    step_s: float = 0.1
    gate_probability: float = GATE_PROBABILITY
    reopen_after: int = 8
    reopen_inflates: bool = False
    scale_sigma: tuple | None = None
    time_offset_sigma_s: float | None = None
    time_offset_rw_s_per_rt_s: float = 1e-4
    correction_period_s: float = 0.0
    record_every: int = 1
    record_cov_ins: bool = False
    gyro_cross_sigma: float | None = None

    def noise_psd(self):
        """PSDs of ``[w_gyro_b, w_accel_b]`` (6,), the ``Qc`` of :func:`leosop.ins.error_model.discretize`."""
        return np.r_[np.full(3, self.gyro_arw_rad_per_rt_s**2), np.full(3, self.accel_vrw_mps_per_rt_s**2)]


@dataclasses.dataclass(frozen=True)
class CourseAlignment:
    """Set the yaw from the first GNSS velocity of at least ``min_speed_mps``.

    The yaw's sigma is then that of the course (:func:`course_sigma_rad` of
    the velocity and its covariance) and ``sigma_rad`` in quadrature: how far
    the heading may point off the course (sideslip, wind crab). A car moving
    off has none to speak of (the drive's lateral body velocity, fitted in
    :class:`leosop.fusion.real.FuseOptions`, is nil at zero yaw rate), so 0.
    """

    min_speed_mps: float = 1.0
    sigma_rad: float = 0.0


def course_sigma_rad(vel_enu_mps, cov_enu_m2ps2):
    """Sigma [rad] of the course ``atan2(-v_E, v_N)`` of a velocity (3,) with covariance (3, 3) (first order).

    The course moves by the velocity error across the track over the speed:
    ``J = [-v_N, v_E, 0] / s^2``, variance ``J cov J^T``.
    """
    v = np.asarray(vel_enu_mps, dtype=float)
    J = np.array([-v[1], v[0], 0.0]) / (v[0] ** 2 + v[1] ** 2)
    return math.sqrt(float(J @ np.asarray(cov_enu_m2ps2, dtype=float) @ J))


#: Row and column of the six off-diagonal gyro cross-axis terms, in the order of their states.
CROSS_IJ = (np.array([0, 0, 1, 1, 2, 2]), np.array([1, 2, 0, 2, 0, 1]))


def state_slices(settings):
    """Slices of the optional states in the filter state: ``(SG, SA, TD)``, None for those not estimated."""
    n = N_INS
    SG = SA = TD = None
    if settings.scale_sigma is not None:
        SG, SA, n = slice(n, n + 3), slice(n + 3, n + 6), n + 6
    if settings.time_offset_sigma_s is not None:
        TD = slice(n, n + 1)
    return SG, SA, TD


def cross_slice(settings):
    """Slice of the six gyro cross-axis states (after those of :func:`state_slices`), None when not estimated."""
    if settings.gyro_cross_sigma is None:
        return None
    n = max([N_INS] + [x.stop for x in state_slices(settings) if x is not None])
    return slice(n, n + 6)


def initial_covariance(P0_ins, settings):
    """The full ``P`` from the 15 INS errors' (15, 15) and the sigmas of the optional states of ``settings``."""
    SG, SA, TD = state_slices(settings)
    MG = cross_slice(settings)
    n = max([N_INS] + [x.stop for x in (SG, SA, TD, MG) if x is not None])
    P = np.zeros((n, n))
    P[:N_INS, :N_INS] = P0_ins
    if SG is not None:
        P[SG, SG] = np.eye(3) * settings.scale_sigma[0] ** 2
        P[SA, SA] = np.eye(3) * settings.scale_sigma[1] ** 2
    if TD is not None:
        P[TD, TD] = settings.time_offset_sigma_s**2
    if MG is not None:
        P[MG, MG] = np.eye(6) * settings.gyro_cross_sigma**2
    return P
