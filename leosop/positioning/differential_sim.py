"""Measurement-level simulation of receivers that see the same satellites with the same satellite errors.

What a base/rover pair (or any set of receivers) measures, for tests and
benchmarks of the differential fix (:mod:`~leosop.positioning.differential`).
Each satellite's errors are drawn once (:func:`draw_satellite_errors`) and
shared by every receiver (:func:`simulate_receiver`):

- an element-set error, a constant offset in the satellite's radial /
  along-track / cross-track frame of its inertial orbit (built from its SGP4
  state); the true velocity is the time derivative of the offset
  position, so the rotating frame's velocity (~1 mm/s per metre of offset at
  the orbital rate) is in the truth too;
- the satellite's oscillator: a frequency offset and drift.

Optionally each receiver also measures the accumulated carrier phase, the
integral of the same Doppler model (cycles)::

    phase = -|r_s + e - r| f0 / c + (o_j + T) t + (o_j' + T') t^2 / 2 + phi + N + noise,

with the satellite's and the receiver's offsets ``o_j``, ``T`` and drifts
``o_j'``, ``T'`` (both integrated from ``errors.t0_utc``), the receiver's
phase ``phi`` common to its satellites and an integer ``N`` per arc (uniform
in +-10^6); a cycle slip starts a new arc with a new ``N``. The double
differences of two receivers are then whole cycles. The satellite's transmit
times at two receivers differ by ~baseline / c; its clock phase is taken at
the reception time (5 Hz over 30 us: 1e-4 cycles). The Doppler is the range
rate of the same states: the phase's rate agrees with it to ~0.03 Hz (the
offset's velocity is a central difference, the states' rate and velocity
differ by the light time's; ``tests/fusion/test_aids_differential.py``).
:func:`simulate_receiver` gives the rows of a measurement table (a moving
receiver, slips); :func:`simulate_phase` the same phase of a receiver at
rest as (n_sats, n_epochs) tracks.

Each receiver has its own position (at rest in ECEF, or a trajectory with
its velocity, e.g. :func:`straight_drive`), epochs, clock offset and drift,
white noise and elevation mask. The model states handed out with the
measurements are the element sets' (SGP4 with light time,
:func:`~leosop.positioning.measurements.sv_states_from_tle`), as a receiver
would compute them; the truth is those states plus the offset.
"""

from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS
from ..frames import C_e_n, azimuth_elevation_range, ecef_to_geodetic, range_rate
from ..orbits.propagate import state_ecef_pairs
from ..timebase import seconds_since
from .differential import ORBIT_SIGMA_RTN_M, rtn_frames
from .measurements import DEFAULT_CARRIER_HZ, Measurements, sv_states_from_tle

__all__ = [
    "SAT_DRIFT_SIGMA_HZ_PER_S",
    "SAT_OFFSET_MAX_HZ",
    "PhaseTracks",
    "SatelliteErrors",
    "draw_satellite_errors",
    "simulate_phase",
    "simulate_receiver",
    "straight_drive",
]

#: Satellite frequency offsets are uniform in +-this [Hz] ([Shen 2024] Table 1: 0-5 Hz).
SAT_OFFSET_MAX_HZ = 5.0
#: Default standard deviation of a satellite's frequency drift [Hz/s] (assumed: 1.5 Hz over a 150 s pass).
SAT_DRIFT_SIGMA_HZ_PER_S = 0.01
#: Step of the central difference that gives the offset's velocity [s].
_STEP_S = 0.5


@dataclass(frozen=True, eq=False)
class SatelliteErrors:
    """Errors of each satellite, the same for every receiver.

    Attributes
    ----------
    sat_ids : ndarray of str, (k,)
    orbit_rtn_m : ndarray, (k, 3)
        True minus element-set position, radial / along-track / cross-track [m].
    offset_hz : ndarray, (k,)
        Satellite frequency offset at ``t0_utc`` [Hz].
    drift_hz_per_s : ndarray, (k,)
    t0_utc : datetime64[ns]
        Reference time of the offsets (and of the receivers' clocks).
    """

    sat_ids: np.ndarray
    orbit_rtn_m: np.ndarray
    offset_hz: np.ndarray
    drift_hz_per_s: np.ndarray
    t0_utc: np.datetime64


