"""What :func:`leosop.fusion.engine.run` keeps of its filter: :class:`EngineResult`, filled by :class:`Recorder`."""

import dataclasses

import numpy as np

from ..ins.error_model import DPOS, DV
from .common import N_INS, pos_jacobian

__all__ = ["EngineResult", "Recorder"]


@dataclasses.dataclass(frozen=True)
class EngineResult:
    """The filter's INS after the INS updates (n epochs: the start and one per ``record_every`` pairs of samples).

    Attributes
    ----------
    t_s : ndarray, (n,)
        On the IMU's clock.
    lat_rad, lon_rad, alt_m : ndarray, (n,)
    vel_enu_mps : ndarray, (n, 3)
    q_n_b : ndarray, (n, 4)
        Attitude (scalar-first quaternion of ``C_n_b``).
    sigma : ndarray, (n, n_x)
        Square roots of the diagonal of ``P``: the 15 INS errors (position in
        rad, rad, m), then the optional states of
        :class:`leosop.fusion.engine.EngineSettings` in their order (scale
        factors, time offset).
    cov_pos_enu_m2, cov_vel_enu_m2ps2 : ndarray, (n, 3, 3)
        Position and velocity error covariances in ENU.
    gyro_bias_rad_per_s, accel_bias_mps2 : ndarray, (n, 3)
    gyro_scale, accel_scale : ndarray, (n, 3)
        Scale-factor estimates (zero without those states).
    time_offset_s : ndarray, (n,)
        IMU time offset estimate (the initial value without that state).
    omega_ib_b_rad_per_s : ndarray, (n, 3)
        Bias-corrected body rate of each update.
    aids : dict of str to [int, int]
        Per kind of aid: used, rejected by the gate.
    yaw_aligned_s : float or None
        When the yaw was set from the course (None: never, or not asked).
    nll : dict of str to float
        Per kind of aid: the negative log-likelihood of its used innovations,
        ``sum 0.5 (z^T S^-1 z + ln det(2 pi S))`` (compares runs on the same aids).
    states : dict of str to (ndarray, ndarray)
        The aids' state blocks alive at the end: estimate and sigma, by key.
    cov_ins : ndarray, (n, 15, 15), or None
        Covariance of the INS errors (position in rad, rad, m), when
        ``settings.record_cov_ins`` asks for it (the ENU blocks above are its
        position and velocity blocks, in metres).
    """

    t_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    alt_m: np.ndarray
    vel_enu_mps: np.ndarray
    q_n_b: np.ndarray
    sigma: np.ndarray
    cov_pos_enu_m2: np.ndarray
    cov_vel_enu_m2ps2: np.ndarray
    gyro_bias_rad_per_s: np.ndarray
    accel_bias_mps2: np.ndarray
    gyro_scale: np.ndarray
    accel_scale: np.ndarray
    time_offset_s: np.ndarray
    omega_ib_b_rad_per_s: np.ndarray
    aids: dict
    yaw_aligned_s: float | None
    nll: dict
    states: dict = dataclasses.field(default_factory=dict)
    cov_ins: np.ndarray | None = None


class Recorder:
    """The arrays of an :class:`EngineResult`, filled epoch by epoch from the running filter.

    Parameters
    ----------
    n : int
        Epochs to record.
    n_core : int
        The INS errors and the optional states (the columns of ``sigma``).
    cov_ins : bool
        Keep the (15, 15) covariance of the INS errors too.
    """

    def __init__(self, n, n_core, cov_ins):
        self.n_core = n_core
        self.pos, self.vel, self.q = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4))
        self.sigma = np.empty((n, n_core))
        self.cov_pos, self.cov_vel = np.empty((n, 3, 3)), np.empty((n, 3, 3))
        self.bg, self.ba, self.sg, self.sa = (np.empty((n, 3)) for _ in range(4))
        self.td, self.omega = np.empty(n), np.empty((n, 3))
        self.cov_ins = np.empty((n, N_INS, N_INS)) if cov_ins else None

    def record(self, k, f):
        """Keep epoch ``k`` of the engine's running filter ``f``: its INS, ``P`` and sensor estimates."""
        s, P = f.state, f.P
        self.pos[k] = (s.lat_rad, s.lon_rad, s.alt_m)
        self.vel[k], self.q[k] = s.vel_enu_mps, s.q_n_b
        self.sigma[k] = np.sqrt(np.diagonal(P)[:self.n_core])
        J = pos_jacobian(s.lat_rad, s.alt_m)
        self.cov_pos[k] = J @ P[DPOS, DPOS] @ J.T
        self.cov_vel[k] = P[DV, DV]
        self.bg[k], self.ba[k], self.sg[k], self.sa[k] = f.bg, f.ba, f.sg, f.sa
        self.td[k], self.omega[k] = f.td, f.omega
        if self.cov_ins is not None:
            self.cov_ins[k] = P[:N_INS, :N_INS]

    def result(self, t_s, f, yaw_aligned_s):
        """The :class:`EngineResult` at the times ``t_s`` (n,), with the counters and blocks of ``f`` at the end."""
        return EngineResult(t_s, self.pos[:, 0], self.pos[:, 1], self.pos[:, 2], self.vel, self.q, self.sigma,
                            self.cov_pos, self.cov_vel, self.bg, self.ba, self.sg, self.sa, self.td, self.omega,
                            {k: tuple(v) for k, v in f.counts.items()}, yaw_aligned_s, dict(f.nll),
                            f.blocks.summary(f.P), self.cov_ins)
