"""Aiding measurements of the INS error-state filter (:mod:`leosop.fusion.engine`).

Each aid is a small object at one time ``t_s`` that answers two questions
about the INS it is shown (an :class:`InsView`):

* :meth:`Aid.predict`: the nonlinear measurement the INS implies, ``h(ins)``;
* :meth:`Aid.design`: the design matrix ``H`` over the 15 INS errors;

and :meth:`Aid.matrices` returns the innovation ``z = h(ins) - measured``,
``H`` and the noise covariance ``R``, so that
  ``z = H dx + v`` with ``dx`` the INS errors in the sense of
  :mod:`leosop.ins.error_model` (computed minus true, misalignment ``phi`` with
  ``C_n_b_computed = (I - [phi x]) C_n_b_true``, position ``[dlat, dlon, dalt]``,
  residual gyro drift ``eps_b`` and accelerometer bias ``nabla_b``).

Adding a sensor is one class; the filter never changes (the shape of
Mayorov's pyins ``Measurement`` classes). Lever arms and velocities are in
the body frame (Right-Forward-Up) of the INS, i.e. after the IMU mounting.
Every ``H`` is checked against finite differences of :meth:`Aid.predict` in
``tests/fusion/test_engine.py``.
"""

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from ..constants import OMEGA_E_RAD_PER_S
from ..earth import earth_rate_enu
from ..ins.error_model import DPOS, DV, EPS, PHI
from ..rotations import skew
from .common import N_INS, pos_jacobian

__all__ = ["Aid", "GnssPosition", "GnssVelocity", "Height", "InsView", "NonHolonomic", "StateBlock", "WalkingSpeed",
           "ZeroRate", "ZeroVelocity"]


@dataclasses.dataclass(frozen=True)
class StateBlock:
    """States an aid needs beside the INS errors (a receiver clock, a satellite's offset), shared by key.

    The engine adds a block with its prior when the first aid naming its
    ``key`` comes, keeps its estimate (in :attr:`InsView.states`), propagates
    it with :meth:`transition` and drops it ``drop_after_s`` after the last
    aid that named it (None: never). Its error state is estimate minus truth.

    Attributes
    ----------
    key : str
    mean0, sigma0 : tuple of float, (k,)
        Prior estimate and its standard deviation, per state.
    psd : tuple of float, (k,)
        Random-walk power spectral density of each state (unit^2/s).
    integrated : bool
        State 0 is the integral of state 1 (a frequency offset and its drift; k = 2).
    drop_after_s : float or None
    cloned : bool
        A clone of INS quantities made by an aid with :attr:`Aid.clones` (its
        ``mean0`` and ``sigma0`` are not used): never added from a prior, an
        aid naming it before it was made (or after it was dropped) is skipped.
    """

    key: str
    mean0: tuple
    sigma0: tuple
    psd: tuple
    integrated: bool = False
    drop_after_s: float | None = None
    cloned: bool = False

    @property
    def size(self):
        return len(self.mean0)

    def transition(self, dt_s):
        """``(Phi, Qd)`` over ``dt_s``, each (k, k): random walks, and the drift integrated into the offset."""
        q = np.asarray(self.psd, dtype=float)
        if not self.integrated:
            return np.eye(self.size), np.diag(q * dt_s)
        Phi = np.array([[1.0, dt_s], [0.0, 1.0]])
        Qd = np.array([[q[0] * dt_s + q[1] * dt_s**3 / 3.0, q[1] * dt_s**2 / 2.0],
                       [q[1] * dt_s**2 / 2.0, q[1] * dt_s]])
        return Phi, Qd


