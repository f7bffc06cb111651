"""The LEO snapshot fix as an aid of the engine (:mod:`leosop.fusion.engine`): loose coupling.

Measurement: INS minus LEO fix, velocity then position, 6 values in ENU
metres ([Shen 2024] eq. 13-16; the position rows of ``H`` carry the radii
that turn ``dlat, dlon`` into metres). ``R`` is the covariance of the fix's
white errors, rotated into ENU.

Time-correlated fix errors. A snapshot fix is ``x_true + G_k e_k`` to first
order, ``G_k`` the least-squares gain of epoch k and ``e_k`` the Doppler
errors of its satellites: constant clock-induced offsets ([Shen 2024] Table 1),
constant orbit errors and white estimator noise. Its systematic part persists
from fix to fix and jumps when the satellite set changes: not white, and not
stationary, so no decaying random error fits it. Treated as white it makes the
filter badly overconfident; a Schmidt (consider) treatment is consistent but
more than doubles the errors. So, given a :class:`FixErrorModel`, the filter
estimates them: each satellite in a fix names a state block of its constant
offset (and three orbit errors, or a block of three shared by all satellites
for a common orbit shift), which enter the measurement through the fix's
gain; a satellite's block is dropped ``DROP_AFTER_S`` (:mod:`.common`) after
the last fix that included it.

What a fix hands the filter. The 6 position and velocity values alone
discard what the fix's residuals show of each satellite's constant errors,
and re-estimating the receiver offsets at every fix discards that they are
constant; in a mixed sky (9-17 satellites, 2-4 clocks) that lost all the
gain of the mix. So each fix aid carries the fix with its receiver offsets
(a near-constant state block per clock, as the tight filter has) and its
residuals in the space orthogonal to the fix's states (:class:`LeoFix`): to
first order what the epoch's Doppler hold. The filter stays loose in what it
needs: fixes from the snapshot solver, which chooses, checks and solves the
Doppler alone; without a fix (fewer than 6 + k usable Doppler) there is no
aid, and the INS carries the solution. The measurements behind these
choices: docs/notes/loose-fix-errors.md.

Corrections every ``correction_period_s`` (:func:`fix_aids`): the fixes in
between are not used, but each names its satellites' blocks
(:class:`FixSighting`), so that a satellite keeps its states while it stays
in view.

Fixes that cannot be checked. The caller hands the filter only fixes with
a spare Doppler or, without one, a well-conditioned geometry
(:func:`checkable_fixes`): a zero-redundancy fix near a singular geometry
is far from linear in its Doppler errors and its linearised covariance lets
it through the innovation gate kilometres off. And a run of
:data:`REOPEN_AFTER` fixes failing the gate re-opens it with the INS
covariance raised (:class:`leosop.fusion.engine.EngineSettings`
``reopen_inflates``), so a filter misled once is not locked out of every
later fix. leosop/data/studies/README.md has the run that showed both.
"""

import dataclasses

import numpy as np

from .. import frames
from ..ins.error_model import DPOS, DV
from ..rotations import quat_to_dcm
from .aids import Aid, StateBlock
from .common import (
    DROP_AFTER_S,
    GATE_PROBABILITY,
    N_INS,
    RX_OFFSET_PSD_HZ2_PER_S,
    RX_OFFSET_SIGMA_HZ,
    FusionResult,
    initial_covariance,
    pos_jacobian,
)
from .engine import EngineSettings, run

__all__ = [
    "MAX_GDOP_UNCHECKED",
    "MIN_REDUNDANCY",
    "PAIR_FIELDS",
    "REOPEN_AFTER",
    "FixErrorModel",
    "FixLog",
    "FixSighting",
    "LeoFix",
    "checkable_fixes",
    "engine_settings",
    "fix_aids",
]

#: Fewest measurements beyond the fix's states for the filter to use it (see :func:`checkable_fixes`).
MIN_REDUNDANCY = 1
#: Largest Doppler GDOP of a fix without redundancy that the filter uses.
MAX_GDOP_UNCHECKED = 300.0
#: Consecutive fixes failing the gate after which the filter re-opens it (see :func:`engine_settings`).
REOPEN_AFTER = 10

