"""Satellite states for identification: one SGP4 propagation on a coarse grid, Hermite-interpolated.

Every satellite is propagated once on a grid of :data:`NODE_STEP_S` nodes
and interpolated by cubic Hermite polynomials (position and velocity at the
nodes); :meth:`Ephemeris.state_received` applies the light time as
:func:`leosop.positioning.measurements.sv_states_from_tle` does (state at
the transmit time, rotated into the ECEF frame of the reception time).

A satellite's time offset ``shift_s`` (its element set's along-track error)
is one of its inertial orbit, as the generator injects it
(:class:`leosop.signal.channel.OrbitError`) and the static fix models it
(:func:`leosop.geometry.doppler.doppler_rate` with ``inertial``): the
satellite is where its orbit puts it at ``t + shift_s`` while the Earth has
turned only until ``t``, i.e. its ECEF state at ``t + shift_s`` turned east
by ``omega_e shift_s``. The ECEF state at ``t + shift_s`` alone (a shift
along the ground track) misplaces it by ``omega_e |r| shift_s``, ~7 % of the
along-track shift.
"""

import numpy as np

from ..constants import C_MPS, OMEGA_E_RAD_PER_S
from ..frames import rotate_to_later_ecef
from ..orbits.propagate import state_ecef

__all__ = ["Ephemeris", "doppler_model", "doppler_hz", "dot3", "NODE_STEP_S", "SPEED_SV_MPS", "RATE_STEP_S"]

#: Node spacing of the propagated grid [s]: the cubic Hermite interpolation
#: of a LEO orbit errs ~1 mm in position and ~0.1 mm/s in velocity at 10 s.
NODE_STEP_S = 10.0
#: Satellite speed converting along-track errors to time offsets [m/s] (LEO at ~550 km).
SPEED_SV_MPS = 7600.0
#: Half step of the central difference giving the Doppler's rate in a satellite's time offset [s].
RATE_STEP_S = 0.5


