"""Reader of the Gebre-Egziabher & Gleason (2009) case-study flight (``flight_data.mat``): IMU, GPS, attitude.

The MATLAB file (``../shared/data/gnss-ins/PROVENANCE.md`` section 2) holds,
one row per 50 Hz IMU sample: ``t`` [s], ``imu`` = ``[t, gyro x y z [rad/s],
accel x y z [m/s^2]]`` in a forward-right-down body, ``gps_pos_lla`` [rad,
rad, m] and ``gps_vel_ned`` [m/s] held between GPS epochs, and the MIDG II
attitude ``roll, pitch, yaw`` in degrees (the benchmark, not truth).

* The file states no absolute time: its ``t = 0`` is placed at the GPS epoch
  (1980-01-06 GPST), which only labels the outputs.
* A GPS epoch is a row whose position differs from the row before.
* It states no GPS sigmas: the epochs are single-point fixes (Q = 5, which
  :func:`leosop.fusion.real.fuse` weights 5x the stated sigmas), stated at
  0.6 m horizontal, 1.2 m vertical and 0.06 m/s, i.e. 3 m, 6 m and 0.3 m/s as
  used: a stand-alone receiver of the period.
"""

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gnss.rtklib_pos import Q_SINGLE, PosSolution
from .imu_io import _from_rates, mount_C_b_s

__all__ = ["GPS_EPOCH_GPST", "read_flight_mat"]

#: The nominal instant of the file's ``t = 0``.
GPS_EPOCH_GPST = "1980-01-06T00:00:00.000000Z GPST"
#: Unix-style GPST seconds of :data:`GPS_EPOCH_GPST`.
_GPS_EPOCH_S = 315964800.0
_SIGMA_STATED = (0.6, 1.2, 0.06)  # horizontal [m], vertical [m], velocity [m/s]; 5x as used (Q = 5)
_VARIABLES = {"t": 1, "imu": 7, "gps_pos_lla": 3, "gps_vel_ned": 3, "roll": 1, "pitch": 1, "yaw": 1}


def read_flight_mat(path, *, C_b_s=None):
    """Read the flight case.

    Parameters
    ----------
    path : path-like
    C_b_s : array_like, (3, 3), optional
        Sensor-to-body (Right-Forward-Up); default the file's forward-right-down axes.

    Returns
    -------
    log : leosop.ins.imu_io.ImuLog
    gps : leosop.gnss.rtklib_pos.PosSolution
    attitude_deg : dict of str to ndarray, (n_imu,)
        MIDG II ``t_s``, ``roll``, ``pitch``, ``yaw`` (clockwise from North).
    """
    import scipy.io

    path = Path(path)
    try:
        m = scipy.io.loadmat(path)
    except (OSError, ValueError, NotImplementedError) as exc:
        raise InputError(f"{path}: not a readable MATLAB file ({exc})") from None
    for name, cols in _VARIABLES.items():
        if name not in m or m[name].ndim != 2 or m[name].shape[1] != cols:
            raise InputError(f"{path}: variable {name!r} with {cols} column(s) missing")
    n = m["t"].shape[0]
    if any(m[k].shape[0] != n for k in _VARIABLES):
        raise InputError(f"{path}: the variables {', '.join(_VARIABLES)} must have the same number of rows")
    if not all(np.all(np.isfinite(m[k])) for k in _VARIABLES):
        raise InputError(f"{path}: non-finite values")
    t = m["t"][:, 0].astype(float)
    imu = m["imu"].astype(float)
    C = mount_C_b_s(0.0, 0.0, 0.0) if C_b_s is None else C_b_s
    log = _from_rates(path, t, imu[:, 4:7], imu[:, 1:4], 1, C, GPS_EPOCH_GPST, {"format": "flight_mat"})
    lla = m["gps_pos_lla"].astype(float)
    new = np.r_[True, np.any(np.diff(lla, axis=0) != 0.0, axis=1)]
    k = np.flatnonzero(new)
    vel_ned = m["gps_vel_ned"][k].astype(float)
    sh, sv, svel = _SIGMA_STATED
    cov = np.broadcast_to(np.diag([sh**2, sh**2, sv**2]), (k.size, 3, 3)).copy()
    gps = PosSolution(_GPS_EPOCH_S + t[k], np.degrees(lla[k, 0]), np.degrees(lla[k, 1]), lla[k, 2],
                      np.full(k.size, Q_SINGLE), np.zeros(k.size, dtype=int), cov,
                      vel_ned[:, [1, 0, 2]] * [1.0, 1.0, -1.0],
                      np.broadcast_to(np.eye(3) * svel**2, (k.size, 3, 3)).copy(), str(path))
    attitude = {"t_s": t, **{a: m[a][:, 0].astype(float) for a in ("roll", "pitch", "yaw")}}
    return log, gps, attitude