@dataclasses.dataclass(frozen=True)
class InsView:
    """What an aid may look at: the INS at the aid's time and the filter's sensor estimates.

    Attributes
    ----------
    state : leosop.ins.strapdown.NavState
    gyro_bias_rad_per_s, accel_bias_mps2 : ndarray, (3,)
        Bias estimates removed from the increments.
    omega_ib_b_rad_per_s : ndarray, (3,)
        Bias-corrected body rate over the last INS update.
    accel_enu_mps2 : ndarray, (3,)
        Mean acceleration over the last INS update (the rate of the velocity).
    states : dict of str to ndarray
        Estimates of the engine's :class:`StateBlock` states, by key.
    """

    state: object
    gyro_bias_rad_per_s: np.ndarray
    accel_bias_mps2: np.ndarray
    omega_ib_b_rad_per_s: np.ndarray
    accel_enu_mps2: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    states: dict = dataclasses.field(default_factory=dict)


def _enu_offset_m(state, lat_rad, lon_rad, alt_m):
    """ENU metres from a geodetic point to the state's position (small-offset map of :func:`pos_jacobian`)."""
    d = np.array([state.lat_rad - lat_rad, state.lon_rad - lon_rad, state.alt_m - alt_m])
    return pos_jacobian(state.lat_rad, state.alt_m) @ d


class Aid:
    """One aiding measurement at ``t_s``; subclasses set the attributes and implement :meth:`predict`, :meth:`design`.

    Attributes
    ----------
    t_s : float
        Time of the measurement [s], on the filter's clock.
    measured : ndarray, (m,)
        The measurement, in the units of :meth:`predict`.
    R : ndarray, (m, m)
        Its noise covariance.
    name : str
        Kind of aid, the key of the run's aid counts.
    needs_heading : bool
        The model assumes a known heading (not applied before the yaw is initialised).
    gated : bool
        Its innovations go through the filter's chi-square gate. Constraints
        (ZUPT, NHC, ...) are: a skid or a wrongly detected stop must not pull
        the INS. GNSS fixes are not: their quality flag and sigmas are the
        receiver's own check, and rejecting fixes after a GNSS outage, when
        the INS has drifted further than its covariance says, only lets it
        drift on (measured on the rtklibexplorer drive and walk).
    external_clock : bool
        Time-tagged by another clock than the IMU's (GNSS): the filter's IMU
        time offset state applies to it through :meth:`rate`. Aids derived
        from the IMU log itself (ZUPT, NHC) are not.
    screens : bool
        It screens its own rows (:meth:`screen`); the filter then applies it
        as an update of its own, never stacked with others due at its time.
    states : tuple of StateBlock
        Blocks of states beside the INS errors the aid depends on; the
        columns of :meth:`design` after the 15 INS errors are theirs, in order.
    clones : bool
        It has no rows: at its time the filter makes its one (cloned) block
        from :meth:`clone_rows` (stochastic cloning, e.g. the antenna position
        at the start of a LEO Doppler's integration window).
    """

    t_s: float
    measured: npt.NDArray[np.float64]
    R: npt.NDArray[np.float64]
    name = "aid"
    needs_heading = False
    gated = True
    external_clock = False
    screens = False
    clones = False
    states = ()

    def __init__(self, t_s: float):
        self.t_s = float(t_s)

    def predict(self, ins: InsView) -> npt.NDArray[np.float64]:
        """The measurement the INS implies, ``h(ins)``, shape (m,)."""
        raise NotImplementedError

    def design(self, ins: InsView) -> npt.NDArray[np.float64]:
        """``H = dz / dx``, shape (m, 15 + the sizes of :attr:`states`)."""
        raise NotImplementedError

    def rate(self, ins: InsView) -> npt.NDArray[np.float64]:
        """``dh/dt`` along the INS's motion, shape (m,): the design column of the IMU time offset."""
        raise NotImplementedError

    def matrices(self, ins: InsView) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                                              npt.NDArray[np.float64]]:
        """``(z, H, R)``: innovation ``h(ins) - measured`` (m,), ``H`` as :meth:`design`, ``R`` (m, m)."""
        return self.predict(ins) - self.measured, self.design(ins), self.R

    def clone_rows(self, ins: InsView) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """For an aid with :attr:`clones`: the cloned quantity's estimate (k,) and its derivative over the 15
        INS errors (k, 15); the filter copies the INS errors' covariance through it (error = estimate minus truth)."""
        raise NotImplementedError

    def screen(self, z: npt.NDArray[np.float64], H: npt.NDArray[np.float64], R: npt.NDArray[np.float64],
               P: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.bool_], list[StateBlock]] | None:
        """Per-row outlier screening before the update (aids with ``screens`` True); None: every row.

        An aid that screens returns ``(keep, restart)``: the rows to use
        (bool, (m,)) and state blocks of its :attr:`states` to restart at
        their ``mean0``, ``sigma0`` (same key) before the update. ``z``,
        ``H``, ``R`` as from :meth:`matrices` over the full state (n_x
        columns), ``P`` (n_x, n_x) the covariance before the update.
        """
        return None


