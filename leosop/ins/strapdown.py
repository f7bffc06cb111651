"""Strapdown inertial navigation in the local ENU frame.

Two-sample (dual-subsample) mechanization after Yan Gongmin, *Strapdown
inertial navigation algorithm and integrated navigation principles* (2019),
as [Shen 2024] uses it: 100 Hz increments, one update per pair (50 Hz).

Per update of length ``T = 2 dt`` with increments ``(dtheta_1, dv_1)``,
``(dtheta_2, dv_2)``:

* coning: ``phi = dtheta_1 + dtheta_2 + 2/3 dtheta_1 x dtheta_2``;
* rotation and sculling: ``dv = dv_1 + dv_2 + 1/2 dtheta x dv
  + 2/3 (dtheta_1 x dv_2 + dv_1 x dtheta_2)``;
* Earth rate, transport rate, Coriolis and WGS84 normal gravity with height
  (:mod:`leosop.earth`) at the mid-epoch, from a position extrapolated with
  the start velocity and a velocity predicted with the start terms;
* ``v+ = v + (I - 1/2 [omega_in T x]) C_n_b dv + (g - (2 omega_ie +
  omega_en) x v_mid) T``; position by the trapezoid rule with mid-epoch radii;
* ``q+ = q(-omega_in T) * q * q(phi)``, renormalised every update.

Attitude is a scalar-first quaternion ``q_n_b`` acting like ``C_n_b``.

Error convention (Yan Gongmin / PSINS, shared with
:mod:`leosop.ins.error_model` and the EKF): ``phi`` is the misalignment of
the computed navigation frame,

    C_n_b_computed = (I - [phi x]) C_n_b_true,

``dv = v_computed - v_true`` (ENU) and the position error is
``[dlat, dlon, dalt] = computed - true`` (rad, rad, m).
:meth:`NavState.corrected` removes estimated errors in exactly that sense.
Estimated sensor biases are removed by the caller from the increments.

The per-update arithmetic is written on plain floats: a step is inherently
sequential and numpy's per-call overhead on 3-vectors would dominate
(tools/bench_strapdown.py measures both).
"""

import dataclasses
import functools
import math

import numpy as np

from .. import earth
from ..errors import InputError
from ..rotations import dcm_to_quat, quat_to_dcm, rotvec_to_dcm
from .track import NavTrack

__all__ = ["NavState", "NavHistory", "coning_sculling", "update", "integrate", "integrate_blocks"]


@dataclasses.dataclass(frozen=True)
class NavState:
    """Navigation state at one epoch.

    Attributes
    ----------
    lat_rad, lon_rad, alt_m : float
        WGS84 geodetic position.
    vel_enu_mps : ndarray, shape (3,)
    q_n_b : ndarray, shape (4,)
        Scalar-first unit quaternion of ``C_n_b``.
    """

    lat_rad: float
    lon_rad: float
    alt_m: float
    vel_enu_mps: np.ndarray
    q_n_b: np.ndarray

    @classmethod
    def from_dcm(cls, lat_rad, lon_rad, alt_m, vel_enu_mps, C_n_b):
        """State from a position, velocity and attitude matrix."""
        vel = np.asarray(vel_enu_mps, dtype=float).reshape(3)
        return cls(float(lat_rad), float(lon_rad), float(alt_m), vel, dcm_to_quat(np.asarray(C_n_b, dtype=float)))

    @functools.cached_property
    def C_n_b(self):
        """Attitude matrix, shape (3, 3); made once per state (a filter step reads it several times), read-only."""
        C = quat_to_dcm(self.q_n_b)
        C.flags.writeable = False
        return C

    def corrected(self, phi_enu_rad=(0.0, 0.0, 0.0), dvel_enu_mps=(0.0, 0.0, 0.0), dpos=(0.0, 0.0, 0.0)):
        """The state with estimated errors removed (feedback correction).

        Parameters
        ----------
        phi_enu_rad : array_like, shape (3,)
            Misalignment with ``C_n_b_computed = (I - [phi x]) C_n_b_true``.
        dvel_enu_mps : array_like, shape (3,)
            ``v_computed - v_true``.
        dpos : array_like, shape (3,)
            ``[dlat_rad, dlon_rad, dalt_m]``, computed minus true.
        """
        C = rotvec_to_dcm(np.asarray(phi_enu_rad, dtype=float)) @ self.C_n_b
        dpos = np.asarray(dpos, dtype=float)
        return NavState(self.lat_rad - float(dpos[0]), self.lon_rad - float(dpos[1]), self.alt_m - float(dpos[2]),
                        self.vel_enu_mps - np.asarray(dvel_enu_mps, dtype=float), dcm_to_quat(C))


