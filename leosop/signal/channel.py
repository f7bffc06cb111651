"""From geometry to received samples: Doppler, Doppler rate, clocks, C/N0, noise.

Two entry points:

:func:`doppler_blocks`
    Geometry-free. One block per row from arrays of Doppler, Doppler rate
    (and its change) and C/N0 at the block centres, as ``leosop simulate``
    needs once per satellite and epoch.
:class:`SiteChannel`
    Real geometry. The received phase of the central tone at reception time
    t is ``-f_c / c`` times the light-time range rho(t) = c tau(t) =
    |R_z(omega_e tau) r_sv(t - tau) - r_rx|: the satellite's SGP4 position at
    emission, rotated into the Earth-fixed frame of reception (Sagnac), to
    the receiver at t (:func:`light_time_positions`, the same physics as
    :func:`leosop.positioning.measurements.sv_states_from_tle`). rho is
    solved exactly (iterated tau) on a node grid and joined by a cubic spline
    (error ~h^4 |d4 rho/dt4| / 384, ~1e-8 m at 0.1 s nodes for LEO); each
    tone's phase is ``-f_k / c`` times the spline, so the Doppler at every
    sample is ``-f_k / c`` times its exact derivative, the truth written to
    the annotations. (d rho/dt is the range rate at emission times
    (1 - rho'/c) plus a Sagnac-rate term: it differs from the range rate at
    reception by ~rate x 3 ms, several Hz.) Clock offsets (per satellite,
    [Shen 2024] Table 1: 0-5 Hz, and the receiver's) add a common frequency to
    every tone; several satellites are summed, each with its own C/N0 at
    every node (:func:`cn0_geometry_dbhz`, or constant), and complex white
    noise is added.

An :class:`OrbitError` makes the truth orbit differ from the element sets
the receiver will use: an along-track time offset and a constant radial /
cross-track shift per satellite.
"""

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline

from ..constants import C_MPS, OMEGA_E_RAD_PER_S
from ..errors import InputError
from ..frames import rotate_to_later_ecef
from ..kernels import compiled, pick
from .comb_phases import KERNEL_MODULE, comb_segments
from .pilot import PilotComb, add_noise, comb_baseband, noise_sigma

if TYPE_CHECKING:  # the orbits are imported where used (propagation is not needed to make IQ)
    from ..orbits.constellation import Constellation
    from .ofdm import FrameTimingJumps

__all__ = ["doppler_blocks", "OrbitError", "light_time_positions", "site_geometry",
           "cn0_geometry_dbhz", "inertial_speed_mps", "CN0_REF_RANGE_M", "SiteChannel"]

#: Range of the reference geometry of :func:`cn0_geometry_dbhz`: a Starlink shell (550 km) at zenith [m].
CN0_REF_RANGE_M = 550e3


#: Signal models of :class:`SiteChannel`.
WAVEFORMS = ("tones", "ofdm")
#: Doppler margin kept inside a narrow recording's band for OFDM subcarriers [Hz].
_MAX_OFDM_DOPPLER_HZ = 300e3

