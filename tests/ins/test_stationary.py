"""The IMU rest detector against a synthetic log whose rest and motion are known."""

import numpy as np

from leosop.constants import G0_MPS2
from leosop.ins.stationary import stationary_windows


def test_rest_windows_are_found_and_motion_is_not():
    # 100 Hz for 20 s: at rest (gravity plus 0.01 m/s^2 and 0.01 deg/s of white noise, a consumer MEMS
    # at idle) for 0-8 s and 14-20 s, accelerating along x with a 1 Hz sway (0.5 m/s^2) and turning at
    # 5 deg/s in between.
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0, 0.01)
    moving = (t >= 8.0) & (t < 14.0)
    accel = np.tile([0.0, 0.0, G0_MPS2], (t.size, 1)) + 0.01 * rng.standard_normal((t.size, 3))
    accel[moving, 0] += 0.5 * np.sin(2 * np.pi * t[moving])
    gyro = np.radians(0.01) * rng.standard_normal((t.size, 3))
    gyro[moving, 2] += np.radians(5.0)
    ends, rates = stationary_windows(t, accel, gyro)
    # Every whole 1 s window inside a rest stretch, none overlapping the motion.
    starts = ends - 0.99
    assert not ((ends >= 8.0) & (starts < 14.0)).any()
    assert ((ends < 8.0).sum(), (starts >= 14.0).sum()) == (8, 5)
    # Their mean rates are the gyro noise averaged over 100 samples: 0.001 deg/s per axis, 5 sigma bound.
    assert np.degrees(np.abs(rates)).max() < 5 * 0.01 / np.sqrt(100)
