"""Static coarse alignment: dual-vector ([Qu 2024]) and an optimal Wahba solution.

[Qu 2024] (Qu et al. 2024) determines the attitude of a static IMU from the
averaged accelerometer (gravity reaction) and gyro (Earth rate) outputs. It
works in its own frames: navigation East-North-Up with ``g^n = [0, 0, g]``
(the reaction to gravity), body Forward-Up-Right ("FUR") and Euler order
yaw - pitch - roll, where the yaw ``gamma`` is the azimuth clockwise from
North, pitch ``theta`` the elevation of the forward axis and roll ``phi``
right wing down. Those angles are the toolkit's pitch, roll and heading
(see :mod:`leosop`), so the edge conversion is a permutation of body axes,
``v_RFU = P @ v_FUR``, and ``yaw = -gamma``.

Algorithm 1 (eq. 3, 5) uses the vector triad ``[g, w_ie, g x w_ie]``,
algorithm 2 (eq. 4, 6) ``[g, g x w_ie, (g x w_ie) x g]``;
``C_b^n = ((e^n)^T)^-1 (e^b)^T``. The closed-form angles (eq. 10-15) use
``atan2`` for the quadrant rule the paper describes (signs of numerator and
denominator); the pitch is ``arcsin(f_x / g)`` with the nominal ``g`` as in
eq. 10 and 13. Eq. 12 prints its numerator as ``f_x w_y - f_y w_z``; the
matrix of eq. 5 and the paper's own ``u`` of eq. 18 give
``u = f_z w_y - f_y w_z``, which we use.

The third method, ``"wahba"``, is the maximum-likelihood attitude for
independent Gaussian errors on the two measured vectors: it minimises
``|f_b - C^T g_n|^2 / s_f^2 + |w_b - C^T w_n|^2 / s_w^2`` over rotations
(Wahba's problem with unnormalised vectors, solved by SVD). It returns a
proper rotation and reads the pitch from the direction of ``f_b`` rather
than from ``f_x / g``, so its pitch error does not grow as ``1 / cos(pitch)``
and it does not depend on knowing ``|g|``.

For real logs, :func:`align_inertial` (``"inertial"``) is the inertial-frame
alignment: the gyros track every rotation of the body since the start
(rocking, settling), the integrated specific force in that frozen body frame
is fitted (orthogonal Procrustes) to the integrated gravity reaction, which
turns with the Earth in the inertial frame frozen at the start. Rotations of
a disturbed vehicle then do not leak into the heading, as they do when the
mean gyro output is taken for the Earth rate.
"""

import warnings

import numpy as np

from ..constants import G0_MPS2, OMEGA_E_RAD_PER_S
from ..earth import normal_gravity_mps2
from ..errors import InputError
from ..rotations import dcm_to_euler, rotvec_to_dcm, skew
from ..shapes import as_vec3

__all__ = [
    "METHODS",
    "P_RFU_FUR",
    "dual_vector_dcm_paper",
    "paper_angles",
    "paper_angle_errors",
    "wahba_dcm",
    "align",
    "align_increments",
    "align_inertial",
    "INCREMENT_METHODS",
    "AUTO_INERTIAL_MIN_S",
    "resolve_method",
    "motion_std_mps2",
    "MotionWarning",
]

#: Alignment methods from mean outputs: [Qu 2024] algorithms 1 and 2, and the optimal solution.
METHODS = ("1", "2", "wahba")
#: Methods that take the increments themselves; ``"auto"`` picks one by :func:`resolve_method`.
INCREMENT_METHODS = METHODS + ("inertial", "auto")

#: ``"auto"`` runs the inertial-frame alignment on spans at least this long [s],
#: else the Wahba solution. The inertial fit takes its heading from gravity
#: turning with the Earth (``Omega_e T`` rad), which is too small to see below
#: a few seconds: on a simulated static IMU with [Shen 2024] Table 1 errors it
#: is degrees off at 2-5 s and as good as Wahba from 10 s; on the disturbed
#: real laser-gyro log it beats the mean-rate methods from 10 s on (300 s:
#: 90.6 deg against Wahba's 83.2 deg, header 90.6 deg).
AUTO_INERTIAL_MIN_S = 10.0

