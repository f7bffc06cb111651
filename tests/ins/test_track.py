"""NavTrack: the one navigation-track type shared by truth trajectories and filter outputs."""

import numpy as np
import pytest

from leosop import frames
from leosop.errors import InputError
from leosop.fusion.common import FusionResult
from leosop.ins import trajectory
from leosop.ins.track import NavTrack


def _track(n=5):
    t = np.arange(n) * 0.5
    lat, lon = np.radians(34.0 + 0.01 * t), np.radians(108.0 - 0.02 * t)
    vel = np.column_stack([t, -t, 0.1 * t])
    return NavTrack(t, lat, lon, 3000.0 + t, vel, np.broadcast_to(np.eye(3), (n, 3, 3)).copy())


def test_at_selects_epochs_and_position_is_the_geodetic_one():
    tr = _track()
    sub = tr.at([0.5, 1.5 + 1e-7])  # within the 1 us slack of epochs 1 and 3
    assert type(sub) is NavTrack
    assert np.array_equal(sub.t_s, tr.t_s[[1, 3]]) and np.array_equal(sub.vel_enu_mps, tr.vel_enu_mps[[1, 3]])
    assert np.array_equal(sub.pos_ecef_m, frames.geodetic_to_ecef(tr.lat_rad[[1, 3]], tr.lon_rad[[1, 3]],
                                                                   tr.alt_m[[1, 3]]))
    with pytest.raises(InputError, match="epochs of the track"):
        tr.at([0.25])
    with pytest.raises(InputError, match="epochs of the track"):
        tr.at([2.5])


def test_truth_and_filter_output_are_tracks():
    truth = trajectory.rolling_flight(duration_s=1.0)
    assert isinstance(truth, NavTrack) and issubclass(FusionResult, NavTrack)
    # A Trajectory keeps its own at(): increments summed between the selected samples.
    sub = truth.at(truth.t_s[::10])
    assert isinstance(sub, trajectory.Trajectory) and sub.dtheta_b_rad.shape == (10, 3)
