"""Doppler tracks simulated from element sets, with the errors a real recording has.

For tests and benchmarks of the identification: the satellite states come
from :func:`~leosop.positioning.measurements.sv_states_from_tle` (SGP4 per
measurement, light time included), independently of the interpolated grid
the identification uses.
"""

import numpy as np

from ..constants import C_MPS
from ..constellations import DEFAULT_FAMILY, REGISTRY
from ..frames import azimuth_elevation_range, range_rate, rotate_to_later_ecef
from ..orbits.propagate import state_ecef
from ..positioning.measurements import sv_states_from_tle
from ..signal.channel import inertial_speed_mps
from .tracks import Track

__all__ = ["visible_indices", "simulate_track", "spurious_track"]


def visible_indices(constellation, pos_rx_ecef_m, times_utc, mask_deg):
    """Satellites above ``mask_deg`` at every one of ``times_utc``, ndarray of int."""
    pos, _, _ = state_ecef(constellation, np.asarray(times_utc, "datetime64[ns]"))
    _, elev, _ = azimuth_elevation_range(pos, np.asarray(pos_rx_ecef_m, float))
    return np.flatnonzero(np.all(np.nan_to_num(elev, nan=-1.0) >= np.radians(mask_deg), axis=1))


def simulate_track(constellation, sat_index, pos_rx_ecef_m, time_utc, rng, *, clock_hz=0.0,
                   clock_drift_hz_per_s=0.0, sat_offset_hz=0.0, along_track_m=0.0, sigma_hz=0.5,
                   carrier_hz=REGISTRY[DEFAULT_FAMILY].carrier_hz):
    """One satellite's track as a static receiver measures it.

    Parameters
    ----------
    constellation : Constellation
    sat_index : int
    pos_rx_ecef_m : array_like, (3,)
    time_utc : ndarray of datetime64[ns], (n,)
    rng : numpy.random.Generator
    clock_hz, clock_drift_hz_per_s : float
        Receiver clock offset at ``time_utc[0]`` and its drift.
    sat_offset_hz : float
        The satellite's own frequency offset.
    along_track_m : float
        Element-set error: the true satellite is this far ahead of SGP4 on its inertial orbit (a time
        offset of the inertial orbit, as :class:`~leosop.signal.channel.OrbitError` injects it).
    sigma_hz : float

    Returns
    -------
    Track
        ``sat_id`` None (the truth is the caller's).
    """
    t_utc = np.asarray(time_utc, "datetime64[ns]")
    shift_s = along_track_m / inertial_speed_mps(constellation, t_utc[0])[sat_index]
    shift_ns = int(round(shift_s * 1e9))
    ids = np.full(len(t_utc), constellation.sat_ids[sat_index])
    pos, vel, _ = sv_states_from_tle(constellation, ids, t_utc + np.timedelta64(shift_ns, "ns"), pos_rx_ecef_m)
    # The inertial orbit ahead, the Earth not: the states at t + shift in the ECEF frame of t.
    pos, vel = rotate_to_later_ecef(pos, -shift_ns * 1e-9), rotate_to_later_ecef(vel, -shift_ns * 1e-9)
    t_s = (t_utc - t_utc[0]) / np.timedelta64(1, "s")
    dop = -range_rate(pos, vel, np.asarray(pos_rx_ecef_m, float)) * carrier_hz / C_MPS
    dop = dop + clock_hz + clock_drift_hz_per_s * t_s + sat_offset_hz + sigma_hz * rng.standard_normal(len(t_s))
    rate = np.gradient(dop, t_s) if len(t_s) > 1 else np.zeros(1)
    return Track(t_s, t_utc, dop, rate, np.full(len(t_s), 50.0), np.full(len(t_s), float(sigma_hz)))


def spurious_track(time_utc, rng, *, sigma_hz=0.5, max_doppler_hz=250e3, max_rate_hz_per_s=2e3):
    """A track no satellite made: a random quadratic Doppler curve, (n,) times as given."""
    t_utc = np.asarray(time_utc, "datetime64[ns]")
    t_s = (t_utc - t_utc[0]) / np.timedelta64(1, "s")
    f0, r0, q0 = rng.uniform(-1, 1, 3) * np.array([max_doppler_hz, max_rate_hz_per_s, 20.0])
    dop = f0 + r0 * t_s + q0 * t_s**2 + sigma_hz * rng.standard_normal(len(t_s))
    rate = r0 + 2 * q0 * t_s
    return Track(t_s, t_utc, dop, rate, np.full(len(t_s), 50.0), np.full(len(t_s), float(sigma_hz)))