@dataclasses.dataclass(frozen=True)
class NavHistory(NavTrack):
    """Navigation solution over time: a :class:`~leosop.ins.track.NavTrack` and its quaternions.

    Attributes
    ----------
    t_s, lat_rad, lon_rad, alt_m, vel_enu_mps, C_n_b
        As in :class:`~leosop.ins.track.NavTrack` (``t_s`` in seconds since the
        initial state); shapes (m,), (m,), (m,), (m,), (m, 3), (m, 3, 3).
    q_n_b : ndarray, shape (m, 4)
        The attitude as integrated, scalar-first quaternions (``C_n_b`` is made from them).
    """

    q_n_b: np.ndarray

    def state(self, i):
        """The :class:`NavState` of epoch ``i``."""
        return NavState(float(self.lat_rad[i]), float(self.lon_rad[i]), float(self.alt_m[i]),
                        self.vel_enu_mps[i].copy(), self.q_n_b[i].copy())


def coning_sculling(dtheta_b_rad, dvel_b_mps, update_every=2):
    """Rotation vector and velocity increment of each update, in the body frame at its start.

    Parameters
    ----------
    dtheta_b_rad, dvel_b_mps : array_like, shape (n, 3)
        IMU increments; ``n // update_every`` whole updates are used.
    update_every : {1, 2}
        1: one-sample (no coning or sculling term); 2: two-sample.

    Returns
    -------
    phi_b_rad, dvel_b_mps : ndarray, shape (n // update_every, 3)
    """
    th = np.asarray(dtheta_b_rad, dtype=float)
    dv = np.asarray(dvel_b_mps, dtype=float)
    if th.ndim != 2 or th.shape[1] != 3 or dv.shape != th.shape:
        raise InputError(f"dtheta_b_rad and dvel_b_mps must both have shape (n, 3), got {th.shape} and {dv.shape}")
    if update_every == 1:
        return th.copy(), dv + 0.5 * np.cross(th, dv)
    if update_every != 2:
        raise InputError(f"update_every={update_every} must be 1 or 2")
    m = th.shape[0] // 2
    th1, th2 = th[0:2 * m:2], th[1:2 * m:2]
    dv1, dv2 = dv[0:2 * m:2], dv[1:2 * m:2]
    th_sum, dv_sum = th1 + th2, dv1 + dv2
    phi = th_sum + (2.0 / 3.0) * np.cross(th1, th2)
    rot = np.cross(th_sum, dv_sum)
    dvel = (dv_sum + 0.5 * rot + np.cross(th_sum, rot) / 6.0
            + (2.0 / 3.0) * (np.cross(th1, dv2) + np.cross(dv1, th2)))
    return phi, dvel


def _rv2q(x, y, z):
    """Quaternion of a rotation vector (plain floats)."""
    n2 = x * x + y * y + z * z
    if n2 < 1e-16:
        return 1.0 - n2 / 8.0, 0.5 * x, 0.5 * y, 0.5 * z  # error O(|phi|^3) < 1e-24
    n = math.sqrt(n2)
    s = math.sin(0.5 * n) / n
    return math.cos(0.5 * n), s * x, s * y, s * z


