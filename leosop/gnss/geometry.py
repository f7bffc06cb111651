"""Receiver-satellite range and range rate from precise orbits: light time and Sagnac.

The satellite is taken at transmission time ``t - tau`` (``tau`` by fixed
point: two iterations reach 1e-9 s from 0.07 s) and expressed in the ECEF
frame of the reception time (:func:`leosop.frames.rotate_to_later_ecef`).
The range rate is the time derivative of that same range for a receiver
moving at constant velocity, by a central difference over ``2 h_s`` (the
range is a smooth function of time: with ``h_s = 0.05 s`` the truncation
error is ~1e-7 m/s), so that simulated observations and a filter's
predictions use one definition.
"""

import numpy as np

from ..constants import C_MPS
from ..frames import rotate_to_later_ecef
from .models import relativistic_clock_s

__all__ = ["satellite_at_reception", "range_and_rate", "satellite_clock"]


def satellite_at_reception(orbits, sv_idx, t_s, pos_rx_ecef_m, *, iterations=2):
    """Satellite positions at transmission, in the ECEF frame at reception.

    Parameters
    ----------
    orbits : leosop.gnss.products.Orbits
    sv_idx : ndarray of int, shape (n,)
    t_s : float or ndarray, shape (n,)
        Reception times, seconds since ``orbits.ref_gps``.
    pos_rx_ecef_m : ndarray, shape (3,) or (n, 3)

    Returns
    -------
    pos_sv_ecef_m : ndarray, shape (n, 3)
    tau_s : ndarray, shape (n,)
    """
    sv_idx = np.asarray(sv_idx, int)
    t = np.broadcast_to(np.asarray(t_s, float), sv_idx.shape)
    tau = np.full(sv_idx.shape, 0.075)
    for _ in range(iterations + 1):
        rs = rotate_to_later_ecef(orbits.position(sv_idx, t - tau), tau)
        tau = np.linalg.norm(rs - pos_rx_ecef_m, axis=-1) / C_MPS
    return rotate_to_later_ecef(orbits.position(sv_idx, t - tau), tau), tau


def range_and_rate(orbits, sv_idx, t_s, pos_rx_ecef_m, vel_rx_ecef_mps, *, h_s=0.05):
    """Geometric range, its rate and the line of sight.

    Parameters
    ----------
    orbits : leosop.gnss.products.Orbits
    sv_idx : ndarray of int, shape (n,)
    t_s : float or ndarray, shape (n,)
        Reception times, seconds since ``orbits.ref_gps``.
    pos_rx_ecef_m, vel_rx_ecef_mps : ndarray, shape (3,) or (n, 3)
        One receiver, or one per row (many epochs in one call).

    Returns
    -------
    rho_m, rate_mps : ndarray, shape (n,)
    los_ecef : ndarray, shape (n, 3)
        Unit vectors from the receiver to the satellites.
    pos_sv_ecef_m : ndarray, shape (n, 3)
    """
    sv_idx = np.asarray(sv_idx, int)
    n = sv_idx.size
    pos_rx_ecef_m = np.broadcast_to(np.asarray(pos_rx_ecef_m, float), (n, 3))
    vel = np.broadcast_to(np.asarray(vel_rx_ecef_mps, float), (n, 3))
    steps = np.repeat([0.0, -h_s, h_s], n)  # the three instants in one interpolation
    p = np.tile(pos_rx_ecef_m, (3, 1)) + steps[:, None] * np.tile(vel, (3, 1))
    rs, _ = satellite_at_reception(orbits, np.tile(sv_idx, 3),
                                   np.tile(np.broadcast_to(np.asarray(t_s, float), (n,)), 3) + steps, p)
    rng = np.linalg.norm(rs - p, axis=-1)
    d = rs[:n] - pos_rx_ecef_m
    return rng[:n], (rng[2 * n:] - rng[n:2 * n]) / (2.0 * h_s), d / rng[:n, None], rs[:n]


def satellite_clock(orbits, clocks, orb_idx, clk_idx, t_tx_s, *, h_s=0.5):
    """Satellite clock offset and drift in metres (``c dt_sv``), relativistic term included.

    Parameters
    ----------
    orbits : leosop.gnss.products.Orbits
    clocks : leosop.gnss.products.Clocks
        Both on the same time origin.
    orb_idx, clk_idx : ndarray of int, shape (n,)
    t_tx_s : ndarray, shape (n,)
        Transmission times.

    Returns
    -------
    clk_m, drift_mps : ndarray, shape (n,)
        Drift by central difference over ``2 h_s`` (the clock product is
        linear between its 30 s records).
    """
    t = np.asarray(t_tx_s, float)
    n = t.size
    t3 = np.concatenate([t, t - h_s, t + h_s])
    o3, c3 = np.tile(orb_idx, 3), np.tile(clk_idx, 3)
    pos, vel = orbits.state(o3, t3)
    clk = C_MPS * (clocks.bias(c3, t3) + relativistic_clock_s(pos, vel))
    return clk[:n], (clk[2 * n:] - clk[n:2 * n]) / (2.0 * h_s)
