"""Where an IMU log is at rest: the windows that ZUPT and zero-rate aids may use."""

import itertools
import math

import numpy as np

__all__ = ["stationary_windows"]


def stationary_windows(t_s, accel_mps2, gyro_rad_per_s, *, window_s=1.0, max_accel_std_mps2=0.2,
                       max_accel_change_mps2=0.05, max_rate_deg_per_s=0.3):
    """Windows of an IMU log in which it is at rest.

    A window is at rest when the scatter of the specific-force magnitude,
    the change of the mean specific force between its quarters and the
    magnitude of its mean body rate are all small. The thresholds separate
    every 1 s window of the rtklibexplorer drive and walk logs in motion
    (GNSS speed over 0.05 m/s: none flagged) from about 80 % of those at rest
    (engine idling, hand-held) (docs/fusion-real.md).

    Parameters
    ----------
    t_s : ndarray, (n,)
    accel_mps2, gyro_rad_per_s : ndarray, (n, 3)

    Returns
    -------
    t_end_s : ndarray, (k,)
        End of each window at rest.
    gyro_mean_rad_per_s : ndarray, (k, 3)
        Its mean body rate.
    """
    edges = np.searchsorted(t_s, np.arange(t_s[0], t_s[-1], window_s))
    ends, means = [], []
    for a, b in itertools.pairwise(edges):
        q = (b - a) // 4
        if q < 2:
            continue
        f = accel_mps2[a:b]
        quarters = f[:4 * q].reshape(4, q, 3).mean(axis=1)
        w = gyro_rad_per_s[a:b].mean(axis=0)
        if (np.linalg.norm(f, axis=1).std() < max_accel_std_mps2
                and np.ptp(quarters, axis=0).max() < max_accel_change_mps2
                and math.degrees(float(np.linalg.norm(w))) < max_rate_deg_per_s):
            ends.append(t_s[b - 1])
            means.append(w)
    return np.asarray(ends), np.asarray(means).reshape(-1, 3)
