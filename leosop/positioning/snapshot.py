"""Snapshot Doppler fixes: one epoch at a time, many epochs at once ([Shen 2024] eq. 4-12).

State ``[x, y, z, vx, vy, vz, T_u]`` (ECEF m, m/s, receiver frequency offset
Hz), at least :data:`~leosop.geometry.doppler.N_DOPPLER_STATES` satellites.
Rows of several constellations (``clock_group``) get one ``T_u`` per
constellation: ``6 + k`` states and measurements for k constellations. Each
epoch is an independent problem of :func:`~leosop.positioning.robust_ls.solve_robust`.
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import InputError
from ..geometry.dop import cofactor
from ..geometry.doppler import N_DOPPLER_STATES, clock_group_rows, doppler_jacobian
from .robust_ls import XTOL_POS_M, FixStatus, solve_robust
from .starts import R_GROUND_M, subpoint_centroid_ecef_m

__all__ = ["SnapshotFixes", "solve_snapshots"]

#: Step thresholds of convergence, per state: 0.1 mm, 1 um/s, 10 uHz.
_XTOL_SNAPSHOT = np.array([XTOL_POS_M] * 3 + [1e-6] * 3 + [1e-5])

@dataclass(frozen=True)
class SnapshotFixes:
    """Snapshot fixes of ``n_ep`` epochs with up to ``n_sv`` satellites each.

    Attributes
    ----------
    pos_ecef_m, vel_ecef_mps : ndarray, (n_ep, 3)
    clock_offset_hz : ndarray, (n_ep,)
        Receiver frequency offset ``T_u`` (several clocks: that of the first
        clock present at the epoch, in the order of ``clock_labels``).
    cov : ndarray, (n_ep, 6 + k, 6 + k)
        Posterior covariance of ``[pos, vel, T_u...]`` from the given sigmas
        (k = 1 without clock groups), times ``chi2 / dof`` for an INCONSISTENT
        fix; NaN rows and columns for a clock absent at the epoch.
    gdop, pos_dop, vel_dop : ndarray, (n_ep,)
        Eq. 10 ``sqrt(trace((H^T H)^-1))`` over the used satellites, and the
        square roots of the position and velocity blocks of that trace. The
        trace covers position [m^2/Hz^2], velocity [(m/s)^2/Hz^2] and every
        clock present at the epoch [Hz^2/Hz^2, i.e. 1] with unit weights, as
        eq. 10 adds them: one number of mixed units, so a mixed set's GDOP
        counts one clock term per constellation.
    residuals_hz : ndarray, (n_ep, n_sv)
        Measured minus modelled Doppler at the solution; NaN where masked.
    used : ndarray of bool, (n_ep, n_sv)
        Measurements in the solution (mask minus excluded outliers).
    n_used, iterations : ndarray of int, (n_ep,)
    chi2 : ndarray, (n_ep,)
        Weighted residual sum of squares.
    dof : ndarray of int, (n_ep,)
        Degrees of freedom of ``chi2``: used measurements minus the ``6 + k_e``
        states of the epoch.
    status : ndarray of int, (n_ep,)
        :class:`~leosop.positioning.robust_ls.FixStatus` values; states are NaN unless OK or INCONSISTENT.
    clock_offsets_hz : ndarray, (n_ep, k)
        Each receiver clock's frequency offset, NaN where absent.
    clock_labels : tuple, (k,)
        The ``clock_group`` value of each clock; ``()`` without groups.
    """

    pos_ecef_m: np.ndarray
    vel_ecef_mps: np.ndarray
    clock_offset_hz: np.ndarray
    cov: np.ndarray
    gdop: np.ndarray
    pos_dop: np.ndarray
    vel_dop: np.ndarray
    residuals_hz: np.ndarray
    used: np.ndarray
    n_used: np.ndarray
    iterations: np.ndarray
    chi2: np.ndarray
    dof: np.ndarray
    status: np.ndarray
    clock_offsets_hz: np.ndarray | None = None
    clock_labels: tuple = ()

    @property
    def residual_rms_hz(self) -> npt.NDArray[np.float64]:
        """RMS of the used residuals per epoch, ndarray (n_ep,)."""
        r2 = np.where(self.used, np.nan_to_num(self.residuals_hz) ** 2, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(r2.sum(-1) / self.n_used)

def solve_snapshots(doppler_hz: npt.ArrayLike, sigma_hz: npt.ArrayLike, pos_sv_ecef_m: npt.ArrayLike,
                    vel_sv_ecef_mps: npt.ArrayLike, carrier_hz: npt.ArrayLike, mask: npt.ArrayLike | None = None,
                    x0: npt.ArrayLike | None = None, *, max_iter: int = 50, alpha: float | None = 1e-3,
                    clock_group: npt.ArrayLike | None = None,
                    clock_labels: npt.ArrayLike | None = None) -> SnapshotFixes:
    """Snapshot Doppler fixes of many epochs at once ([Shen 2024] eq. 4-12).

    Parameters
    ----------
    doppler_hz : array_like, (n_ep, n_sv)
    sigma_hz : float or array_like, broadcastable to (n_ep, n_sv)
        Standard deviation of each measurement.
    pos_sv_ecef_m, vel_sv_ecef_mps : array_like, (n_ep, n_sv, 3)
        Satellite states (at transmit time, in the ECEF frame of reception).
    carrier_hz : float or array_like, broadcastable to (n_ep, n_sv)
    mask : array_like of bool, (n_ep, n_sv), optional
        False drops a measurement (padding, below the mask, ...); non-finite
        inputs are dropped too.
    x0 : array_like, (n_ep, 6 + k) or (6 + k,), optional
        Start ``[pos, vel, T_u...]`` (k receiver clocks; a 7-column start
        gives every clock its offset); default the ground point below the
        satellites' mean direction, at rest, no offset.
    max_iter : int
        Iteration cap of each solve.
    alpha : float or None
        Significance of the chi-square outlier test; None disables it.
    clock_group : array_like of int, broadcastable to (n_ep, n_sv), optional
        Receiver clock of each measurement (e.g. its constellation): each
        distinct value among the unmasked rows gets its own frequency offset
        state ``T_u[g]`` (the k clocks sorted by value). An epoch estimates
        ``6 + k_e`` states, ``k_e`` the clocks present among its rows, and
        needs as many measurements; an absent clock's state is held at its
        start by a pseudo-row that is never excluded (outlier tests, degrees
        of freedom and GDOP are those of the ``6 + k_e`` states). None: one
        clock ([Shen 2024]'s 7 states).
    clock_labels : array_like, (k,), optional
        With ``clock_group``: the clocks to estimate, sorted, e.g. the
        groups of a longer run solved a block of epochs at a time, so that
        every block has the same states; a clock absent from all the epochs
        is held at its start at each. Default the distinct groups among the
        unmasked rows.

    Returns
    -------
    SnapshotFixes
    """
    y = np.atleast_2d(np.asarray(doppler_hz, dtype=float))
    n_ep, n_sv = y.shape
    r_s = np.asarray(pos_sv_ecef_m, dtype=float).reshape(n_ep, n_sv, 3)
    v_s = np.asarray(vel_sv_ecef_mps, dtype=float).reshape(n_ep, n_sv, 3)
    sigma = np.broadcast_to(np.asarray(sigma_hz, dtype=float), y.shape)
    f0 = np.broadcast_to(np.asarray(carrier_hz, dtype=float), y.shape)
    m = np.ones(y.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), y.shape)
    m = m & np.isfinite(y) & np.isfinite(r_s).all(-1) & np.isfinite(v_s).all(-1) & (sigma > 0) & (f0 > 0)
    # Finite placeholders where masked, so that nothing NaN enters the algebra.
    y = np.where(m, y, 0.0)
    sigma = np.where(m, sigma, 1.0)
    f0 = np.where(m, f0, 1.0)
    r_s = np.where(m[..., None], r_s, [2e7, 0.0, 0.0])
    v_s = np.where(m[..., None], v_s, 0.0)
    # Receiver clocks: one offset state per distinct group among the unmasked rows.
    groups = np.zeros(y.shape, int) if clock_group is None else np.broadcast_to(np.asarray(clock_group), y.shape)
    if clock_labels is None:
        clock_labels, g_idx = np.unique(groups[m], return_inverse=True)
    else:
        clock_labels = np.asarray(clock_labels)
        g_idx = np.searchsorted(clock_labels, groups[m])
        if np.any(clock_labels[np.minimum(g_idx, len(clock_labels) - 1)] != groups[m]):
            raise InputError(f"clock_group values {sorted(set(groups[m].tolist()) - set(clock_labels.tolist()))} "
                             f"are not among {clock_labels=}")
    n_clk = max(len(clock_labels), 1)
    n_states = 6 + n_clk
    gi = np.zeros(y.shape, int)
    gi[m] = g_idx.ravel()
    onehot = (gi[..., None] == np.arange(n_clk)) & m[..., None]
    present = onehot.any(-2) if n_clk > 1 else np.ones((n_ep, 1), bool)
    x_ground = np.zeros((n_ep, n_states))
    x_ground[:, :3] = np.nan_to_num(subpoint_centroid_ecef_m(r_s, m), nan=R_GROUND_M)
    if x0 is None:
        x0 = x_ground
    else:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape[-1] == N_DOPPLER_STATES and n_clk > 1:
            x0 = np.concatenate([x0[..., :6], np.repeat(x0[..., 6:], n_clk, -1)], -1)
        x0 = np.broadcast_to(x0, (n_ep, n_states)).copy()
    fixed = None
    if n_clk > 1:
        # Pseudo-rows "clock g = start" for the clocks absent at an epoch (measured 0, weight 1, never excluded).
        x0[:, 6:] = np.where(present, x0[:, 6:], 0.0)
        y = np.concatenate([y, np.zeros((n_ep, n_clk))], -1)
        sigma = np.concatenate([sigma, np.ones((n_ep, n_clk))], -1)
        m = np.concatenate([m, ~present], -1)
        fixed = np.arange(n_sv + n_clk) >= n_sv
        clk_cols = onehot.astype(float)

    def model(x, idx, w):
        H = doppler_jacobian(r_s[idx], v_s[idx], x[:, :3], x[:, 3:6], f0[idx])
        pred = np.einsum("pmi,pmi->pm", H[..., 3:6], x[:, None, 3:6] - v_s[idx])
        if n_clk == 1:
            return pred + x[:, 6:7], H
        pred = np.concatenate([pred + np.einsum("pmk,pk->pm", clk_cols[idx], x[:, 6:]), x[:, 6:]], -1)
        return pred, clock_group_rows(H, clk_cols[idx])

    x, res, H, Q, used, iterations, chi2, status = solve_robust(
        model, x0, y, sigma, m, n_states, xtol=_xtol_snapshot(n_clk), max_iter=max_iter, alpha=alpha,
        x_alt=x_ground, fixed=fixed)
    good = (status == FixStatus.OK) | (status == FixStatus.INCONSISTENT)
    x[~good] = np.nan
    Q[~good] = np.nan
    Q0 = cofactor(H, used)
    d0 = np.diagonal(Q0, axis1=-2, axis2=-1)
    clocks = x[:, 6:]
    if n_clk > 1:
        # Absent clocks are no states of their epoch: no offset, no covariance, outside the GDOP's trace.
        keep = np.concatenate([np.ones((n_ep, 6), bool), present], -1)
        Q = np.where(keep[:, :, None] & keep[:, None, :], Q, np.nan)
        d0 = np.where(keep, d0, 0.0)
        clocks = np.where(present, clocks, np.nan)
        res, used = res[:, :n_sv], used[:, :n_sv]
    with np.errstate(invalid="ignore"):
        gdop = np.sqrt(d0.sum(-1))
        pos_dop, vel_dop = np.sqrt(d0[:, :3].sum(-1)), np.sqrt(d0[:, 3:6].sum(-1))
    first = np.argmax(present, axis=-1)
    return SnapshotFixes(
        pos_ecef_m=x[:, :3], vel_ecef_mps=x[:, 3:6], clock_offset_hz=clocks[np.arange(n_ep), first], cov=Q,
        gdop=gdop, pos_dop=pos_dop, vel_dop=vel_dop, residuals_hz=res, used=used,
        n_used=used.sum(-1), iterations=iterations, chi2=chi2, dof=used.sum(-1) - 6 - present.sum(-1), status=status,
        clock_offsets_hz=clocks,
        clock_labels=tuple(clock_labels.tolist()) if clock_group is not None else (),
    )

def _xtol_snapshot(n_clk):
    """Step thresholds of a snapshot state with ``n_clk`` receiver clocks."""
    return _XTOL_SNAPSHOT if n_clk == 1 else np.concatenate([_XTOL_SNAPSHOT, np.repeat(_XTOL_SNAPSHOT[6:], n_clk - 1)])