def draw_satellite_errors(sat_ids, t0_utc, rng, *, orbit_sigma_rtn_m=ORBIT_SIGMA_RTN_M,
                          offset_max_hz=SAT_OFFSET_MAX_HZ, drift_sigma_hz_per_s=SAT_DRIFT_SIGMA_HZ_PER_S):
    """Draw each satellite's errors: Gaussian orbit offsets and drifts, uniform frequency offsets.

    Parameters
    ----------
    sat_ids : array_like of str, (k,)
    t0_utc : datetime64
    rng : numpy.random.Generator
    orbit_sigma_rtn_m : array_like, (3,)
    offset_max_hz, drift_sigma_hz_per_s : float

    Returns
    -------
    SatelliteErrors
    """
    ids = np.asarray(sat_ids, dtype=str)
    k = len(ids)
    return SatelliteErrors(
        sat_ids=ids, orbit_rtn_m=rng.standard_normal((k, 3)) * np.asarray(orbit_sigma_rtn_m, dtype=float),
        offset_hz=rng.uniform(-offset_max_hz, offset_max_hz, k),
        drift_hz_per_s=rng.normal(0.0, drift_sigma_hz_per_s, k), t0_utc=np.datetime64(t0_utc, "ns"))


def _rtn_offset(constellation, index, time_utc, orbit_rtn_m):
    """Offset ``orbit_rtn_m`` (m, 3) in ECEF at ``time_utc`` (m,): position (m, 3).

    In the inertial orbit's RTN frame (:func:`~leosop.positioning.differential.rtn_frames`),
    where an element set's error stays put.
    """
    pos, vel, _ = state_ecef_pairs(constellation, index, time_utc)
    return np.einsum("mij,mj->mi", rtn_frames(pos, vel)[0], orbit_rtn_m)


def straight_drive(start_ecef_m, heading_enu, speed_mps, t_s):
    """A vehicle at constant speed along a straight line of the local horizon.

    Parameters
    ----------
    start_ecef_m : array_like, (3,)
    heading_enu : array_like, (3,)
        Direction of travel, east / north / up (normalised here).
    speed_mps : float
    t_s : array_like, (n,)
        Seconds from the start.

    Returns
    -------
    pos_ecef_m, vel_ecef_mps : ndarray, (n, 3)
    """
    start = np.asarray(start_ecef_m, dtype=float).reshape(3)
    lat, lon, _ = ecef_to_geodetic(start)
    d = np.asarray(heading_enu, dtype=float)
    vel = C_e_n(lat, lon) @ (speed_mps * d / np.linalg.norm(d))
    t = np.asarray(t_s, dtype=float)[:, None]
    return start + vel * t, np.broadcast_to(vel, (t.shape[0], 3)).copy()


def _arcs(sat_rows, slip, rng):
    """Arc number of each row (rows time-ordered per satellite; ``slip`` (n,) bool starts a new arc at a row) and
    its integer ambiguity [cycles], a fresh draw in +-10^6 per arc."""
    arc = np.zeros(sat_rows.size, dtype=int)
    for j in np.unique(sat_rows):
        rows = np.flatnonzero(sat_rows == j)
        arc[rows] = np.cumsum(slip[rows] & (np.arange(rows.size) > 0))
    key = sat_rows * (arc.max(initial=0) + 1) + arc
    _, first = np.unique(key, return_inverse=True)
    return arc, rng.integers(-10**6, 10**6, first.max(initial=-1) + 1)[first].astype(float)