#: ``v_RFU = P_RFU_FUR @ v_FUR``: toolkit body axes from the paper's.
P_RFU_FUR = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

#: Default error levels weighting the Wahba solution ([Qu 2024] simulation:
#: accelerometer 1 mg, gyro 0.1 deg/h); only their ratio matters.
ACCEL_SIGMA_MPS2 = 1e-3 * G0_MPS2
GYRO_SIGMA_RAD_PER_S = np.radians(0.1) / 3600.0

#: Warn above this standard deviation of the 1 s means of the specific force
#: [m/s^2] (about 5 mg: engine vibration and people moving about stay below,
#: driving does not).
MOTION_STD_LIMIT_MPS2 = 0.05


class MotionWarning(UserWarning):
    """The IMU data do not look static; the coarse alignment will be poor."""


def _check_lat(lat_rad):
    lat = np.asarray(lat_rad, dtype=float)
    if np.any(~(np.abs(lat) <= np.pi / 2)):
        raise InputError(f"latitude {np.degrees(lat)} deg must be within [-90, 90]")
    if np.any(np.abs(lat) > np.radians(89.0)):
        # Gyrocompassing needs the horizontal Earth rate, Omega cos L.
        raise InputError(f"latitude {np.degrees(lat)} deg is too close to a pole for gyrocompassing (|L| <= 89)")
    return lat


def _nominal_g(lat_rad, g_mps2):
    return normal_gravity_mps2(lat_rad, 0.0) if g_mps2 is None else np.asarray(g_mps2, dtype=float)


def _reference_vectors(lat_rad, g_mps2):
    """``g^n`` (upward reaction) and ``w_ie^n`` of eq. 1-2, shape (..., 3)."""
    lat = np.asarray(lat_rad, dtype=float)
    g = np.broadcast_to(g_mps2, lat.shape)
    z = np.zeros_like(lat)
    g_n = np.stack([z, z, g], axis=-1)
    w_n = np.stack([z, OMEGA_E_RAD_PER_S * np.cos(lat), OMEGA_E_RAD_PER_S * np.sin(lat)], axis=-1)
    return g_n, w_n


def _triad(a, b, algorithm):
    """Columns ``e`` of eq. 3 (algorithm 1) or eq. 4 (algorithm 2), shape (..., 3, 3)."""
    gxw = np.cross(a, b)
    second, third = (b, gxw) if algorithm == "1" else (gxw, np.cross(gxw, a))
    return np.stack([a, second, third], axis=-1)


def dual_vector_dcm_paper(f_fur, w_fur, lat_rad, *, algorithm, g_mps2=None):
    """``C_b^n`` of eq. 5 or 6 in the paper's frames (body Forward-Up-Right).

    Parameters
    ----------
    f_fur : array_like, shape (..., 3)
        Mean specific force [m/s^2] in FUR axes.
    w_fur : array_like, shape (..., 3)
        Mean angular rate [rad/s] in FUR axes.
    lat_rad : array_like, shape (...)
    algorithm : {"1", "2"}
    g_mps2 : float or array_like, optional
        Nominal gravity; default WGS84 normal gravity at ``lat_rad``.

    Returns
    -------
    C_b_n : ndarray, shape (..., 3, 3)
        Not orthogonal in general: eq. 5-6 use the measured vectors as they are.
    """
    if algorithm not in ("1", "2"):
        raise ValueError(f"{algorithm=} must be '1' or '2'")
    g_n, w_n = _reference_vectors(lat_rad, _nominal_g(lat_rad, g_mps2))
    e_n = _triad(g_n, w_n, algorithm)
    e_b = _triad(as_vec3(f_fur, "f_fur"), as_vec3(w_fur, "w_fur"), algorithm)
    return np.linalg.solve(np.swapaxes(e_n, -1, -2), np.swapaxes(e_b, -1, -2))


