"""Fixtures of the multi-pass and common-clock fixes (test_doppler_ls.py, test_static_passes.py)."""

import numpy as np
import pytest

from leosop.frames import azimuth_elevation_range, geodetic_to_ecef
from leosop.geometry.doppler import doppler_rate
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef

from tests.positioning.helpers import F0_HZ, LAT, LON, doppler_hz


@pytest.fixture(scope="module")
def two_passes():
    """The first two passes (above 10 deg) of one VHF satellite over a station, each with its own cubic clock."""
    f0 = 145.87e6
    const = load_constellation().subset([0])
    station = geodetic_to_ecef(np.radians(52.0), np.radians(4.37), 95.0)
    t = np.datetime64("2025-01-01T00:00:00") + np.arange(0, 86400, 2).astype("timedelta64[s]")
    pos, vel, _ = state_ecef(const, t)
    _, el, _ = azimuth_elevation_range(pos[0], station)
    k = np.flatnonzero(el > np.radians(10))
    pass_id = np.concatenate([[0], np.cumsum(np.diff(k) > 1)])
    k, pass_id = k[pass_id < 2], pass_id[pass_id < 2]
    t_s = 2.0 * k
    clocks = np.array([[-300.0, -0.5, 1e-4, 1e-7], [-250.0, 0.3, -2e-4, 5e-8]])
    dop = doppler_hz(pos[0, k][None], vel[0, k][None], station[None], np.zeros((1, 3)), np.zeros(1), f0)[0]
    t_ref = np.array([0.5 * (t_s[pass_id == p].min() + t_s[pass_id == p].max()) for p in range(2)])
    dt = t_s - t_ref[pass_id]
    dop += np.einsum("mk,mk->m", clocks[pass_id], dt[:, None] ** np.arange(4))
    return (dop, pos[0, k], vel[0, k], f0, t_s, pass_id), station, clocks, t_ref


@pytest.fixture(scope="module")
def starlink_like():
    """7 satellites of the bundled constellation above 25 deg over Xi'an for 60 s at 1 Hz, Ku-band pilot."""
    const = load_constellation()
    t = np.datetime64("2025-01-01T04:00:00") + np.arange(60).astype("timedelta64[s]")
    pos, vel, _ = state_ecef(const, t)
    rx = geodetic_to_ecef(LAT, LON, 400.0)
    _, el, _ = azimuth_elevation_range(pos, rx)
    sats = np.flatnonzero(el.min(-1) > np.radians(25))[:7]
    assert len(sats) == 7
    n_ep = len(t)
    sat = np.repeat(np.arange(7), n_ep)
    t_s = np.tile(np.arange(n_ep, dtype=float), 7)
    p, v = pos[sats].reshape(-1, 3), vel[sats].reshape(-1, 3)
    geo = doppler_hz(p[None], v[None], rx[None], np.zeros((1, 3)), np.zeros(1))[0]
    rate, _ = doppler_rate(p, v, rx, F0_HZ, inertial=True)  # the fix's time-offset column
    return geo, rate, p, v, t_s, sat, rx

