"""Discrete Kalman filter core as plain functions.

Textbook names (Bar-Shalom, Li and Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, 2001): state ``x`` (n,),
covariance ``P`` (n, n), transition ``Phi``, process noise ``Q``,
measurement ``z`` (m,), design matrix ``H`` (m, n), measurement noise ``R``,
innovation ``y`` and its covariance ``S``. The update uses the Joseph form,
which keeps ``P`` symmetric positive definite for any gain, and returns the
innovation and ``S`` so that callers can keep them for consistency checks
(:func:`nis`, :func:`nees`).
"""

import numpy as np

__all__ = ["nees", "nis", "predict", "update"]


def _symmetric(P):
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def predict(x, P, Phi, Q):
    """Propagate a state and its covariance one step.

    Parameters
    ----------
    x : ndarray, shape (n,)
    P, Phi, Q : ndarray, shape (n, n)
        ``Q`` is the discrete process-noise covariance (already mapped by
        the noise-input matrix, i.e. ``Gamma Q_w Gamma^T``).

    Returns
    -------
    x, P : ndarray, shapes (n,), (n, n)
    """
    return Phi @ x, _symmetric(Phi @ P @ Phi.T + Q)


def update(x, P, z, H, R):
    """Measurement update in Joseph form.

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    z : ndarray, shape (m,)
    H : ndarray, shape (m, n)
    R : ndarray, shape (m, m)

    Returns
    -------
    x, P : ndarray, shapes (n,), (n, n)
        Posterior state and covariance.
    y : ndarray, shape (m,)
        Innovation ``z - H x`` (prior ``x``).
    S : ndarray, shape (m, m)
        Innovation covariance ``H P H^T + R``.
    """
    y = z - H @ x
    PHt = P @ H.T
    S = _symmetric(H @ PHt + R)
    K = np.linalg.solve(S, PHt.T).T
    I_KH = np.eye(P.shape[0]) - K @ H
    P_post = _symmetric(I_KH @ P @ I_KH.T + K @ R @ K.T)
    return x + K @ y, P_post, y, S


def nis(y, S):
    """Normalised innovation squared ``y^T S^-1 y``.

    Parameters
    ----------
    y : ndarray, shape (..., m)
    S : ndarray, shape (..., m, m)

    Returns
    -------
    ndarray, shape (...)
        Chi-square with ``m`` degrees of freedom for a consistent filter.
    """
    y = np.asarray(y, dtype=float)
    return np.sum(y * np.linalg.solve(S, y[..., None])[..., 0], axis=-1)


def nees(err, P):
    """Normalised estimation error squared ``e^T P^-1 e``; same shapes as :func:`nis`."""
    return nis(err, P)