#: The :class:`FixErrorModel` fields with one row per satellite-epoch pair.
PAIR_FIELDS = ("epoch_index", "sat_index", "gain_ecef", "jacobian_pv", "clock_index", "weight_sqrt", "residual_hz",
               "sigma_white_hz")


@dataclasses.dataclass(frozen=True)
class FixErrorModel:
    """What each fix is made of: its least-squares gain, its residuals and its receiver clocks.

    A snapshot fix is ``x = x_true + G e`` to first order, with ``G`` the
    weighted least-squares gain of its epoch and ``e`` the Doppler errors of
    the satellites it used: ``e_j = o_j + h_j . dr_j + n_j`` (clock-induced
    offset, orbit error ``dr_j`` seen through the Doppler's sensitivity ``h_j``
    to the satellite's position, white estimator noise of sigma
    ``sigma_white_hz``). Its whitened residuals ``W^(1/2) r`` are
    ``(I - P) W^(1/2) e``, ``P`` the projection on the columns of
    ``W^(1/2) J`` (``J`` the Doppler's Jacobian in the fix's states): the
    part of the satellites' errors that the fix did not absorb. One row per
    satellite-epoch pair used in a fix, sorted by epoch.

    Attributes
    ----------
    epoch_index, sat_index : ndarray of int, (m,)
    gain_ecef : ndarray, (m, 6 + k)
        The pair's column of ``G``: d[pos, vel (ECEF), receiver offsets] / d(Doppler)
        [m/Hz, m/s/Hz, 1]; zero for the clocks absent at its epoch.
    jacobian_pv : ndarray, (m, 6)
        d(Doppler) / d[receiver pos, vel] (ECEF) at the fix [Hz/m, Hz/(m/s)];
        its position part is ``h_j`` (a satellite believed ``dr`` away acts as
        a receiver moved by ``-dr``).
    clock_index : ndarray of int, (m,)
        The pair's receiver clock, 0 .. k - 1.
    weight_sqrt : ndarray, (m,)
        ``W^(1/2)``: one over the sigma the fix weighted the Doppler by [1/Hz].
    residual_hz : ndarray, (m,)
        Measured minus modelled Doppler at the fix.
    sigma_white_hz : ndarray, (m,)
        Sigma of the pair's white estimator noise.
    fix_clock_hz : ndarray, (n_ep, k)
        Each fix's receiver offsets, NaN for a clock absent at the epoch.
    offset_sigma_hz : float or ndarray, (n_sats,)
        Prior of each offset about its constellation's mean (which that
        constellation's receiver offset absorbs): one for all, or satellite
        j's at index j.
    orbit_sigma_m : float
        Prior of the orbit error per axis.
    orbit_model : {"independent", "common"}
        One orbit error per satellite, or one shift shared by all.
    """

    epoch_index: np.ndarray
    sat_index: np.ndarray
    gain_ecef: np.ndarray
    jacobian_pv: np.ndarray
    clock_index: np.ndarray
    weight_sqrt: np.ndarray
    residual_hz: np.ndarray
    sigma_white_hz: np.ndarray
    fix_clock_hz: np.ndarray
    offset_sigma_hz: float | np.ndarray
    orbit_sigma_m: float
    orbit_model: str = "independent"

    @property
    def orbit_hz_per_m(self):
        """``h_j``: d(Doppler error) / d(orbit error, ECEF) [Hz/m], (m, 3)."""
        return self.jacobian_pv[:, :3]

    @property
    def n_clocks(self):
        """Receiver clocks k (constellations)."""
        return self.fix_clock_hz.shape[1]


def _enu_from_ecef_pv(lat_rad, lon_rad):
    """``T`` mapping ECEF ``[pos, vel]`` to ENU ``[vel, pos]``, (6, 6)."""
    C_n_e = frames.C_e_n(lat_rad, lon_rad).T
    T = np.zeros((6, 6))
    T[0:3, 3:6] = C_n_e
    T[3:6, 0:3] = C_n_e
    return T