class GnssPosition(Aid):
    """A GNSS antenna position; ``h`` is the antenna's ENU offset [m] from the measured point.

    Parameters
    ----------
    t_s : float
    lat_rad, lon_rad, alt_m : float
        Measured antenna position (WGS84).
    cov_enu_m2 : array_like, (3, 3)
        Its covariance in ENU.
    lever_arm_b_m : array_like, (3,)
        Antenna minus IMU in the body frame (Right-Forward-Up).
    """

    name = "gnss_position"
    gated = False
    external_clock = True

    def __init__(self, t_s, lat_rad, lon_rad, alt_m, cov_enu_m2, lever_arm_b_m):
        super().__init__(t_s)
        self.lat_rad, self.lon_rad, self.alt_m = float(lat_rad), float(lon_rad), float(alt_m)
        self.measured = np.zeros(3)  # the offset of the measured point from itself
        self.R = np.asarray(cov_enu_m2, dtype=float).reshape(3, 3)
        self.lever_arm_b_m = np.asarray(lever_arm_b_m, dtype=float).reshape(3)

    def predict(self, ins):
        s = ins.state
        return _enu_offset_m(s, self.lat_rad, self.lon_rad, self.alt_m) + s.C_n_b @ self.lever_arm_b_m

    def rate(self, ins):
        s = ins.state
        return s.vel_enu_mps + s.C_n_b @ np.cross(ins.omega_ib_b_rad_per_s, self.lever_arm_b_m)

    def design(self, ins):
        s = ins.state
        H = np.zeros((3, N_INS))
        H[:, PHI] = skew(s.C_n_b @ self.lever_arm_b_m)
        H[:, DPOS] = pos_jacobian(s.lat_rad, s.alt_m)
        return H


class GnssVelocity(Aid):
    """A GNSS antenna velocity in ENU [m/s]: ``v + C_n_b (omega_ib_b x lever arm)`` (Earth rate neglected).

    A receiver's Doppler velocity is a mean over its measurement interval,
    not the velocity at the epoch: its error grows with the acceleration
    ``a`` (that of the INS at the aid), as ``accel_sigma_s |a|`` per axis,
    added to ``cov_enu_m2ps2``.

    Parameters
    ----------
    t_s : float
    vel_enu_mps : array_like, (3,)
    cov_enu_m2ps2 : array_like, (3, 3)
    lever_arm_b_m : array_like, (3,)
    accel_sigma_s : float
        Velocity error per acceleration [m/s per m/s^2].
    """

    name = "gnss_velocity"
    gated = False
    external_clock = True

    def __init__(self, t_s, vel_enu_mps, cov_enu_m2ps2, lever_arm_b_m, *, accel_sigma_s=0.0):
        super().__init__(t_s)
        self.vel_enu_mps = self.measured = np.asarray(vel_enu_mps, dtype=float).reshape(3)
        self.R = np.asarray(cov_enu_m2ps2, dtype=float).reshape(3, 3)
        self.lever_arm_b_m = np.asarray(lever_arm_b_m, dtype=float).reshape(3)
        self.accel_sigma_s = float(accel_sigma_s)

    def matrices(self, ins):
        z, H, R = super().matrices(ins)
        if self.accel_sigma_s:
            R = R + np.eye(3) * (self.accel_sigma_s * np.linalg.norm(ins.accel_enu_mps2)) ** 2
        return z, H, R

    def predict(self, ins):
        s = ins.state
        return s.vel_enu_mps + s.C_n_b @ np.cross(ins.omega_ib_b_rad_per_s, self.lever_arm_b_m)

    def rate(self, ins):
        return np.asarray(ins.accel_enu_mps2, dtype=float)

    def design(self, ins):
        C = ins.state.C_n_b
        H = np.zeros((3, N_INS))
        H[:, PHI] = skew(C @ np.cross(ins.omega_ib_b_rad_per_s, self.lever_arm_b_m))
        H[:, DV] = np.eye(3)
        # omega_computed = omega_true + eps_b: the rate error moves the lever-arm velocity by -C [l x] eps_b.
        H[:, EPS] = -C @ skew(self.lever_arm_b_m)
        return H


