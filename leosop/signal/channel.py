"""From geometry to received samples: Doppler, Doppler rate, clocks, noise.

Two entry points:

:func:`doppler_blocks`
    Geometry-free. One block per row from arrays of Doppler, Doppler rate
    (and its change) and C/N0 at the block centres, as ``leosop simulate``
    needs once per satellite and epoch.
:class:`SiteChannel`
    Real geometry. SGP4 range rates from a static site on a node grid,
    joined by a cubic spline (error ~h^4 |d4 rr/dt4| / 384, far below a
    micrometre per second at 0.1 s nodes for LEO); each tone's phase is
    ``-f_k / c`` times the spline's exact integral, so the instantaneous
    Doppler at every sample is the range rate. (SGP4's velocity is not
    exactly the derivative of its position: they differ by ~1 cm/s, 0.3 Hz,
    so the phase must come from one of them alone.) Clock offsets (per satellite, seed
    004 Table 1: 0-5 Hz, and the receiver's) add a common frequency to every
    tone; several satellites are summed and complex white noise is added.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from ..constants import C_MPS
from ..errors import InputError
from .pilot import PilotComb, add_noise, comb_baseband, noise_sigma

__all__ = ["doppler_blocks", "site_range_rates", "SiteChannel"]


def doppler_blocks(sample_rate_hz, n_samples, doppler_hz, doppler_rate_hz_per_s=0.0, cn0_dbhz=None, *,
                   doppler_accel_hz_per_s2=0.0, comb=None, rng=None, dtype=np.complex64):
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


def site_range_rates(constellation, pos_rx_ecef_m, start_utc, duration_s, *, node_step_s=0.1):
    """Range rate of every satellite seen from a static site, on a node grid.

    Parameters
    ----------
    constellation : Constellation
    pos_rx_ecef_m : array_like, (3,)
    start_utc : datetime64
    duration_s : float
    node_step_s : float

    Returns
    -------
    t_nodes_s : ndarray, (n_nodes,)
        From ``start_utc``; one node beyond each end.
    range_rate_mps : ndarray, (n_sats, n_nodes)
        NaN where SGP4 fails.
    """
    from ..orbits.propagate import state_ecef

    n_nodes = int(np.ceil(duration_s / node_step_s)) + 3
    t_nodes = (np.arange(n_nodes) - 1) * node_step_s
    times = np.datetime64(start_utc, "ns") + np.round(t_nodes * 1e9).astype("timedelta64[ns]")
    pos, vel, _ = state_ecef(constellation, times)
    los = pos - np.asarray(pos_rx_ecef_m, dtype=float)
    return t_nodes, np.sum(los * vel, axis=-1) / np.linalg.norm(los, axis=-1)


@dataclass
class SiteChannel:
    """Pilot combs of several satellites received at a static site.

    Attributes
    ----------
    t_nodes_s : ndarray, (n_nodes,)
    range_rate_mps : ndarray, (n_sats, n_nodes)
        From :func:`site_range_rates`.
    sample_rate_hz : float
    cn0_dbhz : ndarray, (n_sats,)
        C/N0 per tone of each satellite.
    clock_offset_hz : ndarray, (n_sats,)
        Clock-induced frequency offset of each satellite plus the receiver's.
    comb : PilotComb
    phase_rad : ndarray, (n_sats,)
        Carrier phase of each satellite at t = 0.
    """

    t_nodes_s: np.ndarray
    range_rate_mps: np.ndarray
    sample_rate_hz: float
    cn0_dbhz: np.ndarray
    clock_offset_hz: np.ndarray
    comb: PilotComb = field(default_factory=PilotComb)
    phase_rad: np.ndarray | None = None

    def __post_init__(self):
        if not np.all(np.isfinite(self.range_rate_mps)):
            raise InputError("SGP4 failed for a satellite over the recording (decayed or bad elements)")
        n_sats = self.range_rate_mps.shape[0]
        self.cn0_dbhz = np.broadcast_to(np.asarray(self.cn0_dbhz, dtype=float), (n_sats,))
        self.clock_offset_hz = np.broadcast_to(np.asarray(self.clock_offset_hz, dtype=float), (n_sats,))
        self.phase_rad = np.zeros(n_sats) if self.phase_rad is None else np.asarray(self.phase_rad, dtype=float)
        self._rr = CubicSpline(self.t_nodes_s, self.range_rate_mps, axis=1)
        self._range = self._rr.antiderivative()
        self._range0 = self._range(0.0)

    @property
    def n_sats(self):
        return self.range_rate_mps.shape[0]

    def doppler_hz(self, t_s):
        """Central-tone Doppler of each satellite, clocks included, (n_sats, n)."""
        rr = self._rr(np.asarray(t_s, dtype=float))
        return -rr * self.comb.carrier_hz / C_MPS + self.clock_offset_hz[:, None]

    def doppler_rate_hz_per_s(self, t_s):
        """Rate of the central-tone Doppler, (n_sats, n)."""
        return -self._rr(np.asarray(t_s, dtype=float), 1) * self.comb.carrier_hz / C_MPS

    def noise_sigma(self):
        """Complex noise standard deviation per sample (the strongest satellite has unit tones)."""
        return noise_sigma(np.max(self.cn0_dbhz), self.sample_rate_hz)

    def samples(self, start, count, rng=None):
        """Received samples ``start .. start+count-1`` (complex128, (count,)), with noise if ``rng``.

        Successive calls continue the same phases, so a recording can be made
        chunk by chunk.
        """
        t = (start + np.arange(int(count))) / self.sample_rate_hz
        geom = -(self._range(t) - self._range0[:, None]) * self.comb.carrier_hz / C_MPS
        amp = 10.0 ** ((self.cn0_dbhz - np.max(self.cn0_dbhz)) / 20.0)
        iq = np.zeros(t.size, dtype=complex)
        for i in range(self.n_sats):
            iq += amp[i] * comb_baseband(self.comb, t, geom[i], self.clock_offset_hz[i] * t,
                                         phase_rad=self.phase_rad[i])
        if rng is not None:
            iq = add_noise(iq, np.max(self.cn0_dbhz), self.sample_rate_hz, rng)
        return iq