def paper_angles(f_fur, w_fur, lat_rad, *, algorithm, g_mps2=None):
    """Closed-form pitch, roll and azimuth of eq. 10-15 [rad], paper frames.

    Parameters
    ----------
    f_fur, w_fur : array_like, shape (..., 3)
        Mean specific force [m/s^2] and angular rate [rad/s], FUR axes.
    lat_rad : array_like, shape (...)
    algorithm : {"1", "2"}
    g_mps2 : float or array_like, optional

    Returns
    -------
    theta, phi, gamma : ndarray, shape (...)
        Pitch, roll (right wing down) and azimuth clockwise from North in
        (-pi, pi].
    """
    f = as_vec3(f_fur, "f_fur")
    w = as_vec3(w_fur, "w_fur")
    lat = np.asarray(lat_rad, dtype=float)
    g = _nominal_g(lat, g_mps2)
    fx, fy, fz = np.moveaxis(f, -1, 0)
    wx, wy, wz = np.moveaxis(w, -1, 0)
    theta = np.arcsin(np.clip(fx / g, -1.0, 1.0))  # eq. 10 / 13
    phi = np.arctan2(-fz, fy)  # eq. 11 / 14
    u = fz * wy - fy * wz
    if algorithm == "1":
        gamma = np.arctan2(u, g * wx - OMEGA_E_RAD_PER_S * np.sin(lat) * fx)  # eq. 12
    elif algorithm == "2":
        x = (fy**2 + fz**2) * wx - fx * (fy * wy + fz * wz)
        gamma = np.arctan2(g * u, x)  # eq. 15
    else:
        raise ValueError(f"{algorithm=} must be '1' or '2'")
    return theta, phi, gamma


def paper_angle_errors(f_fur, w_fur, df_fur, dw_fur, lat_rad, *, algorithm, g_mps2=None):
    """First-order angle errors of eq. 16-19 for sensor errors ``df``, ``dw``.

    Parameters
    ----------
    f_fur, w_fur : array_like, shape (..., 3)
        Error-free mean specific force and angular rate, FUR axes.
    df_fur, dw_fur : array_like, shape (..., 3)
        Accelerometer [m/s^2] and gyro [rad/s] errors, FUR axes.
    lat_rad : array_like, shape (...)
    algorithm : {"1", "2"}
    g_mps2 : float or array_like, optional

    Returns
    -------
    d_theta, d_phi, d_gamma : ndarray, shape (...)
    """
    f = as_vec3(f_fur, "f_fur")
    w = as_vec3(w_fur, "w_fur")
    df = as_vec3(df_fur, "df_fur")
    dw = as_vec3(dw_fur, "dw_fur")
    lat = np.asarray(lat_rad, dtype=float)
    g = _nominal_g(lat, g_mps2)
    fx, fy, fz = np.moveaxis(f, -1, 0)
    wx, wy, wz = np.moveaxis(w, -1, 0)
    dfx, dfy, dfz = np.moveaxis(df, -1, 0)
    dwx, dwy, dwz = np.moveaxis(dw, -1, 0)
    d_theta = dfx / np.sqrt(g**2 - fx**2)  # eq. 16
    d_phi = (fz * dfy - fy * dfz) / (fy**2 + fz**2)  # eq. 17
    u = fz * wy - fy * wz
    du = dfz * wy + fz * dwy - dfy * wz - fy * dwz
    if algorithm == "1":
        v = g * wx - OMEGA_E_RAD_PER_S * np.sin(lat) * fx
        dv = g * dwx - OMEGA_E_RAD_PER_S * np.sin(lat) * dfx
        d_gamma = (v * du - u * dv) / (u**2 + v**2)  # eq. 18
    elif algorithm == "2":
        y, dy = g * u, g * du
        x = (fy**2 + fz**2) * wx - fx * (fy * wy + fz * wz)
        dx = (2 * (fy * dfy + fz * dfz) * wx + (fy**2 + fz**2) * dwx
              - dfx * (fy * wy + fz * wz) - fx * (dfy * wy + fy * dwy + dfz * wz + fz * dwz))
        d_gamma = (x * dy - y * dx) / (x**2 + y**2)  # eq. 19
    else:
        raise ValueError(f"{algorithm=} must be '1' or '2'")
    return d_theta, d_phi, d_gamma


