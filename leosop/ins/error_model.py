"""Linear INS error models: 15-state ([Shen 2024] eq. 13) and 9-state short-time ([Chu 2009] eq. 21).

Convention (PSINS / Yan Gongmin, [Shen 2024] eq. 13)
--------------------------------------------------
* ``phi`` (rad) is the misalignment of the computed navigation frame:
  ``C_n_b_computed = (I - [phi x]) C_n_b_true``.
* ``dv = v_computed - v_true`` in ENU [m/s].
* 15-state position error ``[dlat, dlon, dalt]`` [rad, rad, m]; 9-state
  position error in metres ENU ([Chu 2009]).
* Sensor errors are computed minus true: gyro drift ``eps_b`` [rad/s]
  (``omega_computed = omega_true + eps_b``), accelerometer bias ``nabla_b``
  [m/s^2].
* 15-state order ``[phi(3), dv(3), dpos(3), eps_b(3), nabla_b(3)]``, slices
  :data:`PHI`, :data:`DV`, :data:`DPOS`, :data:`EPS`, :data:`NABLA`.
  Noise input ``w = [w_gyro_b(3), w_accel_b(3)]`` (white, rad/s and m/s^2).

Continuous model ``x_dot = F x + G w`` with Yan Gongmin's blocks
(Strapdown inertial navigation algorithm and integrated navigation
principles, 2019, ch. 4)::

    phi_dot = -[w_in x] phi + M_av dv + M_ap dpos - C_n_b eps_b
    dv_dot  = [f_n x] phi + M_vv dv + M_vp dpos + C_n_b nabla_b
    dpos_dot = M_pv dv + M_pp dpos

``M_vp`` also carries the gradient of normal gravity with latitude and
height (``-d gamma / dh`` is the vertical-channel instability ``~2 g / R``),
taken from :func:`leosop.earth.normal_gravity_mps2` by central differences.
As in Yan's blocks, the change of the radii of curvature with latitude is
neglected in the transport-rate and position-rate terms (relative effect
``3 e^2 sin L cos L``, below 1 % of those terms).

[Chu 2009] (Chu et al. 2009) drops Earth rate and transport rate for flights
under ~10 min: ``psi_dot = -C_n_b eps_b``, ``dv_dot = [f_n x] psi + C_n_b
nabla_b``, ``dX_dot = dv``. Its printed eq. 21 shows the ``F^n`` block with
the opposite sign of its own eq. 19 with eq. 6; we follow eq. 19 (checked
against a strapdown run in the tests). Its eq. 5 also swaps the alpha/beta
places; we use ``psi = [d_alpha, d_beta, d_gamma]`` about East, North, Up.
"""

import numpy as np
import scipy.linalg

from ..earth import earth_rate_enu, normal_gravity_mps2, radii_m, transport_rate_enu
from ..rotations import skew
from ..shapes import as_dcm, as_vec3, stack_last

__all__ = [
    "PHI",
    "DV",
    "DPOS",
    "EPS",
    "NABLA",
    "N_STATES",
    "model15",
    "model9",
    "discretize",
    "propagate",
    "position_budget",
]

#: Slices of the 15-state vector.
PHI, DV, DPOS, EPS, NABLA = (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15))
#: Length of the full state vector.
N_STATES = 15
# Steps of the central differences of normal gravity: the formula is a
# quadratic in height and smooth in latitude, so these are exact to ~1e-12.
_DLAT, _DH = 1e-5, 10.0