def simulate_receiver(constellation, errors, pos_rx_ecef_m, time_utc, rng, *, sigma_hz, vel_rx_ecef_mps=None,
                      clock_offset_hz=0.0, clock_drift_hz_per_s=0.0, mask_deg=10.0, carrier_hz=DEFAULT_CARRIER_HZ,
                      source="simulated", phase_sigma_cycles=None, slip_probability=0.0,
                      receiver_phase_cycles=0.0):
    """Doppler of the satellites of ``errors`` above ``mask_deg`` as one receiver measures them.

    Parameters
    ----------
    constellation : Constellation
        Element sets of (at least) the satellites of ``errors``.
    errors : SatelliteErrors
        Shared satellite errors; their ``t0_utc`` is also the reference
        time of the receiver clock.
    pos_rx_ecef_m : array_like, (3,) or (n, 3)
        The receiver at rest, or its position at each epoch.
    time_utc : array_like of datetime64, (n,)
        The receiver's epochs.
    vel_rx_ecef_mps : array_like, (n, 3), optional
        Its velocity at each epoch (default at rest).
    rng : numpy.random.Generator
        The receiver's noise.
    sigma_hz : float
        Standard deviation of the white measurement noise.
    clock_offset_hz, clock_drift_hz_per_s : float
        Receiver frequency offset at ``errors.t0_utc`` and its drift.
    mask_deg : float
        Elevation mask of this receiver (from the element-set states).
    carrier_hz : float
    source : str
        Name carried by the returned measurements.
    phase_sigma_cycles : float, optional
        Standard deviation of the white noise of the accumulated carrier
        phase (0.1 cycles is 2.6 mm at 11.325 GHz); None: no phase (and no
        draws from ``rng`` beyond the Doppler's).
    slip_probability : float
        Probability of a cycle slip at each row of a satellite after its
        first: a new arc with a new integer ambiguity.
    receiver_phase_cycles : float
        The receiver's phase, common to its satellites (``phi`` of the
        module's model; its fraction cancels in the double differences).

    Returns
    -------
    Measurements
        One row per visible satellite and epoch (epoch-major), ``time_utc``
        and ``t_s`` (seconds after ``errors.t0_utc``), the element-set
        states (light time included) and ``sigma_hz``; with
        ``phase_sigma_cycles`` also ``phase_cycles``, ``phase_sigma_cycles``
        and ``arc`` (the module's phase model).
    """
    t_ep = np.asarray(time_utc, dtype="datetime64[ns]")
    rx_ep = np.broadcast_to(np.asarray(pos_rx_ecef_m, dtype=float), (len(t_ep), 3))
    vrx_ep = np.zeros((len(t_ep), 3)) if vel_rx_ecef_mps is None else np.asarray(vel_rx_ecef_mps, float)
    lookup = {s: i for i, s in enumerate(constellation.sat_ids.tolist())}
    missing = [s for s in errors.sat_ids.tolist() if s not in lookup]
    if missing:
        raise ValueError(f"no element set for satellite {missing[0]}")
    index = np.array([lookup[s] for s in errors.sat_ids.tolist()], dtype=int)
    k = len(index)
    t_rows = np.repeat(t_ep, k)
    sat_rows = np.tile(np.arange(k), len(t_ep))
    ids = errors.sat_ids[sat_rows]
    rx, vrx = rx_ep[np.repeat(np.arange(len(t_ep)), k)], vrx_ep[np.repeat(np.arange(len(t_ep)), k)]
    pos_sv, vel_sv, reason = sv_states_from_tle(constellation, ids, t_rows, rx)
    _, elev, _ = azimuth_elevation_range(pos_sv, rx)
    keep = (reason == "") & (np.nan_to_num(elev, nan=-1.0) >= np.radians(mask_deg))
    t_rows, sat_rows, ids, pos_sv, vel_sv = t_rows[keep], sat_rows[keep], ids[keep], pos_sv[keep], vel_sv[keep]
    rx, vrx = rx[keep], vrx[keep]
    rtn = errors.orbit_rtn_m[sat_rows]
    h = np.timedelta64(int(_STEP_S * 1e9), "ns")
    off = _rtn_offset(constellation, index[sat_rows], t_rows, rtn)
    off_vel = (_rtn_offset(constellation, index[sat_rows], t_rows + h, rtn)
               - _rtn_offset(constellation, index[sat_rows], t_rows - h, rtn)) / (2.0 * _STEP_S)
    t_s = seconds_since(t_rows, errors.t0_utc)
    doppler = (-range_rate(pos_sv + off, vel_sv + off_vel, rx, vrx) * carrier_hz / C_MPS
               + errors.offset_hz[sat_rows] + errors.drift_hz_per_s[sat_rows] * t_s
               + clock_offset_hz + clock_drift_hz_per_s * t_s + sigma_hz * rng.standard_normal(len(t_s)))
    n = len(t_s)
    phase = {}
    if phase_sigma_cycles is not None:
        arc, ambiguity = _arcs(sat_rows, rng.random(n) < slip_probability, rng)
        osc_cycles = ((errors.offset_hz[sat_rows] + clock_offset_hz) * t_s
                      + 0.5 * (errors.drift_hz_per_s[sat_rows] + clock_drift_hz_per_s) * t_s**2)
        phase = {"phase_cycles": (-np.linalg.norm(pos_sv + off - rx, axis=-1) * carrier_hz / C_MPS + osc_cycles
                                  + receiver_phase_cycles + ambiguity + phase_sigma_cycles * rng.standard_normal(n)),
                 "phase_sigma_cycles": np.full(n, float(phase_sigma_cycles)), "arc": arc.astype(str)}
    return Measurements(t_s=t_s, time_utc=t_rows, sat_id=ids, doppler_hz=doppler, sigma_hz=np.full(n, float(sigma_hz)),
                        carrier_hz=np.full(n, float(carrier_hz)), pos_sv_ecef_m=pos_sv, vel_sv_ecef_mps=vel_sv,
                        line=np.arange(2, n + 2), source=source, **phase)