def wahba_dcm(f_b_mps2, w_ib_b_rad_per_s, lat_rad, *, g_mps2=None,
              accel_sigma_mps2=ACCEL_SIGMA_MPS2, gyro_sigma_rad_per_s=GYRO_SIGMA_RAD_PER_S):
    """Maximum-likelihood ``C_n_b`` from the mean specific force and angular rate.

    Minimises ``sum_i |b_i - C^T r_i|^2 / s_i^2`` over proper rotations for the
    pairs (``f_b``, ``g_n``) and (``w_b``, ``w_ie_n``) by the SVD of
    ``B = sum_i r_i b_i^T / s_i^2`` (toolkit frames: ENU, body RFU).

    Parameters
    ----------
    f_b_mps2, w_ib_b_rad_per_s : array_like, shape (..., 3)
    lat_rad : array_like, shape (...)
    g_mps2 : float or array_like, optional
    accel_sigma_mps2, gyro_sigma_rad_per_s : float
        Error levels of the two mean vectors (weights).

    Returns
    -------
    C_n_b : ndarray, shape (..., 3, 3)
    """
    f = as_vec3(f_b_mps2, "f_b_mps2")
    w = as_vec3(w_ib_b_rad_per_s, "w_ib_b_rad_per_s")
    g_n, w_n = _reference_vectors(lat_rad, _nominal_g(lat_rad, g_mps2))
    B = (g_n[..., :, None] * f[..., None, :] / accel_sigma_mps2**2
         + w_n[..., :, None] * w[..., None, :] / gyro_sigma_rad_per_s**2)
    U, _, Vt = np.linalg.svd(B)
    d = np.sign(np.linalg.det(U @ Vt))
    return U @ (np.concatenate([np.ones(d.shape + (2,)), d[..., None]], axis=-1)[..., :, None] * Vt)


def align(f_b_mps2, w_ib_b_rad_per_s, lat_rad, *, method="2", g_mps2=None,
          accel_sigma_mps2=ACCEL_SIGMA_MPS2, gyro_sigma_rad_per_s=GYRO_SIGMA_RAD_PER_S):
    """Coarse alignment from mean IMU outputs, toolkit frames and angles.

    Parameters
    ----------
    f_b_mps2 : array_like, shape (..., 3)
        Mean specific force in body RFU axes.
    w_ib_b_rad_per_s : array_like, shape (..., 3)
        Mean angular rate in body RFU axes.
    lat_rad : array_like, shape (...)
    method : {"1", "2", "wahba"}
        [Qu 2024] algorithm 1 or 2 (closed forms eq. 10-15) or the
        maximum-likelihood solution :func:`wahba_dcm`.
    g_mps2 : float or array_like, optional
        Nominal gravity; default WGS84 normal gravity at ``lat_rad``.
    accel_sigma_mps2, gyro_sigma_rad_per_s : float
        Errors of the two mean vectors, the weights of ``"wahba"``.

    Returns
    -------
    pitch_rad, roll_rad, yaw_rad : ndarray, shape (...)
        Toolkit Euler angles (``C_n_b = Rz(yaw) Rx(pitch) Ry(roll)``; yaw
        counter-clockwise, see :func:`leosop.rotations.heading_from_yaw`).
    """
    lat = _check_lat(lat_rad)
    if method == "wahba":
        return dcm_to_euler(wahba_dcm(f_b_mps2, w_ib_b_rad_per_s, lat, g_mps2=g_mps2,
                                      accel_sigma_mps2=accel_sigma_mps2, gyro_sigma_rad_per_s=gyro_sigma_rad_per_s))
    if method not in METHODS:
        raise InputError(f"alignment method {method!r} must be one of {', '.join(METHODS)}")
    to_fur = P_RFU_FUR.T
    f_fur = as_vec3(f_b_mps2, "f_b_mps2") @ to_fur.T
    w_fur = as_vec3(w_ib_b_rad_per_s, "w_ib_b_rad_per_s") @ to_fur.T
    theta, phi, gamma = paper_angles(f_fur, w_fur, lat, algorithm=method, g_mps2=g_mps2)
    return theta, phi, -gamma


