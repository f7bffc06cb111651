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
ambiguities against it. Weighted least squares by QR, Gauss-Newton in ``x``
and ``d`` (relinearised: ``|d|^2 / rho`` is a tenth of a millimetre, which
150 s of phase see).

Joint fit (``sat_clock_degree``), as the Doppler one of
:mod:`~leosop.positioning.differential`. A single difference sees an
element-set offset only through the baseline (~1/100 of it at 7.5 km);
over 20 s that part looks like the rover's position, and the fix's sigma is
a metre. At its known site the base sees the offset's whole range, which
curves over the pass. Keeping each receiver's own phase::

    y_r = rho_r(x) + u_r^T C d_i + s_i(t) + c_r,k + lambda N_r
    y_b = rho_b    + u_b^T C d_i + s_i(t) + c_b,k + lambda N_b

with ``s_i`` satellite i's phase as both see it (a constant and the
integral of a frequency polynomial of ``sat_clock_degree``; one
satellite's is the datum of the receivers' clocks) tells ``d`` apart from
the rover's position (20 s: 0.18 m median, tools/bench_differential_carrier.py).
The price is the assumption on the satellites' oscillators, as for the
Doppler joint fit.

Integer fixing (``integer=True``): the float double-difference ambiguities
and their covariance go to LAMBDA
(:func:`~leosop.gnss.lambda_.partial_fix`: ratio test of [Euler 1991] and the
bootstrapped success rate of [Teunissen 1998], partial fixing) and the
position is conditioned on the accepted integers.
The double differences are integers only when each receiver's phase is the
received carrier phase up to whole cycles and a clock common to its
satellites (:func:`~leosop.replay.carrier.track_carrier` refers its phase
to the received central tone for this); a tracker whose phase starts from an
arbitrary offset per satellite gives real-valued ones, which the ratio test
and the success-rate bound should refuse.

The base's phase must be on the rover's epochs (the same block plan):
interpolating a phase between blocks correlates the rows across epochs,
which the per-epoch clock elimination does not model.
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.stats import chi2 as chi2_dist

from ..constants import C_MPS, OMEGA_E_RAD_PER_S
from ..errors import InputError
from ..gnss.lambda_ import partial_fix
from .differential import ORBIT_SIGMA_RTN_M, rtn_frames

__all__ = ["CHI2_ALPHA", "CarrierFix", "RATIO_MIN", "SUCCESS_MIN", "solve_differential_carrier"]

#: Ratio test threshold of the integer fix (second-best over best squared norm, [Euler 1991]; as the PPP-AR).
RATIO_MIN = 3.0
#: Least bootstrapped success rate of a fixed subset, beside the ratio test ([Teunissen 1998]; measured in
#: tools/bench_differential_carrier.py).
SUCCESS_MIN = 0.999
#: Residuals whose chi-square has an upper-tail probability below this fail their test: the covariance is
#: scaled by chi2 / dof (the phase noise larger than its stated sigma; as :mod:`~leosop.positioning.robust_ls`).
CHI2_ALPHA = 1e-3
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
    variance_factor : float
        ``chi2 / dof`` when ``chi2_p`` is below :data:`CHI2_ALPHA` (every covariance here is scaled by it), else 1.
    n_rows, n_epochs, n_sats : int
        Single differences used, epochs with at least two satellites, satellites with a used row.
    residuals_m : ndarray, (n_sats, n_epochs)
        Float solution's residual of each single difference after its epoch's clock, in the joint fit the
        rover's residual less the base's (NaN where unused).
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
    variance_factor: float
    n_rows: int
    n_epochs: int
    n_sats: int
    residuals_m: np.ndarray
    iterations: int


def _solve(Aw, rw):
    """Least squares of the whitened rows Aw (m, p), rw (m,) by QR (the normal matrix would square a condition
    number of ~1e7: prior-only directions beside mm-level phase): the solution (p,) and its covariance (p, p).

    Raises
    ------
    InputError
        A singular design (too few satellites or epochs).
    """
    d = 1.0 / np.maximum(np.linalg.norm(Aw, axis=0), np.finfo(float).tiny)
    Q, R = np.linalg.qr(Aw * d)
    r = np.abs(np.diag(R))
    if not r.min() > 1e-10 * r.max():
        raise InputError("the carrier-phase fix is singular: too few satellites or epochs")
    Rinv = solve_triangular(R, np.eye(R.shape[0]))
    return d * (Rinv @ (Q.T @ rw)), (d[:, None] * Rinv) @ (d[:, None] * Rinv).T