def checkable_fixes(n_used, cov, gdop):
    """Whether each snapshot fix is fit for the filter: redundant, or of a well-conditioned geometry.

    A fix of ``6 + k`` states (k receiver clocks) from ``6 + k`` Doppler fits
    them exactly: its residuals are zero whatever its errors, so neither the
    fix's chi-square test nor its outlier test can see anything. That is
    harmless while the geometry is good, but near a singular geometry the
    fix is far from linear in the Doppler errors: its linearised covariance
    (and the gain of :class:`FixErrorModel`) understate it, and the filter's
    innovation gate, whose ``S`` is dominated by that huge covariance,
    passes fixes kilometres off. So a fix without redundancy is used only up
    to a Doppler GDOP of :data:`MAX_GDOP_UNCHECKED`; a fix with at least
    :data:`MIN_REDUNDANCY` spare Doppler is always used (its residuals were checked).

    Parameters
    ----------
    n_used : ndarray of int, (n,)
        Doppler in each fix.
    cov : ndarray, (n, 6 + k, 6 + k)
        The fixes' covariance; a state's NaN diagonal means it is absent (a clock not in the sky).
    gdop : ndarray, (n,)
        The fixes' Doppler GDOP ([Shen 2024] eq. 10).

    Returns
    -------
    ndarray of bool, (n,)
    """
    n_states = np.isfinite(np.diagonal(np.asarray(cov), axis1=-2, axis2=-1)).sum(axis=-1)
    redundant = np.asarray(n_used) - n_states >= MIN_REDUNDANCY
    return (n_states > 0) & (redundant | (np.asarray(gdop) <= MAX_GDOP_UNCHECKED))


def _ins_minus_fix(state, pos_fix_ecef_m, vel_fix_ecef_mps):
    """INS minus fix ``z`` (6,) and its INS columns ``H`` (6, 15), and ``T`` (:func:`_enu_from_ecef_pv`)."""
    lat, lon, alt = state.lat_rad, state.lon_rad, state.alt_m
    T = _enu_from_ecef_pv(lat, lon)
    C_n_e = T[0:3, 3:6]
    pos_ins = frames.geodetic_to_ecef(lat, lon, alt)
    z = np.concatenate([state.vel_enu_mps - C_n_e @ vel_fix_ecef_mps, C_n_e @ (pos_ins - pos_fix_ecef_m)])
    H = np.zeros((6, N_INS))
    H[0:3, DV] = np.eye(3)
    H[3:6, DPOS] = pos_jacobian(lat, alt)
    return z, H, T


