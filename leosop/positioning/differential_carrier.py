"""Differential carrier-phase fix of a static rover from a base at a known site (issue 23).

Both receivers track the accumulated carrier phase of the same satellites
(:func:`~leosop.replay.carrier.track_carrier`: the integral of ``doppler_hz``,
so ``-lambda phi = range + clock + lambda N``). The single difference between
receivers, rover minus base, of satellite i at epoch k, in metres::

    y_ik = -lambda (phi_r - phi_b) = rho_r(x) - rho_b + (u_r - u_b)^T C_ik d_i + c_k + lambda N_i + e_ik

holds the rover's position ``x``, the range difference the satellite's
element-set offset ``d_i`` (radial / along / cross-track, a prior of
:data:`~leosop.positioning.differential.ORBIT_SIGMA_RTN_M`; ``C_ik`` its
inertial-orbit frame, :func:`~leosop.positioning.differential.rtn_frames`)
makes between the two lines of sight ``u``, a rover-minus-base clock phase
``c_k`` per epoch, and one ambiguity per satellite and pair of arcs. The
satellite's oscillator cancels (both receivers see it within microseconds).
The clocks are eliminated epoch by epoch (the weighted projection that
removes each epoch's weighted mean, which gives the estimate of the double
differences with their correct, correlated covariance); one ambiguity, the
one with most rows, is the datum, so the others are double-difference
ambiguities against it. Weighted least squares, Gauss-Newton in ``x``.

Integer fixing (``integer=True``): the float double-difference ambiguities
and their covariance go to LAMBDA
(:func:`~leosop.gnss.lambda_.partial_fix`: ratio test of [Euler 1991] and the
bootstrapped success rate of [Teunissen 1998], partial fixing) and the position is conditioned on the accepted integers.
The double differences are integers only when each receiver's phase is the
received carrier phase up to whole cycles and a clock common to its
satellites; a tracker whose phase starts from an arbitrary offset per
satellite (:func:`~leosop.replay.carrier.track_carrier` references each
satellite to its first block) gives real-valued ones: the fix is then
float, and says so.

The base's phase must be on the rover's epochs (the same block plan):
interpolating a phase between blocks correlates the rows across epochs,
which the per-epoch clock elimination does not model.
"""

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..constants import C_MPS
from ..errors import InputError
from ..gnss.lambda_ import partial_fix
from .differential import ORBIT_SIGMA_RTN_M, rtn_frames

__all__ = ["CarrierFix", "RATIO_MIN", "SUCCESS_MIN", "solve_differential_carrier"]

#: Ratio test threshold of the integer fix (second-best over best squared norm, [Euler 1991]; as the PPP-AR).
RATIO_MIN = 3.0
#: Least bootstrapped success rate of a fixed subset, beside the ratio test ([Teunissen 1998]; measured in
#: tools/bench_differential_carrier.py).
SUCCESS_MIN = 0.999
#: Gauss-Newton stops when the position step is below this [m] (0.1 mm, far inside any sigma here).
_XTOL_M = 1e-4
_MAX_ITER = 10


@dataclass(frozen=True, eq=False)
class CarrierFix:
    """A static rover's differential carrier-phase fix.

    Attributes
    ----------
    pos_ecef_m : ndarray, (3,)
        The fix: the fixed solution when ``status`` is ``fixed`` or ``partial``, else the float one.
    cov : ndarray, (3, 3)
        Its covariance [m^2] (the fixed one assumes the integers right; the ratio test is the evidence).
    pos_float_ecef_m, cov_float : ndarray, (3,), (3, 3)
        The float solution.
    status : str
        ``fixed`` (every double-difference ambiguity an integer), ``partial``
        (some), ``float`` (none: ``integer`` off, or the ratio test failed).
    ratio : float
        The ratio test's value of the last subset tried (NaN when not tried).
    n_ambiguities, n_fixed : int
        Double-difference ambiguities (all ambiguities but the datum) and how many were fixed.
    ambiguity_cycles, ambiguity_sigma_cycles : ndarray, (n_ambiguities,)
        The float double-difference ambiguities and their sigmas.
    orbit_rtn_m, orbit_sigma_rtn_m : ndarray, (n_sats, 3)
        Estimated element-set offsets and their sigmas (float solution).
    chi2, chi2_p : float
        Weighted residual sum of squares of the float solution (priors included) and its upper-tail probability.
    dof : int
    n_rows, n_epochs, n_sats : int
        Single differences used, epochs with at least two satellites, satellites with a used row.
    residuals_m : ndarray, (n_sats, n_epochs)
        Float solution's residual of each single difference after its epoch's clock (NaN where unused).
    iterations : int
    """

    pos_ecef_m: np.ndarray
    cov: np.ndarray
    pos_float_ecef_m: np.ndarray
    cov_float: np.ndarray
    status: str
    ratio: float
    n_ambiguities: int
    n_fixed: int
    ambiguity_cycles: np.ndarray
    ambiguity_sigma_cycles: np.ndarray
    orbit_rtn_m: np.ndarray
    orbit_sigma_rtn_m: np.ndarray
    chi2: float
    chi2_p: float
    dof: int
    n_rows: int
    n_epochs: int
    n_sats: int
    residuals_m: np.ndarray
    iterations: int