def _whole_cycles(n0, dd_keys, joint):
    """The whole cycles taken out of each double-difference ambiguity, (n_dd,)."""
    sd = n0[dd_keys[:, 0]] - (n0[dd_keys[:, 1]] if joint else 0.0)
    return sd[:-1] - sd[-1]


def _check(name, a, shape):
    a = np.asarray(a, dtype=float)
    if a.shape != shape:
        raise InputError(f"{name}: shape {a.shape}, expected {shape}")
    return a


def solve_differential_carrier(t_s, phase_rover_cycles, sigma_rover_cycles, arc_rover, phase_base_cycles,
                               sigma_base_cycles, arc_base, pos_sv_rover_ecef_m, pos_sv_base_ecef_m,
                               vel_sv_ecef_mps, base_pos_ecef_m, pos0_ecef_m, *, carrier_hz,
                               orbit_sigma_rtn_m=ORBIT_SIGMA_RTN_M, sat_clock_degree=None, integer=True,
                               ratio_min=RATIO_MIN, success_min=SUCCESS_MIN):
    """Static rover position from between-receiver carrier-phase differences.

    Parameters
    ----------
    t_s : array_like, (n_epochs,)
        The common epochs [s], increasing.
    phase_rover_cycles, sigma_rover_cycles : array_like, (n_sats, n_epochs)
        The rover's accumulated phase and its sigma (NaN: no phase).
    arc_rover : array_like of int, (n_sats, n_epochs)
        Arc numbers (whole cycles continuous within an arc; negative: none).
    phase_base_cycles, sigma_base_cycles, arc_base : array_like, (n_sats, n_epochs)
        The base's, on the same epochs.
    pos_sv_rover_ecef_m, pos_sv_base_ecef_m : array_like, (n_sats, n_epochs, 3)
        Satellite positions with each receiver's light time (the rover's from ``pos0_ecef_m``).
    vel_sv_ecef_mps : array_like, (n_sats, n_epochs, 3)
        Satellite velocities (orbit frames, light time).
    base_pos_ecef_m, pos0_ecef_m : array_like, (3,)
        The base's known site; the rover's first guess (within km).
    carrier_hz : float
        The phase's carrier frequency.
    orbit_sigma_rtn_m : array_like, (3,)
        Prior sigmas of each satellite's element-set offset (zeros: no offset states).
    sat_clock_degree : int, optional
        None: single differences. An int: the joint fit, each receiver's own
        phase kept (its clock per epoch) and each satellite's frequency a
        polynomial of this degree in time (so its phase one degree more;
        one satellite's is the datum): the base at its known site sees the
        offsets' whole range, not only their difference.
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
        raise InputError(f"phase_rover_cycles: shape {phr.shape}, expected (n_sats, n_epochs)")
    shape = phr.shape
    n_sats, n_ep = shape
    t = _check("t_s", t_s, (n_ep,))
    if not np.all(np.diff(t) > 0):
        raise InputError("t_s: the epochs must increase")
    sr = _check("sigma_rover_cycles", sigma_rover_cycles, shape)
    phb = _check("phase_base_cycles", phase_base_cycles, shape)
    sb = _check("sigma_base_cycles", sigma_base_cycles, shape)
    ar = _check("arc_rover", arc_rover, shape).astype(int)
    ab = _check("arc_base", arc_base, shape).astype(int)
    p_r0 = _check("pos_sv_rover_ecef_m", pos_sv_rover_ecef_m, shape + (3,))
    p_b = _check("pos_sv_base_ecef_m", pos_sv_base_ecef_m, shape + (3,))
    v_sv = _check("vel_sv_ecef_mps", vel_sv_ecef_mps, shape + (3,))
    base = _check("base_pos_ecef_m", base_pos_ecef_m, (3,))
    x = _check("pos0_ecef_m", pos0_ecef_m, (3,)).copy()
    lam = C_MPS / float(carrier_hz)
    states = np.all(np.isfinite(p_r0) & np.isfinite(p_b) & np.isfinite(v_sv), axis=-1)
    ok_r = np.isfinite(phr) & (sr > 0) & (ar >= 0) & states
    ok_b = np.isfinite(phb) & (sb > 0) & (ab >= 0) & states
    both = ok_r & ok_b
    both &= np.sum(both, axis=0)[None, :] >= 2          # an epoch's clock takes one row: two satellites needed
    if np.sum(np.any(both, axis=0)) < 2:
        raise InputError("no double difference: fewer than two satellites with phase from both the rover and "
                         "the base at two or more epochs (no satellite in common?)")
    rows = _rows(lam, phr, sr, ar, phb, sb, ab, ok_r, ok_b, both, joint=sat_clock_degree is not None)
    use, y, w, key, col, combos, dd_keys, datum_sat = rows
    n_amb = combos.shape[1]
    cr, cb = (np.array([1.0]), np.array([-1.0])) if sat_clock_degree is None else (np.eye(2)[0], np.eye(2)[1])
    prior = np.asarray(orbit_sigma_rtn_m, dtype=float).reshape(3)
    n_orb = 3 * n_sats if np.any(prior > 0) else 0
    deg = -1 if sat_clock_degree is None else int(sat_clock_degree)
    clk_sats = np.delete(np.arange(n_sats), datum_sat) if deg >= 0 else np.zeros(0, int)
    n_terms = deg + 2 if deg >= 0 else 0                                # phase constant, frequency polynomial
    n_clk = clk_sats.size * n_terms
    o_clk, o_amb = 3 + n_orb, 3 + n_orb + n_clk
    n_par = o_amb + n_amb
    prior_w = np.zeros(n_par)
    prior_w[3:o_clk] = np.tile(1.0 / np.maximum(prior, 1e-6) ** 2, n_sats) if n_orb else 0.0  # sigma 0: held (1 um)
    C_rtn = np.nan_to_num(rtn_frames(p_b, v_sv)[0])                    # (n_sats, n_ep, 3, 3)
    tau = (t - 0.5 * (t[0] + t[-1]))[None, :] ** np.arange(n_terms)[:, None]  # phase terms (n_terms, n_ep)

    base_design = np.zeros(use.shape + (n_par + 1,))                    # the last column: datums, dropped below
    gi, si, ki = np.nonzero(use)
    base_design[gi, si, ki, np.where(col[key[gi, si, ki]] >= 0, o_amb + col[key[gi, si, ki]], n_par)] = lam
    for j, sat in enumerate(clk_sats):
        base_design[:, sat, :, o_clk + j * n_terms: o_clk + (j + 1) * n_terms] = lam * tau.T[None]
    base_design *= use[..., None]
    sw = np.sum(w, axis=1)                                               # (G, n_ep)
    sw = np.where(sw > 0, sw, 1.0)

    def project(a):
        """Each (receiver, epoch) group's weighted mean removed: its clock eliminated, (G, n_sats, n_ep, ...)."""
        wa = np.einsum("gsk,gsk...->gk...", w, a) / sw.reshape(sw.shape + (1,) * (a.ndim - 3))
        return a - wa[:, None]

    # Whole cycles taken out of each ambiguity first (from the first guess): the ambiguities left are small, so
    # the solve keeps its precision (1e6 cycles is 26 km, which the solve's conditioning turns into metres).
    rho_r0 = np.linalg.norm(p_r0 - x, axis=-1)
    r_first = project(np.where(use, y - (cr[:, None, None] * rho_r0 + cb[:, None, None]
                                         * np.linalg.norm(p_b - base, axis=-1)), 0.0))
    n0 = np.round(np.bincount(key[use], weights=r_first[use], minlength=col.size)
                  / np.maximum(np.bincount(key[use], minlength=col.size), 1) / lam)   # (n_keys,)
    y = np.where(use, y - lam * n0[np.maximum(key, 0)], 0.0)
    base_design = base_design[..., :-1]                                  # the datums' column: held at zero
    # The rover's light time from the current position, not the first guess (30 m: 0.8 mm of satellite motion).
    # A longer light time tau moves the apparent position R(w tau) r(t - tau) by -(v + w x r) tau: the inertial
    # velocity in ECEF axes, not v_sv (the rate over reception time), which lacks w x r (~400 m/s; left out, 30 m
    # of first guess biased the joint 60 s fix by 0.5 mm, its NEES 5.4, tools/bench_differential_carrier.py).
    v_in = v_sv + np.cross([0.0, 0.0, OMEGA_E_RAD_PER_S], p_r0)
    d = np.zeros((n_sats, 3))      # element-set offsets, relinearised (their square over the range: 0.1 mm here)
    for it in range(1, _MAX_ITER + 1):
        off = np.einsum("skij,sj->ski", C_rtn, d)
        q_r = p_r0 + off - v_in * ((np.linalg.norm(p_r0 - x, axis=-1) - rho_r0) / C_MPS)[..., None]
        q_b = p_b + off
        rho_r, rho_b = np.linalg.norm(q_r - x, axis=-1), np.linalg.norm(q_b - base, axis=-1)
        u_r, u_b = (q_r - x) / rho_r[..., None], (q_b - base) / rho_b[..., None]
        A = base_design.copy()
        A[..., :3] = -cr[:, None, None, None] * u_r[None] * use[..., None]
        if n_orb:
            u = cr[:, None, None, None] * u_r[None] + cb[:, None, None, None] * u_b[None]
            g = np.einsum("gski,skij->gskj", u, C_rtn) * use[..., None]
            for sat in range(n_sats):
                A[:, sat, :, 3 + 3 * sat: 6 + 3 * sat] = g[:, sat]
        r0 = np.where(use, y - (cr[:, None, None] * rho_r + cb[:, None, None] * rho_b), 0.0)
        Ap, rp = project(A), project(r0)
        sq = np.sqrt(w[use])[:, None]
        prior_rows = np.flatnonzero(prior_w)
        Aw = np.concatenate([sq * Ap[use], np.sqrt(prior_w[prior_rows])[:, None] * np.eye(n_par)[prior_rows]])
        rw = np.concatenate([sq[:, 0] * rp[use], -np.sqrt(prior_w[prior_rows]) * d.ravel()[prior_rows - 3]])
        dx, cov = _solve(Aw, rw)    # position and offset steps; clock terms and ambiguities whole
        x = x + dx[:3]
        d = d + dx[3:o_clk].reshape(d.shape) if n_orb else d
        if np.linalg.norm(dx[:3]) < _XTOL_M:
            break
    res = np.where(use, rp - np.einsum("gskp,p->gsk", Ap, dx), np.nan)
    chi2 = float(np.nansum(w * res**2) + np.sum(prior_w[3:o_clk] * d.ravel()[:n_orb] ** 2))
    n_groups = int(np.sum(np.any(use, axis=1)))
    dof = int(np.sum(use) - n_groups - (n_par - n_orb))
    chi2_p = float(chi2_dist.sf(chi2, dof)) if dof > 0 else float("nan")
    variance_factor = chi2 / dof if chi2_p < CHI2_ALPHA else 1.0
    cov = cov * variance_factor
    # the double-difference ambiguities: rover-minus-base single differences of each satellite and pair of arcs,
    # less the datum's (whose columns are zero)
    M = combos
    a_hat = M @ dx[o_amb:]
    Q_a = M @ cov[o_amb:, o_amb:] @ M.T
    pos, P, status, ratio, n_fixed = x, cov[:3, :3], "float", float("nan"), 0
    if integer and a_hat.size:
        try:
            fixed, a_fix, ratio = partial_fix(a_hat, Q_a, ratio_min=ratio_min, min_fixed=1, success_min=success_min)
        except ValueError:  # dependent combinations (arcs that cross): not fixed
            fixed = np.zeros(a_hat.size, bool)
        n_fixed = int(fixed.sum())
        if n_fixed:
            Mf = M[fixed]
            K = cov[:3, o_amb:] @ Mf.T @ np.linalg.inv(Mf @ cov[o_amb:, o_amb:] @ Mf.T)
            pos = x - K @ (a_hat[fixed] - a_fix[fixed])
            P = cov[:3, :3] - K @ Mf @ cov[o_amb:, :3]
            status = "fixed" if n_fixed == a_hat.size else "partial"
    orb_sig = np.sqrt(np.diag(cov)[3:o_clk]).reshape(-1, 3) if n_orb else np.zeros((n_sats, 3))
    return CarrierFix(
        pos_ecef_m=pos, cov=0.5 * (P + P.T), pos_float_ecef_m=x, cov_float=cov[:3, :3], status=status, ratio=ratio,
        n_ambiguities=int(a_hat.size), n_fixed=n_fixed,
        ambiguity_cycles=a_hat + _whole_cycles(n0, dd_keys, use.shape[0] == 2),
        ambiguity_sigma_cycles=np.sqrt(np.diag(Q_a)), orbit_rtn_m=d, orbit_sigma_rtn_m=orb_sig, chi2=chi2,
        chi2_p=chi2_p, dof=dof, variance_factor=variance_factor,
        n_rows=int(np.sum(both)), n_epochs=int(np.sum(np.any(both, axis=0))), n_sats=int(np.sum(np.any(both, axis=1))),
        residuals_m=res[0] if sat_clock_degree is None else res[0] - res[1], iterations=it)