def doppler_blocks(sample_rate_hz: float, n_samples: int, doppler_hz: npt.ArrayLike,
                   doppler_rate_hz_per_s: npt.ArrayLike = 0.0, cn0_dbhz: npt.ArrayLike | None = None, *,
                   doppler_accel_hz_per_s2: npt.ArrayLike = 0.0,
                   comb: PilotComb | None = None, rng: np.random.Generator | None = None,
                   dtype: npt.DTypeLike = np.complex64) -> npt.NDArray[np.complexfloating]:
    """Pilot comb blocks, one per row, with given Doppler at each block centre.

    The central tone's frequency over block i is
    ``doppler_hz[i] + rate[i] tau + accel[i] tau^2 / 2`` (tau from the block
    centre); tone k's Doppler is s_k = f_k/f_c times that (clock offsets are
    taken as scaling too: a difference below 2e-4 Hz for 10 Hz of offset).
    Each block has a random common carrier phase.

    Parameters
    ----------
    sample_rate_hz : float
    n_samples : int
    doppler_hz, doppler_rate_hz_per_s, doppler_accel_hz_per_s2 : array_like, (n_blocks,) or scalar
    cn0_dbhz : array_like, (n_blocks,) or scalar, optional
        C/N0 per unit-amplitude tone; None for noise-free blocks.
    comb : PilotComb, optional
    rng : numpy.random.Generator, optional
        Needed for the noise and carrier phases (default: phase 0, no noise).
    dtype : numpy dtype
        complex64 (as read from cf32 recordings) or complex128.

    Returns
    -------
    iq : ndarray, (n_blocks, n_samples)
    """
    comb = comb or PilotComb()
    d, r, a = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float))
                                    for v in (doppler_hz, doppler_rate_hz_per_s, doppler_accel_hz_per_s2)))
    tau = (np.arange(int(n_samples)) - 0.5 * (n_samples - 1)) / sample_rate_hz
    cycles = d[:, None] * tau + r[:, None] * tau**2 / 2.0 + a[:, None] * tau**3 / 6.0
    phase = rng.uniform(0.0, 2.0 * np.pi, (d.size, 1)) if rng is not None else 0.0
    iq = comb_baseband(comb, tau, cycles, phase_rad=phase)
    if cn0_dbhz is not None:
        if rng is None:
            raise InputError("doppler_blocks: noise (cn0_dbhz) needs an rng")
        iq = add_noise(iq, np.broadcast_to(np.asarray(cn0_dbhz, dtype=float), d.shape), sample_rate_hz, rng)
    return iq.astype(dtype)


def _inertial_velocity(pos_ecef_m, vel_ecef_mps):
    """ECEF velocity plus omega_e x r: the inertial velocity in ECEF axes, (..., 3)."""
    x, y = pos_ecef_m[..., 0], pos_ecef_m[..., 1]
    return vel_ecef_mps + OMEGA_E_RAD_PER_S * np.stack([-y, x, np.zeros_like(x)], axis=-1)


@dataclass(frozen=True)
class OrbitError:
    """Truth orbit minus the element sets' orbit, per satellite.

    Attributes
    ----------
    along_s : ndarray, (n_sats,)
        Along-track time offset: the truth position at t is SGP4's inertial
        position at ``t + along_s``.
    radial_m, cross_m : ndarray, (n_sats,)
        Constant shift along the radial and cross-track (r x v, inertial v)
        axes of the satellite's RTN frame.
    """

    along_s: np.ndarray
    radial_m: np.ndarray
    cross_m: np.ndarray

    def __post_init__(self):
        arrays = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float))
                                       for v in (self.along_s, self.radial_m, self.cross_m)))
        for name, value in zip(("along_s", "radial_m", "cross_m"), arrays):
            object.__setattr__(self, name, value)

    @classmethod
    def draw(cls, rng, speed_mps, *, along_sigma_m=0.0, radial_sigma_m=0.0, cross_sigma_m=0.0):
        """Gaussian errors, one per satellite; along-track metres become a time offset.

        Parameters
        ----------
        rng : numpy.random.Generator
        speed_mps : array_like, (n_sats,)
            Inertial speed of each satellite (time offset = metres / speed).
        along_sigma_m, radial_sigma_m, cross_sigma_m : float
        """
        speed = np.atleast_1d(np.asarray(speed_mps, dtype=float))
        sigma_m = np.array([along_sigma_m, radial_sigma_m, cross_sigma_m], dtype=float)[:, None]
        err_m = rng.standard_normal((3, speed.size)) * sigma_m
        return cls(err_m[0] / speed, err_m[1], err_m[2])


def inertial_speed_mps(constellation, time_utc):
    """Inertial speed of every satellite at one instant, (n_sats,) (NaN where SGP4 fails)."""
    from ..orbits.propagate import state_ecef

    pos, vel, _ = state_ecef(constellation, np.array([time_utc], dtype="datetime64[ns]"))
    return np.linalg.norm(_inertial_velocity(pos[:, 0], vel[:, 0]), axis=-1)