def _inverse(N):
    """Inverse of the normal matrix N (p, p), scaled to a unit diagonal first (its columns span 1e-5 to 1e7); None
    when it is singular to working precision."""
    d = 1.0 / np.sqrt(np.diag(N))
    Ns = N * d[:, None] * d[None, :]
    if np.linalg.cond(Ns) > 1e12:
        return None
    return np.linalg.inv(Ns) * d[:, None] * d[None, :]


def _check(name, a, shape):
    a = np.asarray(a, dtype=float)
    if a.shape != shape:
        raise InputError(f"{name}: shape {a.shape}, expected {shape}", param=name)
    return a


def solve_differential_carrier(phase_rover_cycles, sigma_rover_cycles, arc_rover, phase_base_cycles,
                               sigma_base_cycles, arc_base, pos_sv_rover_ecef_m, pos_sv_base_ecef_m,
                               vel_sv_ecef_mps, base_pos_ecef_m, pos0_ecef_m, *, carrier_hz,
                               orbit_sigma_rtn_m=ORBIT_SIGMA_RTN_M, integer=True, ratio_min=RATIO_MIN,
                               success_min=SUCCESS_MIN):
    """Static rover position from between-receiver carrier-phase differences.

    Parameters
    ----------
    phase_rover_cycles, sigma_rover_cycles : array_like, (n_sats, n_epochs)
        The rover's accumulated phase and its sigma (NaN: no phase), on common epochs.
    arc_rover : array_like of int, (n_sats, n_epochs)
        Arc numbers (whole cycles continuous within an arc; negative: none).
    phase_base_cycles, sigma_base_cycles, arc_base : array_like, (n_sats, n_epochs)
        The base's, on the same epochs.
    pos_sv_rover_ecef_m, pos_sv_base_ecef_m : array_like, (n_sats, n_epochs, 3)
        Satellite positions with each receiver's light time (rover's from ``pos0_ecef_m``).
    vel_sv_ecef_mps : array_like, (n_sats, n_epochs, 3)
        Satellite velocities (the orbit frames).
    base_pos_ecef_m, pos0_ecef_m : array_like, (3,)
        The base's known site; the rover's first guess (within km).
    carrier_hz : float
        The phase's carrier frequency.
    orbit_sigma_rtn_m : array_like, (3,)
        Prior sigmas of each satellite's element-set offset (zeros: no offset states).
    integer : bool
        Try integer fixing (only when the double differences are integers, see the module).
    ratio_min, success_min : float
        Ratio test threshold and least bootstrapped success rate of a fixed subset
        (:func:`~leosop.gnss.lambda_.partial_fix`).

    Returns
    -------
    CarrierFix

    Raises
    ------
    InputError
        Shapes that disagree; fewer than two satellites with phase from both receivers at two epochs.
    """
    phr = np.asarray(phase_rover_cycles, dtype=float)
    if phr.ndim != 2:
        raise InputError(f"phase_rover_cycles: shape {phr.shape}, expected (n_sats, n_epochs)",
                         param="phase_rover_cycles")
    shape = phr.shape
    n_sats, n_ep = shape
    sr = _check("sigma_rover_cycles", sigma_rover_cycles, shape)
    phb = _check("phase_base_cycles", phase_base_cycles, shape)
    sb = _check("sigma_base_cycles", sigma_base_cycles, shape)
    ar = _check("arc_rover", arc_rover, shape).astype(int)
    ab = _check("arc_base", arc_base, shape).astype(int)
    p_r = _check("pos_sv_rover_ecef_m", pos_sv_rover_ecef_m, shape + (3,))
    p_b = _check("pos_sv_base_ecef_m", pos_sv_base_ecef_m, shape + (3,))
    v_sv = _check("vel_sv_ecef_mps", vel_sv_ecef_mps, shape + (3,))
    base = _check("base_pos_ecef_m", base_pos_ecef_m, (3,))
    x = _check("pos0_ecef_m", pos0_ecef_m, (3,)).copy()
    lam = C_MPS / float(carrier_hz)

    use = (np.isfinite(phr) & np.isfinite(phb) & (sr > 0) & (sb > 0) & (ar >= 0) & (ab >= 0)
           & np.all(np.isfinite(p_r) & np.isfinite(p_b) & np.isfinite(v_sv), axis=-1))
    use &= np.sum(use, axis=0)[None, :] >= 2          # an epoch's clock takes one row: two satellites needed
    if np.sum(np.any(use, axis=0)) < 2:
        raise InputError("no double difference: fewer than two satellites with phase from both the rover and "
                         "the base at two or more epochs (no satellite in common?)")
    sat_used = np.any(use, axis=1)
    w = np.where(use, 1.0 / (lam**2 * (np.where(use, sr, 1.0) ** 2 + np.where(use, sb, 1.0) ** 2)), 0.0)
    y = np.where(use, -lam * (phr - phb), 0.0)

    # ambiguities: one per satellite and pair of arcs; the one with most rows is the datum
    key = np.stack([np.broadcast_to(np.arange(n_sats)[:, None], shape), ar, ab], axis=-1)[use]
    keys, amb_of_row, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    amb = np.full(shape, -1)
    amb[use] = amb_of_row.ravel()
    datum = int(np.argmax(counts))
    n_amb = len(keys) - 1
    col_of_amb = np.where(np.arange(len(keys)) < datum, np.arange(len(keys)), np.arange(len(keys)) - 1)
    col_of_amb[datum] = -1

    prior = np.asarray(orbit_sigma_rtn_m, dtype=float).reshape(3)
    has_orbit = bool(np.any(prior > 0))
    n_orb = 3 * n_sats if has_orbit else 0
    n_par = 3 + n_orb + n_amb
    C_rtn = np.nan_to_num(rtn_frames(p_b, v_sv)[0])                    # (n_sats, n_ep, 3, 3)
    rho_b = np.linalg.norm(p_b - base, axis=-1)
    prior_w = np.zeros(n_par)
    if has_orbit:  # an axis of sigma 0 is held at zero (1 um)
        prior_w[3:3 + n_orb] = np.tile(1.0 / np.maximum(prior, 1e-6) ** 2, n_sats)
    # Whole cycles taken out of each ambiguity first (from the first guess: its single differences less their
    # epoch's weighted mean): the ambiguities left are small, so the solve keeps its precision (a float ambiguity
    # of 1e6 cycles is 26 km, and the solve's conditioning would turn its rounding into metres).
    r_first = np.where(use, y - (np.linalg.norm(p_r - x, axis=-1) - rho_b), 0.0)
    sw = np.sum(w, axis=0)
    r_first -= (np.sum(w * r_first, axis=0) / np.where(sw > 0, sw, 1.0))[None, :]
    n0 = np.round(np.bincount(amb[use], weights=r_first[use], minlength=len(keys)) / counts / lam)
    y = np.where(use, y - lam * n0[np.maximum(amb, 0)], 0.0)
    d = np.zeros((n_sats, 3))      # element-set offsets, relinearised (their square over the range: 0.1 mm here)
    p_r0, rho_r0 = p_r, np.linalg.norm(p_r - x, axis=-1)
    i_row, k_row = np.nonzero(use)
    cols = col_of_amb[amb[i_row, k_row]]
    real = cols >= 0
    for it in range(1, _MAX_ITER + 1):
        # the rover's light time from the current position, not the first guess (30 m: 0.8 mm of satellite motion)
        off = np.einsum("skij,sj->ski", C_rtn, d)
        q_r = p_r0 + off - v_sv * ((np.linalg.norm(p_r0 - x, axis=-1) - rho_r0) / C_MPS)[..., None]
        q_b = p_b + off
        rho_r, rho_b = np.linalg.norm(q_r - x, axis=-1), np.linalg.norm(q_b - base, axis=-1)
        u_r, u_b = (q_r - x) / rho_r[..., None], (q_b - base) / rho_b[..., None]
        A = np.zeros(shape + (n_par,))
        A[..., :3] = np.where(use[..., None], -u_r, 0.0)
        if has_orbit:
            g = np.where(use[..., None], np.einsum("ski,skij->skj", u_r - u_b, C_rtn), 0.0)  # (n_sats, n_ep, 3)
            idx = 3 + 3 * np.arange(n_sats)[:, None] + np.arange(3)[None, :]
            A[np.arange(n_sats)[:, None, None], np.arange(n_ep)[None, :, None], idx[:, None, :]] = g
        A[i_row[real], k_row[real], 3 + n_orb + cols[real]] = lam
        r0 = np.where(use, y - (rho_r - rho_b), 0.0)
        # per-epoch clock eliminated: subtract each epoch's weighted mean of the rows (and of the partials)
        Ap = A - (np.einsum("sk,skp->kp", w, A) / np.where(sw > 0, sw, 1.0)[:, None])[None]
        rp = r0 - (np.sum(w * r0, axis=0) / np.where(sw > 0, sw, 1.0))[None, :]
        N = np.einsum("sk,skp,skq->pq", w, Ap, Ap) + np.diag(prior_w)
        b = np.einsum("sk,skp,sk->p", w, Ap, rp)
        b[3:3 + n_orb] -= prior_w[3:3 + n_orb] * d.ravel()[:n_orb]
        cov = _inverse(N)
        if cov is None:
            raise InputError("the carrier-phase fix is singular: too few satellites or epochs")
        dx = cov @ b                # position and offset steps, ambiguities whole
        x = x + dx[:3]
        d = d + dx[3:3 + n_orb].reshape(d.shape) if has_orbit else d
        if np.linalg.norm(dx[:3]) < _XTOL_M:
            break
    res = np.where(use, rp - np.einsum("skp,p->sk", Ap, dx), np.nan)
    chi2 = float(np.nansum(w * res**2) + np.sum(prior_w[3:3 + n_orb] * d.ravel()[:n_orb] ** 2))
    n_epochs = int(np.sum(np.any(use, axis=0)))
    dof = int(np.sum(use) - n_epochs - 3 - n_amb)
    a_hat = dx[3 + n_orb:]
    n0_dd = np.delete(n0 - n0[datum], datum)
    Q_a = cov[3 + n_orb:, 3 + n_orb:]
    pos, P, status, ratio, n_fixed = x, cov[:3, :3], "float", float("nan"), 0
    if integer and n_amb > 0:
        fixed, a_fix, ratio = partial_fix(a_hat, Q_a, ratio_min=ratio_min, min_fixed=1, success_min=success_min)
        n_fixed = int(fixed.sum())
        if n_fixed:
            f = 3 + n_orb + np.flatnonzero(fixed)
            K = cov[:3, f] @ np.linalg.inv(cov[np.ix_(f, f)])
            pos = x - K @ (a_hat[fixed] - a_fix[fixed])
            P = cov[:3, :3] - K @ cov[f, :3]
            status = "fixed" if n_fixed == n_amb else "partial"
    orb = d
    orb_sig = np.sqrt(np.diag(cov)[3:3 + n_orb]).reshape(-1, 3) if has_orbit else np.zeros((n_sats, 3))
    return CarrierFix(
        pos_ecef_m=pos, cov=0.5 * (P + P.T), pos_float_ecef_m=x, cov_float=cov[:3, :3], status=status, ratio=ratio,
        n_ambiguities=n_amb, n_fixed=n_fixed, ambiguity_cycles=a_hat + n0_dd,
        ambiguity_sigma_cycles=np.sqrt(np.diag(Q_a)),
        orbit_rtn_m=orb, orbit_sigma_rtn_m=orb_sig, chi2=chi2,
        chi2_p=float(chi2_dist.sf(chi2, dof)) if dof > 0 else float("nan"), dof=dof, n_rows=int(np.sum(use)),
        n_epochs=n_epochs, n_sats=int(np.sum(sat_used)), residuals_m=res, iterations=it)