def _rows(lam, phr, sr, ar, phb, sb, ab, ok_r, ok_b, both, *, joint):
    """The rows of the fit, their ambiguities and the double-difference combinations.

    Each row belongs to a key, a satellite and arc (of both receivers in a
    single difference, of one receiver in the joint fit). Datums, held at
    zero: the single difference with most rows (its rover arc in the joint
    fit), and in the joint fit each satellite's base arc with most rows (its
    phase constant takes it; the datum satellite's is the base clock's).

    Returns
    -------
    use : ndarray of bool, (G, n_sats, n_ep)
        G = 1: single differences; G = 2: the rover's and the base's own rows (common satellites only).
    y, w : ndarray, (G, n_sats, n_ep)
        ``-lambda phase`` [m] and its weight [1/m^2] (0 where unused).
    key : ndarray of int, (G, n_sats, n_ep)
        Each row's key (-1 unused).
    col : ndarray of int, (n_keys,)
        Each key's ambiguity column, -1 for a datum.
    combos : ndarray, (n_dd, n_amb)
        The double-difference ambiguities (each single difference but the datum's) in the columns.
    dd_keys : ndarray of int, (n_dd + 1, 2)
        The rover's and the base's key of each single difference (joint), or its key twice; the datum's last.
    datum_sat : int
    """
    n_sats = phr.shape[0]
    n_arcs = int(max(ar.max(), ab.max())) + 1
    sat = np.broadcast_to(np.arange(n_sats)[:, None], phr.shape)
    sd_keys, sd_counts = np.unique(np.stack([sat, ar, ab], axis=-1)[both], axis=0, return_counts=True)
    dat = int(np.argmax(sd_counts))
    datum_sat = int(sd_keys[dat, 0])
    sd_keys = np.concatenate([np.delete(sd_keys, dat, axis=0), sd_keys[dat:dat + 1]])   # the datum last
    if not joint:
        use = both[None]
        y, var = -lam * (phr - phb)[None], lam**2 * (sr**2 + sb**2)[None]
        code = (sat * n_arcs + ar) * n_arcs + ab
        sd_code = (sd_keys[:, 0] * n_arcs + sd_keys[:, 1]) * n_arcs + sd_keys[:, 2]
        key = np.where(use, np.searchsorted(np.sort(sd_code), code[None]), -1)
        order = np.argsort(sd_code)
        dd = order.argsort()                     # key (sorted code) of each single difference
        col = np.full(len(sd_keys), -1)
        col[dd[:-1]] = np.arange(len(sd_keys) - 1)
        combos = np.eye(len(sd_keys) - 1)
        dd_keys = np.stack([dd, dd], axis=1)
    else:
        common = np.any(both, axis=1)[:, None]
        use = np.stack([ok_r & common, ok_b & common])
        use &= np.sum(use, axis=1)[:, None, :] >= 2
        y, var = -lam * np.stack([phr, phb]), lam**2 * np.stack([sr, sb]) ** 2
        key = np.where(use, (np.arange(2)[:, None, None] * n_sats + sat[None]) * n_arcs + np.stack([ar, ab]), -1)
        col = np.full(2 * n_sats * n_arcs, -1)
        n_b = [np.bincount(np.where(use[1][s_], ab[s_], n_arcs), minlength=n_arcs + 1)[:n_arcs] for s_ in range(n_sats)]
        datums = {(0 * n_sats + datum_sat) * n_arcs + sd_keys[-1, 1]}
        datums |= {(n_sats + s_) * n_arcs + (sd_keys[-1, 2] if s_ == datum_sat else int(np.argmax(n_b[s_])))
                   for s_ in range(n_sats)}
        present = np.unique(key[use])
        free = np.array([k for k in present if k not in datums], dtype=int)
        col[free] = np.arange(free.size)
        dd_keys = np.stack([sd_keys[:, 0] * n_arcs + sd_keys[:, 1], (n_sats + sd_keys[:, 0]) * n_arcs + sd_keys[:, 2]],
                           axis=1)
        combos = np.zeros((len(sd_keys) - 1, free.size))
        for row, (k_r, k_b) in enumerate(dd_keys[:-1]):
            if col[k_r] >= 0:
                combos[row, col[k_r]] += 1.0
            if col[k_b] >= 0:
                combos[row, col[k_b]] -= 1.0
    w = np.where(use, 1.0 / np.where(use, var, 1.0), 0.0)
    return use, np.where(use, y, 0.0), w, key, col, combos, dd_keys, datum_sat
