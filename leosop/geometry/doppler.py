"""The Doppler measurement model: its Jacobian rows and its rate ([Shen 2024] eq. 4-9).

Model (the toolkit's sign, see :mod:`leosop`)::

    doppler_hz = -(f0 / c) * (v_s - v_r) . (r_s - r_r) / |r_s - r_r| + T_u

State ``[x, y, z, vx, vy, vz, T_u]`` (ECEF m, m/s, Hz). Its Jacobian is
[Shen 2024] eq. 8-9 with the position and velocity columns negated (the paper
writes the carrier with the opposite sign of the range-rate term).
"""

import numpy as np

from ..constants import C_MPS, GM_M3_PER_S2, OMEGA_E_RAD_PER_S

__all__ = ["N_DOPPLER_STATES", "doppler_jacobian", "clock_group_rows", "doppler_rate", "sv_motion"]

#: States of a Doppler snapshot fix: position (3), velocity (3), one receiver frequency offset; so a
#: snapshot needs at least 7 satellites ([Shen 2024] eq. 4-7).
N_DOPPLER_STATES = 7


def doppler_jacobian(pos_sv_ecef_m, vel_sv_ecef_mps, pos_rx_ecef_m, vel_rx_ecef_mps, carrier_hz):
    """Rows of H: derivative of each satellite's Doppler w.r.t. the receiver state.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (..., n_sv, 3)
    pos_rx_ecef_m, vel_rx_ecef_mps : array_like, (..., 3)
    carrier_hz : float or array_like, broadcastable to (..., n_sv)

    Returns
    -------
    H : ndarray, (..., n_sv, 7)
        Columns d/dr_rx [Hz/m], d/dv_rx [Hz/(m/s)], d/dT_u [1].
    """
    r_s = np.asarray(pos_sv_ecef_m, dtype=float)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float)
    dr = np.asarray(pos_rx_ecef_m, dtype=float)[..., None, :] - r_s
    dv = np.asarray(vel_rx_ecef_mps, dtype=float)[..., None, :] - v_s
    rho = np.linalg.norm(dr, axis=-1, keepdims=True)
    u = dr / rho
    k = -np.asarray(carrier_hz, dtype=float)[..., None] / C_MPS
    d_pos = k * (dv - u * np.sum(u * dv, axis=-1, keepdims=True)) / rho
    d_vel = k * u
    return np.concatenate([d_pos, d_vel, np.ones(d_pos.shape[:-1] + (1,))], axis=-1)


def clock_group_rows(H, clock_onehot):
    """Doppler rows of a state with one receiver frequency offset per clock group (e.g. constellation).

    Parameters
    ----------
    H : ndarray, (..., n_sv, 7)
        Rows of :func:`doppler_jacobian`.
    clock_onehot : array_like, (..., n_sv, k)
        1 where a row belongs to clock group g (padding rows: all 0).

    Returns
    -------
    ndarray, (..., n_sv + k, 6 + k)
        Columns position, velocity, ``T_u[0..k-1]``. The last k rows are
        pseudo-measurements of each clock state alone: weighted 1 for a clock
        no satellite of the epoch sees, 0 otherwise, they keep the state
        determined without counting as a measurement of the others.
    """
    onehot = np.asarray(clock_onehot, dtype=float)
    k = onehot.shape[-1]
    pseudo = np.broadcast_to(np.eye(6 + k)[6:], H.shape[:-2] + (k, 6 + k))
    return np.concatenate([np.concatenate([H[..., :6], onehot], -1), pseudo], -2)


