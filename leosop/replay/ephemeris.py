"""Satellite states for identification: one SGP4 propagation on a coarse grid, Hermite-interpolated.

Every satellite is propagated once on a grid of :data:`NODE_STEP_S` nodes
and interpolated by cubic Hermite polynomials (position and velocity at the
nodes); :meth:`Ephemeris.state_received` applies the light time as
:func:`leosop.positioning.measurements.sv_states_from_tle` does (state at
the transmit time, rotated into the ECEF frame of the reception time).
"""

import numpy as np

from ..constants import C_MPS, OMEGA_E_RAD_PER_S
from ..frames import rotate_to_later_ecef
from ..orbits.propagate import state_ecef

__all__ = ["Ephemeris", "doppler_model", "doppler_hz", "dot3", "NODE_STEP_S", "SPEED_SV_MPS"]

#: Node spacing of the propagated grid [s]: the cubic Hermite interpolation
#: of a LEO orbit errs ~1 mm in position and ~0.1 mm/s in velocity at 10 s.
NODE_STEP_S = 10.0
#: Satellite speed converting along-track errors to time offsets [m/s] (LEO at ~550 km).
SPEED_SV_MPS = 7600.0


class Ephemeris:
    """SGP4 states of all satellites on a time grid, Hermite-interpolated."""

    def __init__(self, constellation, t0_utc, span_s):
        pad = 2.0 * NODE_STEP_S
        n = int(np.ceil((span_s + 2 * pad) / NODE_STEP_S)) + 1
        self.t_grid_s = -pad + NODE_STEP_S * np.arange(n)
        times = t0_utc + np.round(self.t_grid_s * 1e9).astype("timedelta64[ns]")
        pos, vel, status = state_ecef(constellation, times)
        self.ok = (status == 0).all(axis=1) & np.isfinite(pos).all(axis=(1, 2))
        self.pos, self.vel = np.nan_to_num(pos), np.nan_to_num(vel)

    def state(self, sat, t_s):
        """Position and velocity (..., 3) of satellites ``sat`` at ``t_s`` (broadcast)."""
        x = (np.asarray(t_s, float) - self.t_grid_s[0]) / NODE_STEP_S
        i = np.clip(np.floor(x).astype(int), 0, len(self.t_grid_s) - 2)
        s = (x - i)[..., None]
        p0, p1 = self.pos[sat, i], self.pos[sat, i + 1]
        v0, v1 = self.vel[sat, i] * NODE_STEP_S, self.vel[sat, i + 1] * NODE_STEP_S
        s2, s3 = s * s, s * s * s
        pos = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * v0 + (3 * s2 - 2 * s3) * p1 + (s3 - s2) * v1
        vel = ((6 * s2 - 6 * s) * (p0 - p1) + (3 * s2 - 4 * s + 1) * v0 + (3 * s2 - 2 * s) * v1) / NODE_STEP_S
        return pos, vel

    def state_received(self, sat, t_s, pos_rx_ecef_m):
        """Apparent state: position at the transmit time in the ECEF frame of the reception time
        ``t_s``, velocity its derivative over reception time (as
        :func:`~leosop.positioning.measurements.sv_states_from_tle`)."""
        pos, vel = self.state(sat, t_s)
        for _ in range(2):  # each pass gains |range rate| / c ~ 3e-5
            tau = np.linalg.norm(pos - pos_rx_ecef_m, axis=-1) / C_MPS
            pos, vel = self.state(sat, t_s - tau)
        pos, vel = rotate_to_later_ecef(pos, tau), rotate_to_later_ecef(vel, tau)
        # d/dt_rx of R(omega tau) r(t_rx - tau): the light time's rate tau_dot = range rate / c
        # scales the velocity (up to ~6 Hz at Ku band) and turns the frame (< 0.5 Hz).
        los = pos - pos_rx_ecef_m
        tau_dot = np.sum(los * vel, axis=-1) / np.linalg.norm(los, axis=-1) / C_MPS
        turn = np.stack([pos[..., 1], -pos[..., 0], np.zeros_like(tau)], axis=-1)
        return pos, vel * (1 - tau_dot)[..., None] + (OMEGA_E_RAD_PER_S * tau_dot)[..., None] * turn


def doppler_model(pos_sv, vel_sv, pos_rx, hz_per_mps, los=False):
    """Doppler (...) and its gradient (..., 3) in the receiver position [Hz/m].

    ``vel_sv`` is relative to the receiver (satellite minus receiver
    velocity). With ``los`` the unit line of sight (..., 3) is returned too.
    """
    rng, u, rr = _range_rate(pos_sv, vel_sv, pos_rx)
    grad = hz_per_mps * (vel_sv - rr[..., None] * u) / rng[..., None]
    return (-hz_per_mps * rr, grad, u) if los else (-hz_per_mps * rr, grad)


def doppler_hz(pos_sv, vel_sv, pos_rx, hz_per_mps):
    """Doppler (...) alone, as the first output of :func:`doppler_model` (bit for bit)."""
    return -hz_per_mps * _range_rate(pos_sv, vel_sv, pos_rx)[2]


def _range_rate(pos_sv, vel_sv, pos_rx):
    """Range [m], unit line of sight (..., 3) and range rate [m/s] (...)."""
    los_m = pos_sv - pos_rx
    rng = np.sqrt(dot3(los_m, los_m))
    u = los_m / rng[..., None]
    return rng, u, dot3(u, vel_sv)


def dot3(a, b):
    """Dot products over the last axis of length 3, (...): as ``np.sum(a * b, axis=-1)`` bit for bit (the same
    sequential order), without the slow short-axis reduction."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]