def _step(lat, lon, h, ve, vn, vu, q0, q1, q2, q3, px, py, pz, fx, fy, fz, T):
    """One update on plain floats; see the module docstring for the algorithm."""
    # Velocity increment of the specific force, resolved in n at the start attitude.
    a00 = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    a11 = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    a22 = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    a01, a10 = 2.0 * (q1 * q2 - q0 * q3), 2.0 * (q1 * q2 + q0 * q3)
    a02, a20 = 2.0 * (q1 * q3 + q0 * q2), 2.0 * (q1 * q3 - q0 * q2)
    a12, a21 = 2.0 * (q2 * q3 - q0 * q1), 2.0 * (q2 * q3 + q0 * q1)
    se = a00 * fx + a01 * fy + a02 * fz
    sn = a10 * fx + a11 * fy + a12 * fz
    su = a20 * fx + a21 * fy + a22 * fz
    # Mid-epoch position and velocity from the start terms.
    rm_h, rn_h, c, g, wie_n, wie_u, wen_e, wen_n, wen_u = earth.local_terms(lat, h, ve, vn)
    wy, wz = 2.0 * wie_n + wen_n, 2.0 * wie_u + wen_u
    ht = 0.5 * T
    ve_m = ve + 0.5 * se - ht * (wy * vu - wz * vn)
    vn_m = vn + 0.5 * sn - ht * (wz * ve - wen_e * vu)
    vu_m = vu + 0.5 * su - ht * (wen_e * vn - wy * ve + g)
    lat_m = lat + ht * vn / rm_h
    h_m = h + ht * vu
    # Earth terms at the mid-epoch.
    rm_h, rn_h, c, g, wie_n, wie_u, wen_e, wen_n, wen_u = earth.local_terms(lat_m, h_m, ve_m, vn_m)
    ie, in_, iu = wen_e, wie_n + wen_n, wie_u + wen_u  # omega_in^n
    wy, wz = 2.0 * wie_n + wen_n, 2.0 * wie_u + wen_u  # 2 omega_ie + omega_en (East part is wen_e)
    # (I - 1/2 [omega_in T x]) s, then Coriolis and gravity.
    ve1 = ve + se - ht * (in_ * su - iu * sn) - T * (wy * vu_m - wz * vn_m)
    vn1 = vn + sn - ht * (iu * se - ie * su) - T * (wz * ve_m - wen_e * vu_m)
    vu1 = vu + su - ht * (ie * sn - in_ * se) - T * (wen_e * vn_m - wy * ve_m + g)
    lat1 = lat + ht * (vn + vn1) / rm_h
    lon1 = lon + ht * (ve + ve1) / (rn_h * c)
    h1 = h + ht * (vu + vu1)
    # Attitude: q(-omega_in T) * q * q(phi).
    b0, b1, b2, b3 = _rv2q(px, py, pz)
    r0 = q0 * b0 - q1 * b1 - q2 * b2 - q3 * b3
    r1 = q0 * b1 + q1 * b0 + q2 * b3 - q3 * b2
    r2 = q0 * b2 - q1 * b3 + q2 * b0 + q3 * b1
    r3 = q0 * b3 + q1 * b2 - q2 * b1 + q3 * b0
    b0, b1, b2, b3 = _rv2q(-T * ie, -T * in_, -T * iu)
    q0 = b0 * r0 - b1 * r1 - b2 * r2 - b3 * r3
    q1 = b0 * r1 + b1 * r0 + b2 * r3 - b3 * r2
    q2 = b0 * r2 - b1 * r3 + b2 * r0 + b3 * r1
    q3 = b0 * r3 + b1 * r2 - b2 * r1 + b3 * r0
    k = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return lat1, lon1, h1, ve1, vn1, vu1, q0 * k, q1 * k, q2 * k, q3 * k


def update(state, dtheta_pair, dvel_pair, dt_s):
    """One two-sample update (for filters that run the INS step by step).

    Parameters
    ----------
    state : NavState
    dtheta_pair, dvel_pair : array_like, shape (2, 3)
        Two consecutive IMU increments [rad], [m/s], bias-corrected by the caller.
    dt_s : float
        IMU sample interval; the update spans ``2 dt_s``.

    Returns
    -------
    NavState
    """
    th = np.asarray(dtheta_pair, dtype=float)
    dv = np.asarray(dvel_pair, dtype=float)
    if th.shape != (2, 3) or dv.shape != (2, 3):
        raise InputError(f"dtheta_pair and dvel_pair must have shape (2, 3), got {th.shape} and {dv.shape}")
    (a1, a2, a3), (b1, b2, b3) = th.tolist()
    (u1, u2, u3), (w1, w2, w3) = dv.tolist()
    # coning_sculling() for one pair, on plain floats (numpy calls would cost ~20x more).
    tx, ty, tz = a1 + b1, a2 + b2, a3 + b3
    vx, vy, vz = u1 + w1, u2 + w2, u3 + w3
    k = 2.0 / 3.0
    px = tx + k * (a2 * b3 - a3 * b2)
    py = ty + k * (a3 * b1 - a1 * b3)
    pz = tz + k * (a1 * b2 - a2 * b1)
    rx, ry, rz = ty * vz - tz * vy, tz * vx - tx * vz, tx * vy - ty * vx
    sx = (a2 * w3 - a3 * w2) + (u2 * b3 - u3 * b2)
    sy = (a3 * w1 - a1 * w3) + (u3 * b1 - u1 * b3)
    sz = (a1 * w2 - a2 * w1) + (u1 * b2 - u2 * b1)
    fx = vx + 0.5 * rx + (ty * rz - tz * ry) / 6.0 + k * sx
    fy = vy + 0.5 * ry + (tz * rx - tx * rz) / 6.0 + k * sy
    fz = vz + 0.5 * rz + (tx * ry - ty * rx) / 6.0 + k * sz
    v, q = state.vel_enu_mps, state.q_n_b
    out = _step(state.lat_rad, state.lon_rad, state.alt_m, float(v[0]), float(v[1]), float(v[2]),
                float(q[0]), float(q[1]), float(q[2]), float(q[3]), px, py, pz, fx, fy, fz, 2.0 * dt_s)
    return NavState(out[0], out[1], out[2], np.array(out[3:6]), np.array(out[6:10]))