def light_time_positions(constellation, pos_rx_ecef_m, times_utc, *, orbit_error=None, n_iter=3):
    """Satellite positions at emission, in the ECEF frame of reception, and the light time.

    Solves tau = |R_z(omega_e tau) r_sv(t - tau) - r_rx| / c by fixed-point
    iteration: each pass multiplies the error by |range rate| / c ~ 3e-5, so
    three passes leave ~1e-12 s (a range error ~1e-8 m). SGP4 takes
    nanosecond times; the sub-nanosecond remainder is added along the velocity.

    Parameters
    ----------
    constellation : Constellation
    pos_rx_ecef_m : array_like, (3,) or (n, 3)
        Receiver at the reception times (one row: static).
    times_utc : array_like of datetime64, (n,)
        Reception times.
    orbit_error : OrbitError, optional
        Truth minus element sets; None for the element sets' own orbit.
    n_iter : int

    Returns
    -------
    pos_sv_ecef_m : ndarray, (n_sats, n, 3)
        NaN where SGP4 fails.
    tau_s : ndarray, (n_sats, n)
    """
    from ..orbits.propagate import state_ecef_pairs

    t_rx = np.atleast_1d(np.asarray(times_utc, dtype="datetime64[ns]"))
    n_sats, n = len(constellation), t_rx.size
    err = orbit_error or OrbitError(np.zeros(n_sats), 0.0, 0.0)
    along_s, radial_m, cross_m = (np.repeat(np.broadcast_to(v, (n_sats,)), n)
                                  for v in (err.along_s, err.radial_m, err.cross_m))
    rx = np.asarray(pos_rx_ecef_m, dtype=float)
    if rx.ndim == 2:
        rx = np.tile(rx, (n_sats, 1))
    sat = np.repeat(np.arange(n_sats), n)
    t_all = np.tile(t_rx, n_sats)
    tau = np.zeros(n_sats * n)
    for _ in range(n_iter):
        delta_s = along_s - tau  # SGP4 time minus reception time
        delta_ns = np.round(delta_s * 1e9)
        p, v, _ = state_ecef_pairs(constellation, sat, t_all + delta_ns.astype("timedelta64[ns]"))
        p = p + v * (delta_s - delta_ns * 1e-9)[:, None]
        if np.any(radial_m) or np.any(cross_m):
            h = np.cross(p, _inertial_velocity(p, v))
            p = (p + radial_m[:, None] * p / np.linalg.norm(p, axis=-1, keepdims=True)
                 + cross_m[:, None] * h / np.linalg.norm(h, axis=-1, keepdims=True))
        p = rotate_to_later_ecef(p, -delta_s)
        tau = np.linalg.norm(p - rx, axis=-1) / C_MPS
    return p.reshape(n_sats, n, 3), tau.reshape(n_sats, n)