class LeoFix(Aid):
    """A LEO snapshot fix ([Shen 2024] eq. 13): ``h`` is INS minus fix, ``[v, p]`` in ENU [m/s, m].

    Without ``terms`` the fix's whole error is white, of covariance
    ``cov_pv_ecef``. With them (:func:`fix_aids`) the rows are the
    INS-minus-fix difference (6); minus the fix's receiver offsets (one per
    clock present); and ``Q^T W^(1/2) r``, the fix's whitened residuals in an
    orthonormal basis ``Q`` of the complement of the columns of
    ``W^(1/2) J``, which measure the satellites' errors alone (the fix's
    states are projected out). To first order all are linear in the INS
    errors, the offsets and the satellites' errors ``e``, plus ``B n`` with
    ``n`` the Doppler's white noise, so ``R = B diag(sigma_white^2) B^T``
    (the rows are correlated through ``n``); ``h`` subtracts the estimated
    offsets' and satellite errors' share ``B e_hat``. Together the rows hold
    what the epoch's Doppler hold about these states: what the 6 fix values
    alone discard is the residual space, in which each satellite's constant
    errors show directly (docs/notes/loose-fix-errors.md).

    Parameters
    ----------
    t_s : float
    epoch : int
        The fix's epoch index (the caller's record of the update).
    pos_fix_ecef_m, vel_fix_ecef_mps : array_like, (3,)
    cov_pv_ecef : array_like, (6, 6)
        Covariance of the fix's ``[x, y, z, vx, vy, vz]`` (ECEF); used without ``terms``.
    terms : tuple, optional
        ``(model, k, rows, clocks, orbit, sats)``: the :class:`FixErrorModel`,
        the fix's epoch index in it, its rows there (m,), the clock blocks by
        clock index, the shared orbit block (None: one per satellite) and
        the satellite blocks by satellite index.
    """

    name = "leo_fix"

    def __init__(self, t_s, epoch, pos_fix_ecef_m, vel_fix_ecef_mps, cov_pv_ecef=None, terms=None):
        super().__init__(t_s)
        self.epoch = int(epoch)
        self.pos_fix_ecef_m = np.asarray(pos_fix_ecef_m, dtype=float).reshape(3)
        self.vel_fix_ecef_mps = np.asarray(vel_fix_ecef_mps, dtype=float).reshape(3)
        self.cov_pv_ecef = None if cov_pv_ecef is None else np.asarray(cov_pv_ecef, dtype=float).reshape(6, 6)
        self.measured = np.zeros(6)
        if terms is None:
            return
        model, k, rows, clocks, orbit, sats = terms
        clk = np.flatnonzero(np.isfinite(model.fix_clock_hz[k]))
        w = model.weight_sqrt[rows]
        A = w[:, None] * np.hstack([model.jacobian_pv[rows], model.clock_index[rows, None] == clk])
        U, sv, _ = np.linalg.svd(A)
        Q = U[:, int(np.sum(sv > sv[0] * 1e-9)):]
        G = model.gain_ecef[rows]
        self._gain_pv = G[:, :6]
        self._B_low = np.vstack([-G[:, 6 + clk].T, Q.T * w])  # the clock and residual rows of B, (c + r, m)
        self._z_low = np.concatenate([-model.fix_clock_hz[k, clk], Q.T @ (w * model.residual_hz[rows])])
        self._n_clk = clk.size
        self._h = model.orbit_hz_per_m[rows]
        self._sigma2 = model.sigma_white_hz[rows] ** 2
        self._common = orbit is not None
        sat = model.sat_index[rows]
        self.states = tuple(clocks[c] for c in clk) + ((orbit,) if self._common else ()) + tuple(sats[j] for j in sat)
        self.measured = np.zeros(6 + self._B_low.shape[0])

    def _B(self, T):
        """``B`` (6 + c + r, m): the rows' sensitivity to the Doppler errors of the fix's satellites."""
        return np.vstack([-T @ self._gain_pv.T, self._B_low])

    def _error_columns(self, B):
        """d(rows)/d(true offsets and satellite errors) in the order of :attr:`states`, (6 + c + r, n_b)."""
        n_rows, m = B.shape
        c = self._n_clk
        clocks = np.zeros((n_rows, c))
        clocks[6 + np.arange(c), np.arange(c)] = -1.0
        if self._common:
            return np.hstack([clocks, B @ self._h, B])
        per_sat = np.concatenate([B[:, :, None], B[:, :, None] * self._h[None]], axis=2)  # (rows, m, 4)
        return np.hstack([clocks, per_sat.reshape(n_rows, 4 * m)])

    def _block_estimates(self, ins):
        return np.concatenate([ins.states[b.key] for b in self.states]) if self.states else np.zeros(0)

    def matrices(self, ins):
        """``(z, H, R)``: INS minus fix less the estimated errors' share, over the INS errors and :attr:`states`."""
        z, H_ins, T = _ins_minus_fix(ins.state, self.pos_fix_ecef_m, self.vel_fix_ecef_mps)
        if not self.states:
            return z, H_ins, T @ self.cov_pv_ecef @ T.T
        B = self._B(T)
        E = self._error_columns(B)
        # Block error = estimate - truth: the truth's share E e = E (e_hat - de).
        z = np.concatenate([z, self._z_low]) - E @ self._block_estimates(ins)
        H = np.zeros((z.size, N_INS + E.shape[1]))
        H[:6, :N_INS] = H_ins
        H[:, N_INS:] = -E
        return z, H, (B * self._sigma2) @ B.T

    def predict(self, ins):
        return self.matrices(ins)[0]

    def design(self, ins):
        return self.matrices(ins)[1]


class FixSighting(Aid):
    """A fix between corrections: no rows, it names its satellites' blocks to keep them (and add the new)."""

    name = "leo_fix_seen"
    gated = False

    def __init__(self, t_s, states):
        super().__init__(t_s)
        self.states = tuple(states)
        self.measured = np.zeros(0)
        self.R = np.zeros((0, 0))

    def predict(self, ins):
        return np.zeros(0)

    def design(self, ins):
        return np.zeros((0, N_INS + sum(b.size for b in self.states)))


