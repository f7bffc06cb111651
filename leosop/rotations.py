"""Attitude: Euler angles, direction cosine matrices, rotation vectors, quaternions.

Convention (the toolkit's, see :mod:`leosop`): navigation frame n is
East-North-Up, body frame b is Right-Forward-Up. ``C_n_b`` maps body vectors
to the navigation frame and is built as ``Rz(yaw) @ Rx(pitch) @ Ry(roll)``:
yaw about Up (counter-clockwise from North positive, so the heading
clockwise from North is ``-yaw``), pitch about the body Right axis (nose up
positive), roll about the body Forward axis (right wing down positive).
Quaternions are scalar-first ``[q0, q1, q2, q3]`` and act like ``C_n_b``.
All functions are vectorised over leading axes.
"""

import numpy as np

from .shapes import stack_last

__all__ = [
    "skew",
    "euler_to_dcm",
    "dcm_to_euler",
    "heading_from_yaw",
    "yaw_from_heading",
    "rotvec_to_dcm",
    "rotvec_to_quat",
    "quat_multiply",
    "quat_to_dcm",
    "dcm_to_quat",
    "quat_normalize",
]


def skew(v):
    """Cross-product matrix ``[v x]`` of vectors, shape (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    z = np.zeros_like(v[..., 0])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return stack_last([[z, -w, y], [w, z, -x], [-y, x, z]], 2)


def euler_to_dcm(pitch_rad, roll_rad, yaw_rad):
    """``C_n_b`` from pitch, roll and yaw [rad]; shape (..., 3, 3)."""
    p, r, y = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (pitch_rad, roll_rad, yaw_rad)))
    sp, cp = np.sin(p), np.cos(p)
    sr, cr = np.sin(r), np.cos(r)
    sy, cy = np.sin(y), np.cos(y)
    return stack_last([[cy * cr - sy * sp * sr, -sy * cp, cy * sr + sy * sp * cr],
                       [sy * cr + cy * sp * sr, cy * cp, sy * sr - cy * sp * cr],
                       [-cp * sr, sp, cp * cr]], 2)


def dcm_to_euler(C_n_b):
    """Pitch, roll, yaw [rad] of ``C_n_b``; pitch in [-pi/2, pi/2]."""
    C = np.asarray(C_n_b, dtype=float)
    pitch = np.arcsin(np.clip(C[..., 2, 1], -1.0, 1.0))
    roll = np.arctan2(-C[..., 2, 0], C[..., 2, 2])
    yaw = np.arctan2(-C[..., 0, 1], C[..., 1, 1])
    return pitch, roll, yaw


def heading_from_yaw(yaw_rad):
    """Heading clockwise from North in [0, 2 pi) from the counter-clockwise yaw."""
    return np.mod(-np.asarray(yaw_rad, dtype=float), 2.0 * np.pi)


def yaw_from_heading(heading_rad):
    """Counter-clockwise yaw in (-pi, pi] from the heading clockwise from North."""
    y = -np.asarray(heading_rad, dtype=float)
    return np.arctan2(np.sin(y), np.cos(y))


def rotvec_to_dcm(phi_rad):
    """Rotation matrix of rotation vectors (Rodrigues), (..., 3) -> (..., 3, 3)."""
    phi = np.asarray(phi_rad, dtype=float)
    angle = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = angle < 1e-8
    a2 = np.where(small, 1.0, angle**2)
    # Series below 1e-8 rad, where the closed form loses precision.
    s = np.where(small, 1.0 - angle**2 / 6.0, np.sin(angle) / np.where(small, 1.0, angle))
    c = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(angle)) / a2)
    K = skew(phi)
    return np.eye(3) + s * K + c * (K @ K)


def rotvec_to_quat(phi_rad):
    """Unit quaternion of rotation vectors, (..., 3) -> (..., 4)."""
    phi = np.asarray(phi_rad, dtype=float)
    half = 0.5 * np.linalg.norm(phi, axis=-1)
    small = half < 1e-8
    k = np.where(small, 0.5 - half**2 / 12.0, np.sin(half) / np.where(small, 1.0, 2.0 * half))
    return np.concatenate([np.cos(half)[..., None], k[..., None] * phi], axis=-1)


def quat_multiply(p, q):
    """Hamilton product ``p * q`` of quaternions, shape (..., 4)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    p0, pv = p[..., :1], p[..., 1:]
    q0, qv = q[..., :1], q[..., 1:]
    return np.concatenate(
        [p0 * q0 - np.sum(pv * qv, axis=-1, keepdims=True), p0 * qv + q0 * pv + np.cross(pv, qv)], axis=-1
    )


def quat_normalize(q):
    """Quaternions scaled to unit norm, shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_to_dcm(q):
    """Rotation matrix of unit quaternions, (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return stack_last(
        [
            [q0*q0 + q1*q1 - q2*q2 - q3*q3, 2 * (q1*q2 - q0*q3), 2 * (q1*q3 + q0*q2)],
            [2 * (q1*q2 + q0*q3), q0*q0 - q1*q1 + q2*q2 - q3*q3, 2 * (q2*q3 - q0*q1)],
            [2 * (q1*q3 - q0*q2), 2 * (q2*q3 + q0*q1), q0*q0 - q1*q1 - q2*q2 + q3*q3],
        ],
        2,
    )


def dcm_to_quat(C):
    """Unit quaternion (q0 >= 0) of rotation matrices, (..., 3, 3) -> (..., 4).

    Uses the largest of the four squared components for numerical stability.
    """
    C = np.asarray(C, dtype=float)
    tr = np.trace(C, axis1=-2, axis2=-1)
    sq = stack_last([1 + tr, 1 + 2 * C[..., 0, 0] - tr, 1 + 2 * C[..., 1, 1] - tr, 1 + 2 * C[..., 2, 2] - tr])
    best = np.argmax(sq, axis=-1)
    d = stack_last(
        [
            C[..., 2, 1] - C[..., 1, 2],
            C[..., 0, 2] - C[..., 2, 0],
            C[..., 1, 0] - C[..., 0, 1],
            C[..., 1, 0] + C[..., 0, 1],
            C[..., 0, 2] + C[..., 2, 0],
            C[..., 2, 1] + C[..., 1, 2],
        ]
    )
    # 4 q_i q_j for every pair, arranged per choice of the pivot component.
    prods = [
        [sq[..., 0], d[..., 0], d[..., 1], d[..., 2]],
        [d[..., 0], sq[..., 1], d[..., 3], d[..., 4]],
        [d[..., 1], d[..., 3], sq[..., 2], d[..., 5]],
        [d[..., 2], d[..., 4], d[..., 5], sq[..., 3]],
    ]
    rows = stack_last(prods, 2) / (2.0 * np.sqrt(np.maximum(sq, 1e-300)))[..., None]
    q = np.take_along_axis(rows, best[..., None, None], axis=-2)[..., 0, :]
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    return quat_normalize(q)