def site_geometry(constellation: "Constellation", pos_rx_ecef_m: npt.ArrayLike, start_utc: np.datetime64 | str,
                  duration_s: float, *, node_step_s: float = 0.1, orbit_error: "OrbitError | None" = None,
                  vel_rx_ecef_mps: npt.ArrayLike | None = None
                  ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Light-time range and elevation of every satellite seen from a receiver, on a node grid.

    Parameters
    ----------
    constellation : Constellation
    pos_rx_ecef_m : array_like, (3,)
        Receiver at ``start_utc``.
    start_utc : datetime64
    duration_s : float
    node_step_s : float
    orbit_error : OrbitError, optional
    vel_rx_ecef_mps : array_like, (3,), optional
        Constant receiver velocity (a straight line through ``pos_rx_ecef_m``);
        None for a static site.

    Returns
    -------
    t_nodes_s : ndarray, (n_nodes,)
        From ``start_utc``; one node before the start and two beyond the end.
    range_m : ndarray, (n_sats, n_nodes)
        c tau (:func:`light_time_positions`); NaN where SGP4 fails.
    elev_rad : ndarray, (n_sats, n_nodes)
        Elevation of the emission-time position.
    """
    from ..frames import azimuth_elevation_range

    n_nodes = int(np.ceil(duration_s / node_step_s)) + 3
    t_nodes = (np.arange(n_nodes, dtype=np.float64) - 1) * node_step_s
    times = np.asarray(start_utc, dtype="datetime64[ns]") + np.round(t_nodes * 1e9).astype("timedelta64[ns]")
    rx = np.asarray(pos_rx_ecef_m, dtype=float)
    if vel_rx_ecef_mps is not None:
        rx = rx + t_nodes[:, None] * np.asarray(vel_rx_ecef_mps, dtype=float)
    pos, tau = light_time_positions(constellation, rx, times, orbit_error=orbit_error)
    _, elev, _ = azimuth_elevation_range(pos, rx)
    return t_nodes, tau * C_MPS, elev


def cn0_geometry_dbhz(cn0_ref_dbhz, range_m, elev_rad, *, ref_range_m=CN0_REF_RANGE_M):
    """C/N0 from free-space loss and a flat receive array's elevation pattern.

    ``cn0 = cn0_ref + 20 log10(ref_range / range) + 10 log10(sin(elev))``:
    ``cn0_ref`` holds for a satellite at zenith at ``ref_range_m``; the
    pattern is the projected aperture of a flat phased array facing zenith
    (gain proportional to the cosine of the zenith angle), like a Starlink
    user terminal. Below the horizon the Earth blocks the signal (-inf).

    Parameters
    ----------
    cn0_ref_dbhz : float or array_like broadcastable to range_m
    range_m, elev_rad : array_like, same shape
    ref_range_m : float

    Returns
    -------
    cn0_dbhz : ndarray, shape of range_m
    """
    sin_el = np.sin(np.asarray(elev_rad, dtype=float))
    up = sin_el > 0
    pattern_db = np.full(sin_el.shape, -np.inf)
    pattern_db[up] = 10.0 * np.log10(sin_el[up])
    return cn0_ref_dbhz + 20.0 * np.log10(ref_range_m / np.asarray(range_m, dtype=float)) + pattern_db


@dataclass
class SiteChannel:
    """Pilot combs of several satellites received at a site (static or moving: ``range_m`` holds the motion).

    Attributes
    ----------
    t_nodes_s : ndarray, (n_nodes,)
    range_m : ndarray, (n_sats, n_nodes)
        Light-time range at the nodes (:func:`site_geometry`).
    sample_rate_hz : float
    cn0_dbhz : ndarray, (n_sats,) or (n_sats, n_nodes)
        C/N0 per tone of each satellite, constant or at every node (-inf: silent).
        Stored as (n_sats, n_nodes); linear in amplitude between nodes.
    clock_offset_hz : ndarray, (n_sats,)
        Clock-induced frequency offset of each satellite plus the receiver's
        at t = 0.
    comb : PilotComb
    phase_rad : ndarray, (n_sats,)
        Carrier phase of each satellite's central tone at t = 0 when the
        range is ``range_ref_m``.
    waveform : {"tones", "ofdm"}
        The pilot comb alone, or the full OFDM downlink frame with the comb
        at its channel centre (:class:`~leosop.signal.ofdm.OfdmDownlink`;
        each subcarrier as strong as one pilot tone; each satellite's data
        seeded by its index; frames aligned at transmission). In a narrow
        recording only the subcarriers that stay inside the band under
        +-300 kHz of Doppler are synthesised.
    rx_drift_hz_per_s : float
        Receiver LO frequency ramp, common to every satellite and tone: the
        receiver's offset at t is its offset at 0 plus this times t (a
        temperature drift of an LNB oscillator). It is part of every
        satellite's Doppler and Doppler rate (DESIGN 4.2: clocks included).
    sat_drift_hz_per_s : ndarray, (n_sats,), optional
        Each satellite oscillator's frequency drift: its offset at t is its
        part of ``clock_offset_hz`` plus this times t (None: no drift).
        Receivers of a base/rover pair share it, as they share the orbit.
    frame_jumps : FrameTimingJumps, optional
        OFDM only: frame-timing jumps, satellite i's drawn with seed
        ``(*frame_jumps.seed, i)`` (:class:`~leosop.signal.ofdm.FrameTimingJumps`).
    range_ref_m : ndarray, (n_sats,), optional
        The range at which each satellite's tones have their nominal phases
        (``phase_rad`` and the comb's): tone k's phase is ``-(f_c + k spacing)
        (range(t) - range_ref_m) / c`` cycles off them. None: the range at t = 0.
        Receivers that share it (and their satellites' ``phase_rad`` up to a
        receiver's own LO phase) see each satellite's phases differ by their
        ranges, as from one transmitter: double differences of the central
        tone's phase are the ranges' in cycles.
    kernel : {None, "numba", "numpy"}
        How :meth:`samples` synthesises the tones: compiled from polynomial
        phases (:mod:`~leosop.signal.combkernels`: within 1e-6 of a unit tone
        of the numpy path, ~4 ns per sample and satellite against ~100) or
        satellite by satellite with
        :func:`~leosop.signal.pilot.comb_baseband`; None: numba when installed.
    """

    t_nodes_s: np.ndarray
    range_m: np.ndarray
    sample_rate_hz: float
    cn0_dbhz: np.ndarray
    clock_offset_hz: np.ndarray
    comb: PilotComb = field(default_factory=PilotComb)
    phase_rad: np.ndarray | None = None
    waveform: str = "tones"
    rx_drift_hz_per_s: float = 0.0
    sat_drift_hz_per_s: np.ndarray | None = None
    frame_jumps: "FrameTimingJumps | None" = None
    range_ref_m: np.ndarray | None = None
    kernel: str | None = None

    def __post_init__(self):
        if not np.all(np.isfinite(self.range_m)):
            raise InputError("SGP4 failed for a satellite over the recording (decayed or bad elements)")
        n_sats = self.range_m.shape[0]
        cn0 = np.asarray(self.cn0_dbhz, dtype=float)
        cn0 = cn0[:, None] if cn0.ndim == 1 else cn0
        self.cn0_dbhz = np.broadcast_to(cn0, self.range_m.shape)
        finite = np.isfinite(self.cn0_dbhz)
        if not finite.any() or np.any(self.cn0_dbhz[~finite] != -np.inf):
            raise InputError("C/N0 must be finite (or -inf for silence) and finite somewhere")
        self.clock_offset_hz = np.broadcast_to(np.asarray(self.clock_offset_hz, dtype=float), (n_sats,))
        self.phase_rad = np.zeros(n_sats) if self.phase_rad is None else np.asarray(self.phase_rad, dtype=float)
        drift = 0.0 if self.sat_drift_hz_per_s is None else np.asarray(self.sat_drift_hz_per_s, dtype=float)
        self.sat_drift_hz_per_s = np.broadcast_to(drift, (n_sats,))
        self._range = CubicSpline(self.t_nodes_s, self.range_m, axis=1)
        self._range0 = self._range(0.0)
        if self.range_ref_m is None:
            self.range_ref_m = self._range0
        self.range_ref_m = np.broadcast_to(np.asarray(self.range_ref_m, dtype=float), (n_sats,))
        self._cn0_ref = float(np.max(self.cn0_dbhz[finite]))
        self._amp = 10.0 ** ((self.cn0_dbhz - self._cn0_ref) / 20.0)
        if self.waveform not in WAVEFORMS:
            raise InputError(f"waveform={self.waveform!r} must be one of {', '.join(WAVEFORMS)}")
        pick(self.kernel, KERNEL_MODULE)  # refuses an unknown kernel, and numba where it is not installed
        self._ofdm = None
        if self.frame_jumps is not None and self.waveform != "ofdm":
            raise InputError("frame-timing jumps need waveform='ofdm' (the tones have no frames)")
        if self.waveform == "ofdm":
            from .ofdm import OfdmDownlink

            band = self.sample_rate_hz - 2.0 * _MAX_OFDM_DOPPLER_HZ
            band = band if band > 0 else self.sample_rate_hz
            self._ofdm = [OfdmDownlink(self.sample_rate_hz, channel_hz=self.comb.carrier_hz, seed=i, comb=self.comb,
                                       band_hz=band, timing_jumps=self._jumps(i)) for i in range(n_sats)]

    def _jumps(self, i):
        """Satellite i's frame-timing jumps, or None."""
        if self.frame_jumps is None:
            return None
        return replace(self.frame_jumps, seed=(*np.atleast_1d(self.frame_jumps.seed).tolist(), i))

    def frame_jumps_truth(self, i, duration_s):
        """Satellite i's frame-timing jumps within ``duration_s``: receive times [s] and steps [s], ((n,), (n,)).

        The receive time is where the frame clock (transmit time) reaches
        the jump: ``t - (range(t) - range(0)) / c``, solved by iteration
        (each step divides the error by c / range rate, ~4e4).
        """
        link = self._ofdm[i] if self._ofdm is not None else None
        if link is None or link.timing_jumps is None:
            return np.zeros(0), np.zeros(0)
        jumps = link.timing_jumps
        tau = jumps.period_s * np.arange(1, int(np.floor(duration_s / jumps.period_s)) + 2)
        t = tau.copy()
        for _ in range(3):
            t = tau + link.frame_offset_s + (self._range(t)[i] - self._range0[i]) / C_MPS
        keep = (t >= 0) & (t < duration_s)
        return t[keep], jumps.steps_s(tau.size)[keep]

    @property
    def n_subcarriers(self):
        """OFDM subcarriers synthesised per satellite (0 for the tones alone)."""
        return 0 if self._ofdm is None else int(self._ofdm[0].subcarriers.size)

    @property
    def n_sats(self):
        return self.range_m.shape[0]

    def doppler_hz(self, t_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Central-tone Doppler of each satellite, clocks included, (n_sats, n)."""
        t = np.asarray(t_s, dtype=float)
        rr = self._range(t, 1)
        return -rr * self.comb.carrier_hz / C_MPS + self.clock_offset_hz[:, None] + self._drift_hz_per_s()[:, None] * t

    def doppler_rate_hz_per_s(self, t_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Rate of the central-tone Doppler, (n_sats, n)."""
        rate = -self._range(np.asarray(t_s, dtype=float), 2) * self.comb.carrier_hz / C_MPS
        return rate + self._drift_hz_per_s()[:, None]

    def _drift_hz_per_s(self):
        """Clock drift in each satellite's Doppler, the receiver's plus the satellite's, (n_sats,)."""
        return self.rx_drift_hz_per_s + self.sat_drift_hz_per_s

    def amplitude(self, t_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Tone amplitude of each satellite (1 at the strongest node of all), (n_sats, n)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        k = np.clip(np.searchsorted(self.t_nodes_s, t, side="right") - 1, 0, self.t_nodes_s.size - 2)
        w = (t - self.t_nodes_s[k]) / (self.t_nodes_s[k + 1] - self.t_nodes_s[k])
        return self._amp[:, k] * (1.0 - w) + self._amp[:, k + 1] * w

    def cn0_at(self, t_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """C/N0 per tone of each satellite [dB-Hz], -inf when silent, (n_sats, n)."""
        with np.errstate(divide="ignore"):
            return self._cn0_ref + 20.0 * np.log10(self.amplitude(t_s))

    @property
    def cn0_ref_dbhz(self):
        """C/N0 of a unit-amplitude tone: the strongest node's, the scale of :meth:`samples`."""
        return self._cn0_ref

    def noise_sigma(self):
        """Complex noise standard deviation per sample (the strongest node has unit tones)."""
        return noise_sigma(self._cn0_ref, self.sample_rate_hz)

    def samples(self, start, count, rng=None):
        """Received samples ``start .. start+count-1`` (complex128, (count,)), with noise if ``rng``.

        Sample i is at ``i / sample_rate_hz`` seconds after the channel's
        t = 0; any calls, adjacent or far apart, continue the same phases, so a
        recording can be made chunk by chunk or snapshot by snapshot.
        """
        kernels = compiled(KERNEL_MODULE) if self._ofdm is None and self.kernel != "numpy" else None
        iq = np.zeros(int(count), dtype=complex)
        if kernels is not None:
            coef = self.comb.tone_amplitudes * np.exp(1j * self.comb.tone_phases_rad)
            kernels.add_comb_segments(coef, *comb_segments(self, start, count), iq)
        else:
            t = (start + np.arange(int(count))) / self.sample_rate_hz
            geom = -(self._range(t) - self.range_ref_m[:, None]) * self.comb.carrier_hz / C_MPS
            amp = self.amplitude(t)
            drift = self._drift_hz_per_s()
            for i in np.flatnonzero(np.any(amp > 0, axis=1)):
                clock_cycles = self.clock_offset_hz[i] * t + 0.5 * drift[i] * t**2
                if self._ofdm is None:
                    iq += amp[i] * comb_baseband(self.comb, t, geom[i], clock_cycles, phase_rad=self.phase_rad[i])
                else:
                    iq += amp[i] * self._ofdm[i].samples(t, geom[i], clock_cycles, phase_rad=self.phase_rad[i])
        if rng is not None:
            iq = add_noise(iq, self._cn0_ref, self.sample_rate_hz, rng)
        return iq