def _window_means(increments, dt_s, window_s):
    """Means of the rate over successive windows, shape (k, 3); k may be 0."""
    n = max(1, int(round(window_s / dt_s)))
    k = increments.shape[0] // n
    return increments[: k * n].reshape(k, n, 3).sum(axis=1) / (n * dt_s)


def motion_std_mps2(dvel_b_mps, dt_s, *, window_s=1.0):
    """Standard deviation of the ``window_s`` means of the specific force [m/s^2].

    Root of the summed per-axis variances; a static IMU shows only sensor
    noise averaged over the window (< 1e-3 m/s^2 for tactical grade).
    """
    means = _window_means(as_vec3(dvel_b_mps, "dvel_b_mps"), dt_s, window_s)
    if means.shape[0] < 2:
        return 0.0
    return float(np.sqrt(np.sum(np.var(means, axis=0))))


def _standard_error(increments, dt_s):
    """Standard error of the mean rate from the scatter of 1 s means (None if < 10 s).

    On a real vehicle the scatter is mostly disturbance (rocking, vibration),
    which is what should weight the Wahba solution, not the datasheet noise.
    """
    means = _window_means(increments, dt_s, 1.0)
    if means.shape[0] < 10:
        return None
    return float(np.sqrt(np.mean(np.var(means, axis=0)) / means.shape[0]))


def align_inertial(dtheta_b_rad, dvel_b_mps, dt_s, lat_rad, *, g_mps2=None, fit_every_s=1.0):
    """Inertial-frame coarse alignment; the attitude at the end of the data.

    With ``b0`` the body frame and ``i0`` the navigation frame frozen in
    inertial space at the start:
    ``V_b0(t) = int C_b0_b f_b dt`` (gyro-tracked ``C_b0_b``) and
    ``V_i0(t) = int expm([w_ie x] tau) g_n dtau`` (closed form) satisfy
    ``V_i0 = C_i0_b0 V_b0``; ``C_i0_b0`` is the orthogonal Procrustes fit
    over samples every ``fit_every_s`` seconds, and
    ``C_n_b(T) = expm([w_ie x] T)^T C_i0_b0 C_b0_b(T)``.

    Parameters
    ----------
    dtheta_b_rad, dvel_b_mps : array_like, shape (n, 3)
        Increments, body RFU.
    dt_s : float
    lat_rad : float
    g_mps2 : float, optional
    fit_every_s : float

    Returns
    -------
    pitch_rad, roll_rad, yaw_rad : float
    """
    lat = _check_lat(lat_rad)
    dtheta = as_vec3(dtheta_b_rad, "dtheta_b_rad")
    dvel = as_vec3(dvel_b_mps, "dvel_b_mps")
    n = dtheta.shape[0]
    # Body attitude relative to b0: one rotation vector per sample (static
    # rates make the non-commutativity error negligible).
    steps = rotvec_to_dcm(dtheta)
    C_b0_b = np.empty((n + 1, 3, 3))
    C = np.eye(3)
    C_b0_b[0] = C
    for k in range(n):
        C = C @ steps[k]
        C_b0_b[k + 1] = C
    # Velocity increments with the rotation correction, into b0, summed.
    dv_b0 = np.einsum("kij,kj->ki", C_b0_b[:-1], dvel + 0.5 * np.cross(dtheta, dvel))
    V_b0 = np.cumsum(dv_b0, axis=0)
    t = dt_s * np.arange(1, n + 1)
    g_n, w_n = _reference_vectors(lat, _nominal_g(lat, g_mps2))
    W = float(np.linalg.norm(w_n))
    K = skew(w_n)
    # int_0^t expm(K tau) dtau = I t + (1 - cos W t) / W^2 K + (W t - sin W t) / W^3 K^2
    a = (1.0 - np.cos(W * t)) / W**2
    b = (W * t - np.sin(W * t)) / W**3
    V_i0 = t[:, None] * g_n + a[:, None] * (K @ g_n) + b[:, None] * (K @ K @ g_n)
    pick = slice(max(1, int(round(fit_every_s / dt_s))) - 1, None, max(1, int(round(fit_every_s / dt_s))))
    B = V_i0[pick].T @ V_b0[pick]
    U, _, Vt = np.linalg.svd(B)
    d = np.sign(np.linalg.det(U @ Vt))
    C_i0_b0 = U @ np.diag([1.0, 1.0, d]) @ Vt
    T = t[-1]
    R_T = np.eye(3) + np.sin(W * T) / W * K + (1.0 - np.cos(W * T)) / W**2 * (K @ K)
    return tuple(float(x) for x in dcm_to_euler(R_T.T @ C_i0_b0 @ C_b0_b[-1]))