class ZeroVelocity(Aid):
    """Zero-velocity update (ZUPT): the IMU is at rest, ``h = v_enu``."""

    name = "zupt"

    def __init__(self, t_s, sigma_mps):
        super().__init__(t_s)
        self.R = np.eye(3) * float(sigma_mps) ** 2
        self.measured = np.zeros(3)

    def predict(self, ins):
        return ins.state.vel_enu_mps.copy()

    def design(self, ins):
        H = np.zeros((3, N_INS))
        H[:, DV] = np.eye(3)
        return H


class ZeroRate(Aid):
    """Zero angular rate (ZARU): at rest the bias-corrected mean body rate is the Earth rate.

    ``h = omega_mean_b - eps_hat - C_n_b^T omega_ie_n`` with ``omega_mean_b`` the
    raw mean gyro rate over the stationary window.

    Parameters
    ----------
    t_s : float
    omega_mean_b_rad_per_s : array_like, (3,)
        Mean measured rate over the window (before bias removal).
    sigma_rad_per_s : float
        Noise of that mean per axis.
    """

    name = "zero_rate"

    def __init__(self, t_s, omega_mean_b_rad_per_s, sigma_rad_per_s):
        super().__init__(t_s)
        self.omega_mean_b = np.asarray(omega_mean_b_rad_per_s, dtype=float).reshape(3)
        self.R = np.eye(3) * float(sigma_rad_per_s) ** 2
        self.measured = np.zeros(3)

    def predict(self, ins):
        s = ins.state
        return self.omega_mean_b - ins.gyro_bias_rad_per_s - s.C_n_b.T @ earth_rate_enu(s.lat_rad)

    def design(self, ins):
        s = ins.state
        H = np.zeros((3, N_INS))
        H[:, PHI] = s.C_n_b.T @ skew(earth_rate_enu(s.lat_rad))
        H[:, DPOS.start] = -s.C_n_b.T @ (OMEGA_E_RAD_PER_S * np.array([0.0, -math.sin(s.lat_rad), math.cos(s.lat_rad)]))
        H[:, EPS] = np.eye(3)
        return H