@dataclass(frozen=True, eq=False)
class PhaseTracks:
    """Accumulated carrier phase of the satellites of ``errors`` at one receiver, each array (n_sats, n_epochs).

    Attributes
    ----------
    phase_cycles, sigma_cycles : ndarray
        The phase (NaN below the mask) and its sigma.
    arc : ndarray of int
        0 where the satellite is above the mask (one arc, no slip), -1 elsewhere.
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n_sats, n_epochs, 3)
        The element-set states, their light time to ``pos_light_ecef_m`` (the model's, not the truth's).
    """

    phase_cycles: np.ndarray
    sigma_cycles: np.ndarray
    arc: np.ndarray
    pos_sv_ecef_m: np.ndarray
    vel_sv_ecef_mps: np.ndarray


def simulate_phase(constellation, errors, pos_rx_ecef_m, time_utc, rng, *, sigma_cycles, pos_light_ecef_m=None,
                   clock_offset_hz=0.0, clock_drift_hz_per_s=0.0, mask_deg=10.0, carrier_hz=DEFAULT_CARRIER_HZ):
    """:func:`simulate_receiver`'s carrier phase of a receiver at rest, without slips, as tracks per satellite.

    The receiver's phase ``phi`` is drawn uniform in a cycle (the single
    differences are not whole cycles, the double differences are).

    Parameters
    ----------
    constellation : Constellation
    errors : SatelliteErrors
    pos_rx_ecef_m : array_like, (3,)
    time_utc : array_like of datetime64, (n_epochs,)
        Increasing.
    rng : numpy.random.Generator
    sigma_cycles : float
        Standard deviation of the white phase noise.
    pos_light_ecef_m : array_like, (3,), optional
        Where the returned model states take their light time from (default the receiver: a rover's first guess).
    clock_offset_hz, clock_drift_hz_per_s, mask_deg, carrier_hz : float
        As :func:`simulate_receiver`'s.

    Returns
    -------
    PhaseTracks
        Each array (n_sats, n_epochs), the satellites in the order of ``errors.sat_ids``.
    """
    t_ep = np.asarray(time_utc, dtype="datetime64[ns]")
    if np.any(np.diff(t_ep) <= np.timedelta64(0, "ns")):
        raise ValueError("time_utc: the epochs must increase")
    rx = np.asarray(pos_rx_ecef_m, dtype=float).reshape(3)
    meas = simulate_receiver(constellation, errors, rx, t_ep, rng, sigma_hz=0.0, clock_offset_hz=clock_offset_hz,
                             clock_drift_hz_per_s=clock_drift_hz_per_s, mask_deg=mask_deg, carrier_hz=carrier_hz,
                             phase_sigma_cycles=sigma_cycles, receiver_phase_cycles=rng.uniform())
    k, n = len(errors.sat_ids), len(t_ep)
    order = np.argsort(errors.sat_ids)
    sat = order[np.searchsorted(errors.sat_ids[order], meas.sat_id)]
    epoch = np.searchsorted(t_ep, meas.time_utc)
    phase, arc = np.full((k, n), np.nan), np.full((k, n), -1)
    phase[sat, epoch], arc[sat, epoch] = meas.phase_cycles, meas.arc.astype(int)
    light = rx if pos_light_ecef_m is None else np.asarray(pos_light_ecef_m, dtype=float).reshape(3)
    pos_sv, vel_sv, _ = sv_states_from_tle(constellation, np.repeat(errors.sat_ids, n), np.tile(t_ep, k), light)
    return PhaseTracks(phase, np.full((k, n), float(sigma_cycles)), arc, pos_sv.reshape(k, n, 3),
                       vel_sv.reshape(k, n, 3))