def model15(C_n_b, f_n_mps2, vel_enu_mps, lat_rad, alt_m):
    """Continuous 15-state error model ``F``, ``G`` ([Shen 2024] eq. 13).

    Parameters
    ----------
    C_n_b : array_like, shape (..., 3, 3)
        Body-to-ENU attitude (the INS solution).
    f_n_mps2 : array_like, shape (..., 3)
        Specific force in ENU, ``C_n_b @ f_b``.
    vel_enu_mps : array_like, shape (..., 3)
    lat_rad, alt_m : array_like, shape (...)

    Returns
    -------
    F : ndarray, shape (..., 15, 15)
    G : ndarray, shape (..., 15, 6)
        Maps ``[w_gyro_b, w_accel_b]`` into the state derivative.
    """
    C = as_dcm(C_n_b)
    f_n = as_vec3(f_n_mps2, "f_n_mps2")
    v = as_vec3(vel_enu_mps, "vel_enu_mps")
    lat = np.asarray(lat_rad, dtype=float)
    h = np.asarray(alt_m, dtype=float)
    shape = np.broadcast_shapes(C.shape[:-2], f_n.shape[:-1], v.shape[:-1], lat.shape, h.shape)
    C = np.broadcast_to(C, shape + (3, 3))
    f_n = np.broadcast_to(f_n, shape + (3,))
    v = np.broadcast_to(v, shape + (3,))
    lat = np.broadcast_to(lat, shape)
    h = np.broadcast_to(h, shape)

    R_M, R_N = radii_m(lat)
    rm_h, rn_h = R_M + h, R_N + h
    sl, cl, tl = np.sin(lat), np.cos(lat), np.tan(lat)
    ve, vn = v[..., 0], v[..., 1]
    w_ie = earth_rate_enu(lat)
    w_en = transport_rate_enu(lat, h, v)
    W = np.linalg.norm(w_ie, axis=-1)
    zero = np.zeros(shape)

    M_av = stack_last([[zero, -1.0 / rm_h, zero], [1.0 / rn_h, zero, zero], [tl / rn_h, zero, zero]], 2)
    M_1 = stack_last([[zero, zero, zero], [-W * sl, zero, zero], [W * cl, zero, zero]], 2)
    M_2 = stack_last([[zero, zero, vn / rm_h**2], [zero, zero, -ve / rn_h**2],
                      [ve / (cl**2 * rn_h), zero, -ve * tl / rn_h**2]], 2)
    V = skew(v)
    M_vv = V @ M_av - skew(2.0 * w_ie + w_en)
    M_vp = V @ (2.0 * M_1 + M_2)
    M_vp[..., 2, 0] -= (normal_gravity_mps2(lat + _DLAT, h) - normal_gravity_mps2(lat - _DLAT, h)) / (2 * _DLAT)
    M_vp[..., 2, 2] -= (normal_gravity_mps2(lat, h + _DH) - normal_gravity_mps2(lat, h - _DH)) / (2 * _DH)
    M_pv = stack_last([[zero, 1.0 / rm_h, zero], [1.0 / (cl * rn_h), zero, zero], [zero, zero, 1.0 + zero]], 2)
    M_pp = stack_last([[zero, zero, -vn / rm_h**2], [ve * tl / (cl * rn_h), zero, -ve / (cl * rn_h**2)],
                       [zero, zero, zero]], 2)

    F = np.zeros(shape + (15, 15))
    F[..., PHI, PHI] = -skew(w_ie + w_en)
    F[..., PHI, DV] = M_av
    F[..., PHI, DPOS] = M_1 + M_2
    F[..., PHI, EPS] = -C
    F[..., DV, PHI] = skew(f_n)
    F[..., DV, DV] = M_vv
    F[..., DV, DPOS] = M_vp
    F[..., DV, NABLA] = C
    F[..., DPOS, DV] = M_pv
    F[..., DPOS, DPOS] = M_pp
    G = np.zeros(shape + (15, 6))
    G[..., PHI, 0:3] = -C
    G[..., DV, 3:6] = C
    return F, G


def model9(C_n_b, f_n_mps2):
    """[Chu 2009]'s short-time 9-state model (eq. 21, sign of its eq. 19).

    State ``[d_alpha, d_beta, d_gamma, dv_E, dv_N, dv_U, dX_E, dX_N, dX_U]``
    (rad, m/s, m), input ``u = [gyro drift_b (rad/s), accel bias_b (m/s^2)]``.

    Parameters
    ----------
    C_n_b : array_like, shape (..., 3, 3)
    f_n_mps2 : array_like, shape (..., 3)

    Returns
    -------
    F : ndarray, shape (..., 9, 9)
    G : ndarray, shape (..., 9, 6)
    """
    C = as_dcm(C_n_b)
    f_n = as_vec3(f_n_mps2, "f_n_mps2")
    shape = np.broadcast_shapes(C.shape[:-2], f_n.shape[:-1])
    F = np.zeros(shape + (9, 9))
    F[..., 3:6, 0:3] = skew(f_n)
    F[..., 6:9, 3:6] = np.eye(3)
    G = np.zeros(shape + (9, 6))
    G[..., 0:3, 0:3] = -C
    G[..., 3:6, 3:6] = C
    return F, G