def doppler_rate(pos_sv_ecef_m, vel_sv_ecef_mps, pos_rx_ecef_m, carrier_hz, vel_rx_ecef_mps=None, *, inertial=False,
                 motion=None):
    """Rate of the Doppler, and its gradient w.r.t. the receiver position.

    The satellite's ECEF acceleration is two-body gravity plus the frame's
    centrifugal and Coriolis terms (J2 changes it by ~0.1 %); the receiver's
    acceleration is neglected. At rest the rate is ``d(doppler)/d(dt)`` for
    a time offset ``dt`` of the satellite states.

    With ``inertial`` the offset is one of the satellite's inertial orbit
    (an element set's along-track error: the satellite is where its orbit
    puts it at ``t + dt`` while the Earth has turned only until ``t``): its
    ECEF states at ``t + dt`` turned east about the Earth's axis by
    ``omega_e dt``, i.e. the ECEF derivative plus ``(omega x r, omega x v)``.
    The two differ by ``omega_e |r| / |v|`` ~ 7 % of the along-track shift
    (25 m east for 380 m, several Hz of Doppler at Ku band); the ECEF rate
    is the derivative in time of what a receiver at rest sees.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (m, 3)
    pos_rx_ecef_m : array_like, (..., 3)
    carrier_hz : float or array_like, (m,)
    vel_rx_ecef_mps : array_like, (..., 3) or (m, 3), optional
        Receiver velocity; default at rest in ECEF.
    inertial : bool
        Derivative for a time offset of the satellite's inertial orbit
        rather than of its ECEF states (the receiver's motion then not
        included).
    motion : tuple of ndarray, optional
        :func:`sv_motion` of these satellites with the same ``inertial``
        (computed here when not given).

    Returns
    -------
    rate_hz_per_s : ndarray, (..., m)
    grad_hz_per_s_m : ndarray, (..., m, 3)
    """
    r_s = np.asarray(pos_sv_ecef_m, dtype=float)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float)
    # Per second of offset the geometry moves along (w, a_s): the relative ECEF velocity and the satellite's
    # acceleration, or for an inertial offset the satellite's alone plus the Earth's turn (omega x r, omega x v).
    w, a_s = sv_motion(r_s, v_s, inertial=inertial) if motion is None else motion
    if vel_rx_ecef_mps is not None:
        v_rel = v_s - np.asarray(vel_rx_ecef_mps, dtype=float)
    else:
        v_rel = v_s
    if not inertial:
        w = v_rel
    v_s = v_rel
    dr = r_s - np.asarray(pos_rx_ecef_m, dtype=float)[..., None, :]
    rho = np.linalg.norm(dr, axis=-1, keepdims=True)
    u = dr / rho
    rho_dot = np.sum(u * v_s, axis=-1, keepdims=True)
    u_w = np.sum(u * w, axis=-1, keepdims=True)
    u_a = np.sum(u * a_s, axis=-1, keepdims=True)
    v_w = np.sum(v_s * w, axis=-1, keepdims=True)
    k = -np.asarray(carrier_hz, dtype=float)[..., None] / C_MPS
    rate = k * ((v_w - rho_dot * u_w) / rho + u_a)
    grad = k * ((u_w * (v_s - u * rho_dot) + rho_dot * (w - u * u_w) + (v_w - rho_dot * u_w) * u) / rho**2
                - (a_s - u * u_a) / rho)
    return rate[..., 0], grad


def sv_motion(pos_sv_ecef_m, vel_sv_ecef_mps, *, inertial=False):
    """The satellites' own terms of :func:`doppler_rate`: how each moves per second of a time offset.

    The ECEF acceleration is two-body gravity plus the frame's centrifugal and
    Coriolis terms; with ``inertial`` the velocity and acceleration of an
    offset along the inertial orbit (those plus ``(omega x r, omega x v)``,
    see :func:`doppler_rate`). They do not depend on the receiver: an
    iterated fix, whose satellites stay while the receiver moves, computes
    them once.

    Parameters
    ----------
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (m, 3)
    inertial : bool

    Returns
    -------
    vel_ecef_mps, accel_ecef_mps2 : ndarray, (m, 3)
    """
    r_s = np.asarray(pos_sv_ecef_m, dtype=float)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float)
    omega = np.array([0.0, 0.0, OMEGA_E_RAD_PER_S])
    a_s = (-GM_M3_PER_S2 * r_s / np.linalg.norm(r_s, axis=-1, keepdims=True) ** 3
           - 2.0 * np.cross(omega, v_s) - np.cross(omega, np.cross(omega, r_s)))
    if inertial:
        return v_s + np.cross(omega, r_s), a_s + np.cross(omega, v_s)
    return v_s, a_s