def _blocks(model):
    """The state blocks of ``model``: clocks by clock index, the shared orbit block (or None), satellites by index."""
    clocks = [StateBlock(f"leo_fix_clock:{c}", (0.0,), (RX_OFFSET_SIGMA_HZ,), (RX_OFFSET_PSD_HZ2_PER_S,))
              for c in range(model.n_clocks)]
    orbit_sigma = max(model.orbit_sigma_m, 1e-3)
    common = model.orbit_model == "common"
    orbit = StateBlock("leo_fix_orbit", (0.0,) * 3, (orbit_sigma,) * 3, (0.0,) * 3) if common else None
    offset_sigma = np.asarray(model.offset_sigma_hz, dtype=float)
    per_sat = 1 if common else 4
    sats = {int(j): StateBlock(f"leo_fix_sat:{j}", (0.0,) * per_sat,
                               (float(offset_sigma if offset_sigma.ndim == 0 else offset_sigma[j]),)
                               + (orbit_sigma,) * (per_sat - 1), (0.0,) * per_sat,
                               drop_after_s=DROP_AFTER_S) for j in np.unique(model.sat_index)}
    return clocks, orbit, sats


def fix_aids(t_s, pos_fix_ecef_m, vel_fix_ecef_mps, cov_pv_ecef, correction_period_s, fix_errors=None):
    """One aid per fix: a :class:`LeoFix` at each correction, a :class:`FixSighting` between them.

    A correction is due at the first fix at least ``correction_period_s``
    after the previous correction (the first: after the start, ``t_s[0]``).
    The fix of epoch 0 (the start) is not used.

    Parameters
    ----------
    t_s : ndarray, (n,)
        Epoch times on the filter's clock.
    pos_fix_ecef_m, vel_fix_ecef_mps : ndarray, (n, 3)
        NaN rows where there is no fix (or one the filter must not take).
    cov_pv_ecef : ndarray, (n, 6, 6)
        The fixes' covariance, used without ``fix_errors`` (their whole error white).
    correction_period_s : float
    fix_errors : FixErrorModel, optional
        What the fixes are made of: each fix then carries its offsets,
        residuals and satellites' blocks (module docstring).

    Returns
    -------
    list of Aid
    """
    have = np.flatnonzero(np.isfinite(pos_fix_ecef_m).all(axis=-1))
    have = have[have > 0]
    if fix_errors is not None:
        blocks = _blocks(fix_errors)
        bounds = np.searchsorted(fix_errors.epoch_index, np.arange(len(t_s) + 1))
    out, last_s = [], t_s[0]
    for k in have:
        rows = np.arange(bounds[k], bounds[k + 1]) if fix_errors is not None else None
        if t_s[k] - last_s < correction_period_s - 1e-9:
            if fix_errors is not None:
                out.append(FixSighting(t_s[k], [blocks[2][j] for j in fix_errors.sat_index[rows]]))
            continue
        last_s = t_s[k]
        terms = None if fix_errors is None else (fix_errors, k, rows) + blocks
        out.append(LeoFix(t_s[k], k, pos_fix_ecef_m[k], vel_fix_ecef_mps[k], cov_pv_ecef[k], terms))
    return out


def engine_settings(settings, reopen_after=REOPEN_AFTER):
    """The :class:`leosop.fusion.engine.EngineSettings` of a :class:`leosop.fusion.common.FilterSettings`.

    Constant biases (no random walk), the filter's step, the gate of
    :data:`~leosop.fusion.common.GATE_PROBABILITY` (none when
    ``settings.gate`` is false) re-opened after ``reopen_after`` rejected
    fixes with the INS covariance raised (None: never re-opened).
    """
    return EngineSettings(settings.gyro_arw_rad_per_rt_s, settings.accel_vrw_mps2_per_rt_hz, 0.0, 0.0,
                          step_s=settings.step_s, gate_probability=GATE_PROBABILITY if settings.gate else 1.0,
                          reopen_after=np.iinfo(np.int64).max if reopen_after is None else reopen_after,
                          reopen_inflates=True)