def resolve_method(method, duration_s):
    """The alignment method that runs for ``method`` on ``duration_s`` seconds of data.

    ``"auto"`` becomes ``"inertial"`` from :data:`AUTO_INERTIAL_MIN_S` on, else
    ``"wahba"``; any other method of :data:`INCREMENT_METHODS` is returned as is.

    Parameters
    ----------
    method : {"1", "2", "wahba", "inertial", "auto"}
    duration_s : float
        Length of the data.

    Returns
    -------
    str
    """
    if method not in INCREMENT_METHODS:
        raise InputError(f"alignment method {method!r} must be one of {', '.join(INCREMENT_METHODS)}")
    if method != "auto":
        return method
    return "inertial" if duration_s >= AUTO_INERTIAL_MIN_S else "wahba"


def align_increments(dtheta_b_rad, dvel_b_mps, dt_s, lat_rad, *, method="2", g_mps2=None):
    """Coarse alignment from gyro and accelerometer increments of a static IMU.

    Warns (:class:`MotionWarning`) when the specific force varies more than a
    static vehicle's would (:data:`MOTION_STD_LIMIT_MPS2`). The Wahba
    weights come from the scatter of the 1 s means of each sensor (for 10 s
    of data or more), so disturbances weigh as they should.

    Parameters
    ----------
    dtheta_b_rad, dvel_b_mps : array_like, shape (n, 3)
        Angle [rad] and velocity [m/s] increments per sample, body RFU.
    dt_s : float
        Sampling interval.
    lat_rad : float
    method : {"1", "2", "wahba", "inertial", "auto"}
        ``"auto"``: see :func:`resolve_method`, which also names the method
        that runs.
    g_mps2 : float, optional

    Returns
    -------
    pitch_rad, roll_rad, yaw_rad : float
        The mean attitude over the data; for ``"inertial"`` the attitude at
        the end of the data.
    """
    dtheta = as_vec3(dtheta_b_rad, "dtheta_b_rad")
    dvel = as_vec3(dvel_b_mps, "dvel_b_mps")
    if dtheta.ndim != 2 or dtheta.shape != dvel.shape or dtheta.shape[0] < 1:
        raise InputError(f"IMU increments must be two (n, 3) arrays of equal length, got {dtheta.shape} and "
                         f"{dvel.shape}")
    if not (dt_s > 0):
        raise InputError(f"sampling interval {dt_s} s must be > 0")
    duration_s = dtheta.shape[0] * dt_s
    std = motion_std_mps2(dvel, dt_s)
    if std > MOTION_STD_LIMIT_MPS2:
        warnings.warn(f"specific force varies by {std:.3g} m/s^2 (1 s means) > {MOTION_STD_LIMIT_MPS2}: "
                      "the vehicle does not look static, the coarse alignment will be poor",
                      MotionWarning, stacklevel=2)
    method = resolve_method(method, duration_s)
    if method == "inertial":
        return align_inertial(dtheta, dvel, dt_s, lat_rad, g_mps2=g_mps2)
    w_b = dtheta.sum(axis=0) / duration_s
    f_b = dvel.sum(axis=0) / duration_s
    sigma_f = _standard_error(dvel, dt_s) or ACCEL_SIGMA_MPS2
    sigma_w = _standard_error(dtheta, dt_s) or GYRO_SIGMA_RAD_PER_S
    return tuple(float(a) for a in align(f_b, w_b, lat_rad, method=method, g_mps2=g_mps2,
                                         accel_sigma_mps2=sigma_f, gyro_sigma_rad_per_s=sigma_w))