class Ephemeris:
    """SGP4 states of all satellites on a time grid, Hermite-interpolated."""

    def __init__(self, constellation, t0_utc, span_s):
        pad = 2.0 * NODE_STEP_S
        n = int(np.ceil((span_s + 2 * pad) / NODE_STEP_S)) + 1
        self.t_grid_s = -pad + NODE_STEP_S * np.arange(n)
        times = t0_utc + np.round(self.t_grid_s * 1e9).astype("timedelta64[ns]")
        pos, vel, status = state_ecef(constellation, times)
        self.ok = (status == 0).all(axis=1) & np.isfinite(pos).all(axis=(1, 2))
        # The nodes' positions and velocities times the step (the Hermite tangents), one row per
        # (satellite, node), (n_sats * n_nodes, 3): a row gather (take) is twice as fast as indexing two axes.
        self._pos_rows = np.nan_to_num(pos).reshape(-1, 3)
        self._tangent_rows = (np.nan_to_num(vel) * NODE_STEP_S).reshape(-1, 3)

    def state(self, sat, t_s):
        """Position and velocity (..., 3) of satellites ``sat`` at ``t_s`` (broadcast)."""
        return self._state(sat, t_s)[:2]

    def _state(self, sat, t_s, prev=None):
        """:meth:`state` and the nodes it interpolated, ``(row, nodes)``, for a later call's ``prev``.

        With ``prev`` from a call of the same shape (the same satellites at nearby times: the light-time
        iterations, the two sides of a central difference) only the rows whose node changed are gathered
        anew; the values are those a gather of every row gives.
        """
        n_nodes = len(self.t_grid_s)
        x = (np.asarray(t_s, float) - self.t_grid_s[0]) / NODE_STEP_S
        i = np.clip(np.floor(x).astype(int), 0, n_nodes - 2)
        s = (x - i)[..., None]
        row = np.asarray(sat) * n_nodes + i
        p0, v0, p1, v1 = nodes = self._nodes(row, prev)
        s2, s3 = s * s, s * s * s
        pos = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * v0 + (3 * s2 - 2 * s3) * p1 + (s3 - s2) * v1
        vel = ((6 * s2 - 6 * s) * (p0 - p1) + (3 * s2 - 4 * s + 1) * v0 + (3 * s2 - 2 * s) * v1) / NODE_STEP_S
        return pos, vel, (row, nodes)

    def _nodes(self, row, prev=None):
        """Positions and tangents at the nodes ``row`` and ``row + 1``: (p0, v0, p1, v1), each (..., 3)."""
        tables = (self._pos_rows, self._tangent_rows, self._pos_rows, self._tangent_rows)
        if prev is not None and prev[0].shape == row.shape:
            old_row, old = prev
            changed = np.flatnonzero(row != old_row)
            if changed.size == 0:
                return old
            if 4 * changed.size < row.size:  # a few rows crossed a node: patch them
                new = tuple(a.copy() for a in old)
                r = row.reshape(-1)[changed]
                for a, table, step in zip(new, tables, (0, 0, 1, 1)):
                    a.reshape(-1, 3)[changed] = table.take(r + step, axis=0)
                return new
        return tuple(table.take(row + step, axis=0) for table, step in zip(tables, (0, 0, 1, 1)))

    def state_shifted(self, sat, t_s, shift_s):
        """Position and velocity (..., 3) at ``t_s`` of satellites ``sat`` whose inertial orbit is
        ``shift_s`` ahead (broadcast): the ECEF state at ``t_s + shift_s`` in the ECEF frame of ``t_s``."""
        return self._state_shifted(sat, t_s, shift_s)[:2]

    def _state_shifted(self, sat, t_s, shift_s, prev=None):
        """:meth:`state_shifted` and its nodes (:meth:`_state`)."""
        shift_s = np.asarray(shift_s, float)
        pos, vel, nodes = self._state(sat, np.asarray(t_s, float) + shift_s, prev)
        return rotate_to_later_ecef(pos, -shift_s), rotate_to_later_ecef(vel, -shift_s), nodes

    def state_received(self, sat, t_s, pos_rx_ecef_m, shift_s=0.0):
        """Apparent state: position at the transmit time in the ECEF frame of the reception time
        ``t_s``, velocity its derivative over reception time (as
        :func:`~leosop.positioning.measurements.sv_states_from_tle`); the inertial orbit
        ``shift_s`` ahead (broadcast, see :meth:`state_shifted`)."""
        shift_s = np.asarray(shift_s, float)
        pos, vel, nodes = self._state(sat, t_s + shift_s)
        for _ in range(2):  # each pass gains |range rate| / c ~ 3e-5
            tau = np.linalg.norm(pos - pos_rx_ecef_m, axis=-1) / C_MPS
            pos, vel, nodes = self._state(sat, t_s - tau + shift_s, nodes)
        # The transmit-time state of the shifted orbit (frame of t_s - tau + shift_s) in the frame of t_s.
        pos, vel = rotate_to_later_ecef(pos, tau - shift_s), rotate_to_later_ecef(vel, tau - shift_s)
        # d/dt_rx of R(omega tau) r(t_rx - tau): the light time's rate tau_dot = range rate / c
        # scales the velocity (up to ~6 Hz at Ku band) and turns the frame (< 0.5 Hz).
        los = pos - pos_rx_ecef_m
        tau_dot = np.sum(los * vel, axis=-1) / np.linalg.norm(los, axis=-1) / C_MPS
        turn = np.stack([pos[..., 1], -pos[..., 0], np.zeros_like(tau)], axis=-1)
        return pos, vel * (1 - tau_dot)[..., None] + (OMEGA_E_RAD_PER_S * tau_dot)[..., None] * turn

    def doppler_shift_rate(self, sat, t_s, shift_s, pos_rx_ecef_m, hz_per_mps):
        """Derivative of the Doppler (...) [Hz/s] in the satellite's inertial time offset ``shift_s``:
        a central difference over +-:data:`RATE_STEP_S` of :meth:`state_shifted` (light time left out)."""
        pa, va, nodes = self._state_shifted(sat, t_s, shift_s + RATE_STEP_S)
        pb, vb, _ = self._state_shifted(sat, t_s, shift_s - RATE_STEP_S, nodes)
        return (doppler_hz(pa, va, pos_rx_ecef_m, hz_per_mps)
                - doppler_hz(pb, vb, pos_rx_ecef_m, hz_per_mps)) / (2 * RATE_STEP_S)


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