def integrate(state0, dtheta_b_rad, dvel_b_mps, dt_s, *, update_every=2, out_every=1):
    """Integrate IMU increments from an initial state.

    Parameters
    ----------
    state0 : NavState
    dtheta_b_rad, dvel_b_mps : array_like, shape (n, 3)
        IMU increments at interval ``dt_s``; ``n // update_every`` whole
        updates are made (a trailing incomplete group is not used).
    dt_s : float
        IMU sample interval [s].
    update_every : {1, 2}
        Samples per update: 2 is the two-sample algorithm, 1 a one-sample one.
    out_every : int
        Keep every ``out_every``-th update (and the initial state).

    Returns
    -------
    NavHistory
    """
    return integrate_blocks(state0, [(dtheta_b_rad, dvel_b_mps)], dt_s, update_every=update_every,
                            out_every=out_every)


def integrate_blocks(state0, blocks, dt_s, *, update_every=2, out_every=1):
    """:func:`integrate` over consecutive blocks of increments, holding one block at a time.

    The result is bit for bit :func:`integrate`'s on the blocks joined.

    Parameters
    ----------
    state0 : NavState
    blocks : iterable of (dtheta_b_rad, dvel_b_mps)
        Consecutive increments, each pair shape (n_i, 3); every block but
        the last a whole number of updates (``n_i`` a multiple of ``update_every``).
    dt_s, update_every, out_every
        As in :func:`integrate`.

    Returns
    -------
    NavHistory
    """
    if not dt_s > 0:
        raise InputError(f"dt_s={dt_s} must be > 0")
    if int(out_every) != out_every or out_every < 1:
        raise InputError(f"out_every={out_every} must be a positive integer")
    T = update_every * dt_s
    v, q = state0.vel_enu_mps, state0.q_n_b
    s = (float(state0.lat_rad), float(state0.lon_rad), float(state0.alt_m), float(v[0]), float(v[1]), float(v[2]),
         float(q[0]), float(q[1]), float(q[2]), float(q[3]))
    rows = [np.array([s])]
    step = _step
    i = 0
    left_over = 0
    for dtheta_b_rad, dvel_b_mps in blocks:
        if left_over:
            raise InputError(f"a block of increments ends inside an update ({left_over} samples left over) "
                             "and is not the last")
        phi, dv = coning_sculling(dtheta_b_rad, dvel_b_mps, update_every)
        left_over = np.shape(dtheta_b_rad)[0] % update_every
        m = phi.shape[0]
        out = np.empty(((i + m) // out_every - i // out_every, 10))
        j = 0
        for p, f in zip(phi.tolist(), dv.tolist()):
            s = step(*s, *p, *f, T)
            i += 1
            if i % out_every == 0:
                out[j] = s
                j += 1
        rows.append(out)
    out = np.concatenate(rows)
    t = np.arange(out.shape[0]) * out_every * T
    return NavHistory(t, out[:, 0], out[:, 1], out[:, 2], out[:, 3:6], quat_to_dcm(out[:, 6:10]), out[:, 6:10])