def discretize(F, G, Qc, dt_s, *, method="van_loan"):
    """Transition matrix and discrete process noise over one step.

    Parameters
    ----------
    F : array_like, shape (..., n, n)
    G : array_like, shape (..., n, m)
    Qc : array_like, shape (m, m) or (m,)
        Power spectral density of the white input ``w`` (a vector is the
        diagonal): (rad/s)^2 s for gyro noise, (m/s^2)^2 s for accelerometer
        noise.
    dt_s : float
    method : {"van_loan", "series"}
        ``"van_loan"``: exact for constant ``F`` over the step (matrix
        exponential of Van Loan's block matrix). ``"series"``: second-order
        series ``Phi = I + F dt + (F dt)^2 / 2``,
        ``Q = (Qg + Phi Qg Phi^T) dt / 2`` with ``Qg = G Qc G^T``, for fast
        EKF steps where ``|F| dt << 1``.

    Returns
    -------
    Phi : ndarray, shape (..., n, n)
    Qd : ndarray, shape (..., n, n)
    """
    F = np.asarray(F, dtype=float)
    G = np.asarray(G, dtype=float)
    Qc = np.asarray(Qc, dtype=float)
    if Qc.ndim == 1:
        Qc = np.diag(Qc)
    n, m = F.shape[-1], G.shape[-1]
    if F.shape[-2] != n or G.shape[-2] != n or Qc.shape != (m, m):
        raise ValueError(f"inconsistent shapes: F {F.shape}, G {G.shape}, Qc {Qc.shape}")
    if not dt_s > 0:
        raise ValueError(f"{dt_s=} must be > 0")
    Qg = G @ Qc @ np.swapaxes(G, -1, -2)
    if method == "series":
        Fdt = F * dt_s
        Phi = np.eye(n) + Fdt + 0.5 * Fdt @ Fdt
        Qd = 0.5 * dt_s * (Qg + Phi @ Qg @ np.swapaxes(Phi, -1, -2))
    elif method == "van_loan":
        shape = np.broadcast_shapes(F.shape[:-2], Qg.shape[:-2])
        A = np.zeros(shape + (2 * n, 2 * n))
        A[..., :n, :n] = -F
        A[..., :n, n:] = Qg
        A[..., n:, n:] = np.swapaxes(F, -1, -2)
        B = scipy.linalg.expm(A * dt_s)
        Phi = np.swapaxes(B[..., n:, n:], -1, -2)
        Qd = Phi @ B[..., :n, n:]
    else:
        raise ValueError(f"{method=} must be 'van_loan' or 'series'")
    return Phi, 0.5 * (Qd + np.swapaxes(Qd, -1, -2))


def _expm_stack(A):
    """Matrix exponential of a stack of small matrices, shape (k, n, n).

    Scaling and squaring with a degree-12 Taylor polynomial: after scaling to
    norm <= 0.5 the truncation error is below 0.5^13 / 13! ~ 2e-14 relative.
    (scipy.linalg.expm is over 10x slower on long stacks of tiny matrices;
    tools/bench_error_model.py.)
    """
    norm = float(np.abs(A).sum(axis=-1).max()) if A.size else 0.0
    s = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    X = A / 2.0**s
    E = np.eye(A.shape[-1]) + X
    term = X
    for k in range(2, 13):
        term = term @ X / k
        E = E + term
    for _ in range(s):
        E = E @ E
    return E