class NonHolonomic(Aid):
    """Non-holonomic constraint (NHC): a wheeled vehicle does not slip sideways nor leave the road.

    ``h`` is the Right and Up components of the velocity in the vehicle
    frame, ``C_v_b C_n_b^T v_enu``; ``C_v_b`` is a residual mounting of the
    body in the vehicle (identity when the IMU mounting is already applied).

    In a turn the tyres slip (their slip angle grows with the lateral force,
    hence with the lateral acceleration ``a = v_forward omega_up``) and a
    sensor off the rear axle moves sideways with ``omega_up`` times its
    offset: the lateral variance grows to ``sigma^2 + (slip_s a)^2 +
    (offset_m omega_up)^2``, from the INS's own velocity and rate.

    Parameters
    ----------
    t_s : float
    sigma_mps : float
        Allowed lateral and vertical speed (slip, bumps) per axis.
    C_v_b : array_like, (3, 3)
    slip_s : float
        Lateral speed per lateral acceleration [m/s per m/s^2].
    offset_m : float
        Lateral speed per yaw rate [m/s per rad/s]: the sensor's distance along the vehicle from the point
        that does not slip.
    """

    name = "nhc"
    needs_heading = True
    _ROWS = [0, 2]

    def __init__(self, t_s, sigma_mps, C_v_b=np.eye(3), *, slip_s=0.0, offset_m=0.0):
        super().__init__(t_s)
        self.R = np.eye(2) * float(sigma_mps) ** 2
        self.measured = np.zeros(2)
        self.C_v_b = np.asarray(C_v_b, dtype=float).reshape(3, 3)
        self.slip_s, self.offset_m = float(slip_s), float(offset_m)

    def matrices(self, ins):
        z, H, R = super().matrices(ins)
        if self.slip_s or self.offset_m:
            v_b = self.C_v_b @ ins.state.C_n_b.T @ ins.state.vel_enu_mps
            w_up = (self.C_v_b @ ins.omega_ib_b_rad_per_s)[2]
            R = R.copy()
            R[0, 0] += (self.slip_s * v_b[1] * w_up) ** 2 + (self.offset_m * w_up) ** 2
        return z, H, R

    def predict(self, ins):
        s = ins.state
        return (self.C_v_b @ s.C_n_b.T @ s.vel_enu_mps)[self._ROWS]

    def design(self, ins):
        s = ins.state
        A = self.C_v_b @ s.C_n_b.T
        H = np.zeros((2, N_INS))
        # C_computed^T = C^T (I + [phi x]): the body velocity moves by -C^T [v x] phi.
        H[:, PHI] = -(A @ skew(s.vel_enu_mps))[self._ROWS]
        H[:, DV] = A[self._ROWS]
        return H


class WalkingSpeed(Aid):
    """A pedestrian's pace: the horizontal speed ``h = |v_EN|`` [m/s] holds near its recent value.

    A walker keeps a cadence and a step length (the premise of pedestrian
    dead reckoning, Groves 2013, section 16.2), so while walking the speed
    is known to its scatter about the pace even where its direction is
    not; in turns that scatter bounds every horizontal direction of the
    velocity error in turn.

    Parameters
    ----------
    t_s : float
    speed_mps : float
        The pace (e.g. the recent GNSS speed).
    sigma_mps : float
        Scatter of the speed about it.
    """

    name = "walking_speed"

    def __init__(self, t_s, speed_mps, sigma_mps):
        super().__init__(t_s)
        self.measured = np.array([float(speed_mps)])
        self.R = np.eye(1) * float(sigma_mps) ** 2

    def predict(self, ins):
        return np.array([math.hypot(*ins.state.vel_enu_mps[:2])])

    def design(self, ins):
        v = ins.state.vel_enu_mps
        H = np.zeros((1, N_INS))
        H[0, DV.start:DV.start + 2] = v[:2] / max(math.hypot(*v[:2]), 1e-6)
        return H


class Height(Aid):
    """An ellipsoidal height (barometer, known road or floor) [m]."""

    name = "height"

    def __init__(self, t_s, alt_m, sigma_m):
        super().__init__(t_s)
        self.alt_m = float(alt_m)
        self.measured = np.array([self.alt_m])
        self.R = np.eye(1) * float(sigma_m) ** 2

    def predict(self, ins):
        return np.array([ins.state.alt_m])

    def design(self, ins):
        H = np.zeros((1, N_INS))
        H[0, DPOS.start + 2] = 1.0
        return H