class FixLog:
    """What the engine did with the fixes, epoch by epoch: pass as ``on_aid`` to :func:`leosop.fusion.engine.run`.

    Parameters
    ----------
    n : int
        Epochs of the run (fix aids carry their epoch index).
    """

    def __init__(self, n):
        self.updated = np.zeros(n, dtype=bool)
        self.rejected = np.zeros(n, dtype=bool)
        self.reopened = np.zeros(n, dtype=bool)
        self.nis = np.full(n, np.nan)
        self.nis_dof = np.zeros(n, dtype=int)
        self.innovation = np.full((n, 6), np.nan)
        self.innovation_cov = np.full((n, 6, 6), np.nan)

    def __call__(self, index, aid, z, S, used, failed):
        if not isinstance(aid, LeoFix):
            return
        k = aid.epoch
        if not used:
            self.rejected[k] = True
            return
        self.updated[k], self.reopened[k] = True, failed
        self.nis[k], self.nis_dof[k] = float(z @ np.linalg.solve(S, z)), z.size
        self.innovation[k], self.innovation_cov[k] = z[:6], S[:6, :6]

    def result(self, res):
        """The :class:`leosop.fusion.common.FusionResult` of engine result ``res``, recorded at the fix epochs
        with its ``cov_ins`` (:func:`fuse`'s settings)."""
        n = self.updated.size
        return FusionResult(res.t_s[:n] - res.t_s[0], res.lat_rad[:n], res.lon_rad[:n], res.alt_m[:n],
                            res.vel_enu_mps[:n], quat_to_dcm(res.q_n_b[:n]), res.cov_ins[:n], self.updated,
                            self.rejected, self.nis, self.nis_dof, res.gyro_bias_rad_per_s[:n],
                            res.accel_bias_mps2[:n], innovation=self.innovation,
                            innovation_cov=self.innovation_cov, reopened=self.reopened)


def fuse(state0, dtheta_b_rad, dvel_b_mps, dt_s, fixes, settings, *, fix_errors=None, reopen_after=REOPEN_AFTER,
         progress=None):
    """Loose coupling: the INS corrected by the fixes' aids (:func:`fix_aids`) in the engine, at the fix epochs.

    Parameters
    ----------
    state0 : leosop.ins.strapdown.NavState
        Initial INS state (with its errors).
    dtheta_b_rad, dvel_b_mps : ndarray, (n_imu, 3)
        Measured IMU increments at interval ``dt_s``.
    dt_s : float
    fixes : tuple (pos_ecef_m, vel_ecef_mps, cov_pv)
        LEO fixes at every step epoch ``k * settings.step_s`` (k = 0 .. n-1):
        shapes (n, 3), (n, 3), (n, 6, 6); NaN rows where there is no fix.
    settings : leosop.fusion.common.FilterSettings
    fix_errors : FixErrorModel, optional
    reopen_after : int or None
        See :func:`engine_settings`.
    progress : callable, optional
        Wraps the iterator over INS updates.

    Returns
    -------
    leosop.fusion.common.FusionResult
        At the fix epochs that the IMU covers.
    """
    pos_fix, vel_fix, cov_fix = fixes
    every = round(settings.step_s / dt_s) // 2
    if every < 1 or abs(2 * every * dt_s - settings.step_s) > 1e-9:
        raise ValueError(f"step_s={settings.step_s} must be an even multiple of dt_s={dt_s}")
    t_imu = (np.arange(dtheta_b_rad.shape[0]) + 1) * dt_s
    n = min(len(pos_fix), dtheta_b_rad.shape[0] // (2 * every) + 1)
    t_fix = np.r_[0.0, t_imu[2 * every * np.arange(1, n) - 1]]  # exactly the engine's output times
    aids = fix_aids(t_fix, pos_fix[:n], vel_fix[:n], cov_fix[:n], settings.correction_period_s, fix_errors)
    log = FixLog(n)
    es = dataclasses.replace(engine_settings(settings, reopen_after), record_every=every, record_cov_ins=True)
    res = run(state0, initial_covariance(settings, state0.lat_rad, state0.alt_m), t_imu, np.full(t_imu.size, dt_s),
              dtheta_b_rad, dvel_b_mps, aids, es, progress=progress, on_aid=log)
    return log.result(res)