def propagate(F, G, u, dt_s, x0):
    """Propagate ``x_dot = F(t) x + G(t) u(t)`` with coefficients constant per step.

    Each step uses ``Phi = expm(F dt)`` and the exact input integral
    ``int_0^dt expm(F s) ds G u`` (Van Loan's augmented exponential), so a
    model whose ``F`` is nilpotent, such as :func:`model9`, is integrated
    without truncation error for piecewise-constant coefficients.

    Parameters
    ----------
    F : array_like, shape (n_steps, n, n)
        Coefficients of each step (e.g. at the step's midpoint).
    G : array_like, shape (n_steps, n, m)
    u : array_like, shape (n_steps, m) or (m,)
        Deterministic input (e.g. constant gyro drift and accelerometer bias).
    dt_s : float
    x0 : array_like, shape (n,)

    Returns
    -------
    x : ndarray, shape (n_steps + 1, n)
        The state at the start and after every step.
    """
    F = np.asarray(F, dtype=float)
    G = np.asarray(G, dtype=float)
    n_steps, n = F.shape[0], F.shape[-1]
    u = np.broadcast_to(np.asarray(u, dtype=float), (n_steps, G.shape[-1]))
    A = np.zeros((n_steps, n + 1, n + 1))
    A[:, :n, :n] = F
    A[:, :n, n] = np.einsum("kij,kj->ki", G, u)
    E = _expm_stack(A * dt_s)
    x = np.empty((n_steps + 1, n))
    x[0] = x0
    for k in range(n_steps):
        x[k + 1] = E[k, :n, :n] @ x[k] + E[k, :n, n]
    return x


def position_budget(F, G, Qc, dt_s, P0, groups):
    """Position covariance after a run of steps without aiding (a GNSS gap), split by its sources.

    ``P(T) = Phi P0 Phi^T + Q_gyro + Q_accel`` with ``Phi`` the product of
    the steps' transitions and each sensor's process noise propagated over
    the steps (Van Loan, :func:`discretize`). Each group's share is what its
    block of ``P0`` alone would give, ``Phi[DPOS, g] P0[g, g] Phi[DPOS, g]^T``;
    the shares of correlated groups do not add up to the total (tilt and
    horizontal accelerometer bias, anti-correlated after GNSS aiding, are
    best one group).

    Parameters
    ----------
    F : array_like, shape (n_steps, n, n)
        Coefficients of each step (:func:`model15` or :func:`model9`; rows
        :data:`DPOS` are the position errors).
    G : array_like, shape (n_steps, n, 6)
    Qc : array_like, shape (6,)
        Power spectral densities of ``[w_gyro_b, w_accel_b]``: (rad/s)^2 s
        and (m/s^2)^2 s.
    dt_s : float
    P0 : array_like, shape (n, n)
        Covariance at the start.
    groups : dict of str to sequence of int
        Named sets of state indices into ``P0``.

    Returns
    -------
    dict of str to ndarray, shape (3, 3)
        Covariance of the position errors (the units of :data:`DPOS`) at the
        end: one entry per group, ``"gyro noise"``, ``"accel noise"`` and
        ``"total"`` (``P0`` whole, correlations included, and both noises).
    """
    F = np.asarray(F, dtype=float)
    P0 = np.asarray(P0, dtype=float)
    Qc = np.asarray(Qc, dtype=float)
    n = F.shape[-1]
    if F.ndim != 3 or P0.shape != (n, n) or Qc.shape != (6,):
        raise ValueError(f"F {F.shape} must be (n_steps, n, n), P0 {P0.shape} (n, n) and Qc {Qc.shape} (6,)")
    gyro = np.r_[Qc[:3], np.zeros(3)]
    Phi_k, Qg_k = discretize(F, G, gyro, dt_s)
    _, Qa_k = discretize(F, G, Qc - gyro, dt_s)
    Phi, Qg, Qa = np.eye(n), np.zeros((n, n)), np.zeros((n, n))
    for Ph, qg, qa in zip(Phi_k, Qg_k, Qa_k):
        Phi = Ph @ Phi
        Qg = Ph @ Qg @ Ph.T + qg
        Qa = Ph @ Qa @ Ph.T + qa
    T = Phi[DPOS]
    out = {}
    for name, idx in groups.items():
        idx = np.asarray(idx, dtype=int)
        out[name] = T[:, idx] @ P0[np.ix_(idx, idx)] @ T[:, idx].T
    out["gyro noise"], out["accel noise"] = Qg[DPOS, DPOS], Qa[DPOS, DPOS]
    out["total"] = T @ P0 @ T.T + out["gyro noise"] + out["accel noise"]
    return out
