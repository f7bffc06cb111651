"""The one navigation-track type: position, velocity and attitude over time.

:class:`NavTrack` is what a truth trajectory (:class:`leosop.ins.trajectory.Trajectory`,
which adds the ideal IMU increments) and a filter's output
(:class:`leosop.fusion.common.FusionResult`, which adds its covariance and
update record) have in common, so that code comparing or exporting tracks
takes any of them.
"""

import dataclasses

import numpy as np

from .. import frames
from ..errors import InputError

__all__ = ["NavTrack"]

#: Times asked of :meth:`NavTrack.at` must be within this of an epoch [s].
TIME_SLACK_S = 1e-6


@dataclasses.dataclass(frozen=True)
class NavTrack:
    """Navigation states at epochs ``t_s``.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Seconds since the start, increasing.
    lat_rad, lon_rad, alt_m : ndarray, shape (n,)
        WGS84 geodetic position.
    vel_enu_mps : ndarray, shape (n, 3)
        Velocity relative to the Earth in ENU.
    C_n_b : ndarray, shape (n, 3, 3)
        Attitude, body (Right-Forward-Up) to ENU.
    """

    t_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    alt_m: np.ndarray
    vel_enu_mps: np.ndarray
    C_n_b: np.ndarray

    @property
    def pos_ecef_m(self):
        """ECEF position, shape (n, 3)."""
        return frames.geodetic_to_ecef(self.lat_rad, self.lon_rad, self.alt_m)

    def index(self, t_s):
        """Indices of the epochs at times ``t_s`` (each within :data:`TIME_SLACK_S` of one), shape (m,).

        Raises
        ------
        InputError
            A time is not an epoch of the track.
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        n = self.t_s.size
        if n == 0:
            raise InputError("the track has no epochs")
        hi = np.clip(np.searchsorted(self.t_s, t), 0, n - 1)
        lo = np.clip(hi - 1, 0, n - 1)
        k = np.where(np.abs(self.t_s[lo] - t) < np.abs(self.t_s[hi] - t), lo, hi)
        if np.any(~(np.abs(self.t_s[k] - t) <= TIME_SLACK_S)):
            raise InputError(f"t_s must be epochs of the track (within {TIME_SLACK_S} s) in "
                             f"[{self.t_s[0]}, {self.t_s[-1]}] s")
        return k

    def at(self, t_s):
        """The track at epochs ``t_s`` (which must be epochs of it), a :class:`NavTrack`."""
        k = self.index(t_s)
        return NavTrack(self.t_s[k], self.lat_rad[k], self.lon_rad[k], self.alt_m[k], self.vel_enu_mps[k],
                        self.C_n_b[k])
