"""What the fusion filters share: tuning, output, the INS-error conventions and constants.

:class:`FilterSettings` (priors and noise of the 15 INS errors of
:mod:`leosop.ins.error_model`) with :func:`initial_covariance`, the output
:class:`FusionResult` of simulate's loose (:func:`leosop.fusion.aids_fix.fuse`)
and tight (:mod:`leosop.apps.simulate.tight`) couplings, :func:`pos_jacobian`
(``[dlat, dlon, dalt]`` to ENU metres), the gate and the satellites' error
models of the LEO aids.
"""

import dataclasses

import numpy as np

from .. import earth
from ..ins.error_model import DPOS, DV, EPS, NABLA, PHI
from ..ins.track import NavTrack

__all__ = ["DROP_AFTER_S", "GATE_PROBABILITY", "N_INS", "ORBIT_MODELS", "RX_OFFSET_PSD_HZ2_PER_S", "RX_OFFSET_SIGMA_HZ",
           "FilterSettings", "FusionResult", "initial_covariance", "pos_jacobian"]

#: How the satellites' orbit errors are related: each its own, or one shift of all.
ORBIT_MODELS = ("independent", "common")
#: A satellite's error states are dropped this long after it was last used.
DROP_AFTER_S = 30.0
#: Number of INS error states; they come first in every filter state.
N_INS = 15
#: Innovations beyond this chi-square quantile (degrees of freedom: the measurement's size) are rejected:
#: a consistent filter loses one good measurement in a million (a single Doppler: 4.9 sigma), while a
#: wrong Doppler peak is tens of Hz off and its fix hundreds of metres.
GATE_PROBABILITY = 1.0 - 1e-6
#: Prior sigma of each receiver frequency offset [Hz] and its random walk [Hz^2/s], for both couplings.
RX_OFFSET_SIGMA_HZ = 10.0
RX_OFFSET_PSD_HZ2_PER_S = 1e-6


@dataclasses.dataclass(frozen=True)
class FilterSettings:
    """Filter tuning, in the units the names carry.

    ``pos_sigma_m``, ``vel_sigma_mps``: initial uncertainty per ENU axis;
    ``att_sigma_rad``: initial attitude uncertainty (E, N, U); ``gyro_bias_*``
    and ``accel_bias_*``: initial bias uncertainty and white-noise densities.
    """

    pos_sigma_m: tuple
    vel_sigma_mps: tuple
    att_sigma_rad: tuple
    gyro_bias_sigma_rad_per_s: float
    accel_bias_sigma_mps2: float
    gyro_arw_rad_per_rt_s: float
    accel_vrw_mps2_per_rt_hz: float
    correction_period_s: float = 1.0
    step_s: float = 1.0
    gate: bool = True

    @property
    def noise_psd(self):
        """Power spectral densities of ``[w_gyro_b, w_accel_b]``, (6,): the ``Qc`` of :mod:`leosop.ins.error_model`."""
        return np.r_[np.full(3, self.gyro_arw_rad_per_rt_s**2), np.full(3, self.accel_vrw_mps2_per_rt_hz**2)]


@dataclasses.dataclass(frozen=True)
class FusionResult(NavTrack):
    """Filter output at every step epoch (n epochs, the first is the initial state): a track and its record.

    Attributes
    ----------
    t_s, lat_rad, lon_rad, alt_m, vel_enu_mps, C_n_b
        The corrected INS (:class:`leosop.ins.track.NavTrack`): shapes (n,),
        (n,), (n,), (n,), (n, 3), (n, 3, 3).
    P : ndarray, (n, 15, 15)
        Covariance of the remaining INS errors (after feedback).
    updated : ndarray of bool, (n,)
        An update was made at this epoch.
    rejected : ndarray of bool, (n,)
        A fix (loose) or a Doppler (tight) was offered but failed the innovation gate.
    nis : ndarray, (n,)
        Normalised innovation squared of each update, NaN elsewhere.
    nis_dof : ndarray of int, (n,)
        Its degrees of freedom (measurements in the update; 0 without one).
    gyro_bias_rad_per_s, accel_bias_mps2 : ndarray, (n, 3)
        Accumulated bias estimates.
    innovation, innovation_cov : ndarray, (n, 6), (n, 6, 6), or None
        Loose coupling: ``z - H x`` and ``S`` of each update's fix rows
        (velocity [m/s], position [m] ENU; the offset and residual rows are
        in ``nis``), NaN elsewhere; None for tight coupling.
    doppler_innovation : structured ndarray or None
        Tight coupling: one row per Doppler used, fields ``epoch``, ``sat``
        and ``normalized`` (innovation over the square root of its variance
        in ``S``); None for loose coupling.
    reopened : ndarray of bool, (n,), or None
        Loose coupling: the innovation gate was re-opened at this epoch after
        a run of rejected fixes (:class:`leosop.fusion.aids_fix.FixLog`); None for tight coupling.
    """

    P: np.ndarray
    updated: np.ndarray
    rejected: np.ndarray
    nis: np.ndarray
    nis_dof: np.ndarray
    gyro_bias_rad_per_s: np.ndarray
    accel_bias_mps2: np.ndarray
    innovation: np.ndarray | None = None
    innovation_cov: np.ndarray | None = None
    doppler_innovation: np.ndarray | None = None
    reopened: np.ndarray | None = None

    def pos_vel_cov_enu(self):
        """Covariance of ``[dv_enu, dpos_enu]`` in m/s and m, (n, 6, 6)."""
        D = np.zeros((self.t_s.size, 6, 15))
        D[:, 0:3, DV] = np.eye(3)
        D[:, 3:6, DPOS] = pos_jacobian(self.lat_rad, self.alt_m)
        return D @ self.P @ np.swapaxes(D, 1, 2)


def pos_jacobian(lat_rad, alt_m):
    """d(ENU metres)/d[dlat, dlon, dalt], shape (..., 3, 3)."""
    lat = np.asarray(lat_rad, dtype=float)
    R_M, R_N = earth.radii_m(lat)
    J = np.zeros(lat.shape + (3, 3))
    J[..., 0, 1] = (R_N + alt_m) * np.cos(lat)
    J[..., 1, 0] = R_M + alt_m
    J[..., 2, 2] = 1.0
    return J


def initial_covariance(settings, lat_rad, alt_m):
    """Initial 15 x 15 covariance of the INS errors (position in rad, rad, m)."""
    J_inv = np.linalg.inv(pos_jacobian(lat_rad, alt_m))
    P = np.zeros((N_INS, N_INS))
    P[PHI, PHI] = np.diag(np.square(settings.att_sigma_rad))
    P[DV, DV] = np.diag(np.square(settings.vel_sigma_mps))
    P[DPOS, DPOS] = J_inv @ np.diag(np.square(settings.pos_sigma_m)) @ J_inv.T
    P[EPS, EPS] = np.eye(3) * settings.gyro_bias_sigma_rad_per_s**2
    P[NABLA, NABLA] = np.eye(3) * settings.accel_bias_sigma_mps2**2
    return P
