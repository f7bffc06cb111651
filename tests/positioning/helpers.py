"""The Doppler model and receiver site the positioning tests share, written out independently of the solvers."""

import numpy as np

from leosop.constants import C_MPS
from leosop.constellations import REGISTRY
from leosop.frames import C_e_n, azimuth_elevation_range, geodetic_to_ecef
from leosop.orbits import DEFAULT_TLE, read_tle
from leosop.orbits.propagate import state_ecef

F0_HZ = REGISTRY["starlink"].carrier_hz
#: Xi'an, the receiver of the snapshot and Starlink-like tests.
LAT, LON = np.radians(34.342), np.radians(108.940)


def doppler_hz(pos_sv, vel_sv, pos_rx, vel_rx, clock_hz, f0_hz=F0_HZ):
    """The measurement model written out independently of the solver.

    Parameters
    ----------
    pos_sv, vel_sv : ndarray, (..., n_sv, 3)
        Satellite ECEF states, m and m/s.
    pos_rx, vel_rx : ndarray, (..., 3)
        Receiver ECEF states, m and m/s.
    clock_hz : ndarray, (...)
        Receiver frequency offset.
    f0_hz : float
        Carrier.

    Returns
    -------
    ndarray, (..., n_sv)
        Doppler, Hz: ``-range_rate f0 / c`` plus the clock.
    """
    los = pos_sv - pos_rx[..., None, :]
    rate = np.sum(los * (vel_sv - vel_rx[..., None, :]), -1) / np.linalg.norm(los, axis=-1)
    return -rate * f0_hz / C_MPS + clock_hz[..., None]


def common_truth(rate, t_s, sat, rng, sat_range_hz=(-5.0, 5.0), zero_mean=True):
    """Injected clock terms of ``starlink_like``: receiver offset + drift, satellite offsets, time offsets.

    Parameters
    ----------
    rate : ndarray, (m,)
        Doppler rate of each row, Hz/s (the time offsets enter to first order).
    t_s : ndarray, (m,)
        Row times, s.
    sat : ndarray of int, (m,)
        Satellite (0..6) of each row.
    rng : numpy.random.Generator
    sat_range_hz : tuple of float
        Satellite offsets drawn uniform in this range, Hz.
    zero_mean : bool
        Remove the offsets' mean (a common offset is then the receiver's alone).

    Returns
    -------
    extra : ndarray, (m,)
        The clock terms to add to each row, Hz.
    rx_poly : ndarray, (2,)
        Receiver offset (Hz) and drift (Hz/s) about t = 29.5 s.
    sat_hz, dt_s : ndarray, (7,)
        Satellite offsets, Hz, and time offsets, s.
    """
    rx_poly = np.array([1.5e3, -0.7])
    sat_hz = rng.uniform(*sat_range_hz, 7)
    if zero_mean:
        sat_hz -= sat_hz.mean()
    dt_s = rng.normal(0.0, 0.05, 7)
    extra = rx_poly[0] + rx_poly[1] * (t_s - 29.5) + sat_hz[sat] + dt_s[sat] * rate
    return extra, rx_poly, sat_hz, dt_s


def base_rover_scene(offsets, n_sats):
    """The bundled Walker set after its epoch, a base at 34.3 N 108.9 E and a rover 7.5 km from it.

    Parameters
    ----------
    offsets : timedelta64 array, (n_epochs,)
        The epochs after the element sets' latest epoch.
    n_sats : int
        How many of the satellites above 25 deg over the base throughout to keep.

    Returns
    -------
    const, base_ecef_m (3,), rover_ecef_m (3,), t (n_epochs,) datetime64, ids (n_sats,)
    """
    lat, lon = np.radians(34.3), np.radians(108.9)
    const = read_tle(DEFAULT_TLE)
    base = geodetic_to_ecef(lat, lon, 400.0)
    rover = base + C_e_n(lat, lon) @ np.array([6e3, 4.5e3, 30.0])
    t = const.epochs_utc.max() + offsets
    pos, _, _ = state_ecef(const, t[[0, -1]])
    _, el, _ = azimuth_elevation_range(pos, base)
    ids = const.sat_ids[np.flatnonzero(el.min(-1) > np.radians(25.0))[:n_sats]]
    assert len(ids) == n_sats
    return const, base, rover, t, ids
