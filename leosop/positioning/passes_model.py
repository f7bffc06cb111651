"""The model of the multi-pass static fix: its rows in pass order, and the position with the linear terms eliminated.

:func:`pass_rows` orders the rows by pass, sets up the clock bases (the
shared receiver polynomials, each pass's polynomial or satellite offset, its
time offset's Doppler-rate column) and appends the priors and the height as
pseudo-rows. :class:`PassesModel` is the variable-projection model that
:func:`~leosop.positioning.robust_ls.solve_robust` iterates on the position
alone: each call solves the weighted linear fit of all linear terms to the
residuals (block-diagonal per pass, the shared clocks by their Schur
complement) and returns the prediction and the projected Jacobian
``(I - A K) D``; :meth:`PassesModel.normal_matrix` is the full normal matrix
of the fix at its solution. Used by
:func:`~leosop.positioning.static_passes.solve_static_passes`.

Blocks (optional): rows of one block (one instant of a snapshot receiver)
share a frequency error ``c_b ~ N(0, q_b)`` (the receiver LO's phase noise
over the block). Each block gets a state with that prior, solved with the
shared clocks (the global tier of the Schur complement; its own normal
matrix is diagonal). Eliminating it leaves the block's rows the covariance
``diag(sigma^2) + q_b 1 1^T``, so this is the generalised least squares of
the correlated rows (its chi-square the rows' Mahalanobis distance).
"""

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..frames import C_e_n, ecef_to_geodetic
from ..geometry.doppler import doppler_jacobian, doppler_rate, sv_motion
from .robust_ls import batch_rows

__all__ = ["PassRows", "PassesModel", "pass_rows"]


@dataclass(frozen=True)
class PassRows:
    """The rows of a multi-pass fix in pass order, with the layout of its linear terms.

    ``n`` Doppler rows come first, then the priors' pseudo-rows (one per
    pass and prior'd per-pass term, measured 0) and the height row if any.

    Attributes
    ----------
    y, sigma, used : ndarray, (n_rows,)
        Measurements, sigmas and usable rows, pseudo-rows included.
    carrier_hz, t_s, pass_index, clock_index : ndarray, (n,)
        Of the Doppler rows; ``pass_index`` into ``labels``, ``clock_index``
        into ``clock_labels``.
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n, 3)
        Masked rows filled with a harmless satellite.
    fixed : ndarray of bool, (n_rows,)
        The pseudo-rows (never excluded as outliers).
    groups : ndarray of int, (n_rows,)
        Each row's pass for the outlier test, -1 for pseudo-rows.
    order : ndarray of int, (n,)
        The input row of each row.
    labels : ndarray, (n_pass,)
    clock_labels : ndarray, (n_clk,)
    pass_clock : ndarray of int, (n_pass,)
    seg : ndarray of int, (n_pass,)
        First row of each pass.
    t_ref_s, half_span_s : ndarray, (n_pass,)
        Each pass's mid-time and half span (at least 1 s).
    rx_t_ref_s, half_rx_s : float
        Mid-time and half span of all passes.
    B_glob : ndarray, (n, n_glob)
        The receiver clocks' polynomial basis in scaled time.
    basis : ndarray, (n, n_poly)
        Each pass's polynomial basis (or the satellite offset's column).
    prior : ndarray, (n_loc,)
        Prior weights of the per-pass terms; ``prior_cols`` those non-zero.
    prior_cols : ndarray of int
    block_index : ndarray of int, (n,)
        Each Doppler row's block (0 for masked rows and without blocks).
    block_prior : ndarray, (n_block,)
        Prior weight ``1 / q_b`` of each block's common frequency error [1/Hz^2].
    n, n_pass, n_clk, n_glob, n_loc, deg, time_bias : int
        ``n_glob`` the receiver clocks' polynomial terms (the blocks' states not counted).
    common, has_alt : bool
    time_offset_model : {"inertial", "earth_fixed"}
        What a pass's time offset shifts (:data:`~leosop.positioning.static_passes.TIME_OFFSET_MODELS`).
    """

    y: np.ndarray
    sigma: np.ndarray
    used: np.ndarray
    carrier_hz: np.ndarray
    t_s: np.ndarray
    pass_index: np.ndarray
    clock_index: np.ndarray
    pos_sv_ecef_m: np.ndarray
    vel_sv_ecef_mps: np.ndarray
    fixed: np.ndarray
    groups: np.ndarray
    order: np.ndarray
    labels: np.ndarray
    clock_labels: np.ndarray
    pass_clock: np.ndarray
    seg: np.ndarray
    t_ref_s: np.ndarray
    half_span_s: np.ndarray
    rx_t_ref_s: float
    half_rx_s: float
    B_glob: np.ndarray
    basis: np.ndarray
    prior: np.ndarray
    prior_cols: np.ndarray
    n: int
    n_pass: int
    n_clk: int
    n_glob: int
    n_loc: int
    deg: int
    time_bias: int
    common: bool
    has_alt: bool
    time_offset_model: str = "inertial"
    block_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    block_prior: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_block(self):
        """Blocks with a common frequency error state, int (0 without)."""
        return self.block_prior.size

    @property
    def n_states(self):
        """Position, receiver clock terms, blocks' common errors and per-pass terms, int."""
        return 3 + self.n_glob + self.n_block + self.n_pass * self.n_loc

    @property
    def B_all(self):
        """The global tier's basis, (n, n_glob + n_block): the clocks' polynomials, then each block's indicator."""
        if not self.n_block:
            return self.B_glob
        return np.hstack([self.B_glob, self.block_index[:, None] == np.arange(self.n_block)])

    @property
    def scale(self):
        """Factors from the scaled-time terms to [Hz/s^k]: global (n_glob,), per pass (n_pass, n_loc)."""
        scale_glob = np.tile(1.0 / self.half_rx_s ** np.arange(self.n_glob // self.n_clk), self.n_clk)
        scale_loc = np.ones((self.n_pass, self.n_loc)) if self.common else \
            np.concatenate([1.0 / self.half_span_s[:, None] ** np.arange(self.deg + 1),
                            np.ones((self.n_pass, self.time_bias))], -1)
        return scale_glob, scale_loc


def _in_pass_order(rows, pass_id, clock_group, n_min, common):
    """Drop passes with fewer than ``n_min`` usable rows, number the receiver clocks, sort the rows by pass."""
    y, sigma, f0, t, r_s, v_s, m = rows
    n = y.size
    labels, gi = np.unique(np.asarray(pass_id).ravel(), return_inverse=True)
    counts = np.bincount(gi[m], minlength=len(labels))
    keep = counts >= n_min
    if not keep.any():
        hint = "" if common else ', or clock "common" (fewer terms per pass)'
        raise InputError(f"no pass has the {n_min} usable rows its own terms need (the most: {counts.max(initial=0)}): "
                         f"longer passes{hint}", param=() if common else "clock")
    m &= keep[gi]
    labels, gi = labels[keep], np.cumsum(keep)[gi] - 1
    gi[~m] = np.maximum(gi[~m], 0)
    # Receiver clocks (clock "common"): one polynomial per distinct group among the rows kept.
    grp = np.zeros(n, int) if clock_group is None or not common else np.broadcast_to(np.asarray(clock_group), (n,))
    clock_labels, g_idx = np.unique(grp[m], return_inverse=True)
    clk = np.zeros(n, int)
    clk[m] = g_idx.ravel()
    # Rows in pass order internally (contiguous segments for the per-pass sums).
    order = np.argsort(gi, kind="stable")
    y, sigma, f0, t, m, gi, r_s, v_s, clk = (a[order] for a in (y, sigma, f0, t, m, gi, r_s, v_s, clk))
    pass_clk = np.zeros(len(labels), int)
    pass_clk[gi[m]] = clk[m]
    y, sigma, f0, t = (np.where(m, a, fill) for a, fill in ((y, 0.0), (sigma, 1.0), (f0, 1.0), (t, 0.0)))
    r_s = np.where(m[:, None], r_s, [2e7, 0.0, 0.0])
    v_s = np.where(m[:, None], v_s, 0.0)
    return (y, sigma, f0, t, r_s, v_s, m), gi, clk, labels, clock_labels, pass_clk, order


def pass_rows(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, pass_id, *, mask, common, deg,
              time_bias, sat_offset_sigma_hz, time_bias_sigma_s, clock_group, alt_m, alt_sigma_m,
              time_offset_model="inertial", block_id=None, block_sigma_hz=None):
    """The rows of a multi-pass fix in pass order and the layout of its linear terms.

    Arguments as :func:`~leosop.positioning.static_passes.solve_static_passes`'s
    (``common`` its clock ``"common"``, ``deg`` the clock degree). Blocks are
    numbered over the usable rows; a block's prior sigma is the largest of
    its usable rows'.

    Returns
    -------
    PassRows
    """
    tb = int(bool(time_bias))
    n_glob = deg + 1 if common else 0
    n_loc = (1 if common else deg + 1) + tb
    # Prior weights of the per-pass terms: [satellite offset | polynomial..., time offset].
    prior = np.zeros(n_loc)
    if common:
        prior[0] = 1.0 / float(sat_offset_sigma_hz) ** 2
    if tb and time_bias_sigma_s is not None:
        prior[-1] = 1.0 / float(time_bias_sigma_s) ** 2
    prior_cols = np.flatnonzero(prior > 0)
    rows = batch_rows(doppler_hz, sigma_hz, pos_sv_ecef_m, vel_sv_ecef_mps, carrier_hz, t_s, mask)
    n = rows[0].size
    (y, sigma, f0, t, r_s, v_s, m), gi, clk, labels, clock_labels, pass_clk, order = _in_pass_order(
        rows, pass_id, clock_group, n_loc + 1 - len(prior_cols), common)
    block_index, block_prior = np.zeros(n, int), np.zeros(0)
    if block_id is not None:
        ids = np.broadcast_to(np.asarray(block_id), (n,))[order]
        sig_b = np.broadcast_to(np.asarray(block_sigma_hz, dtype=float), (n,))[order]
        _, block_index[m] = np.unique(ids[m], return_inverse=True)
        sig_max = np.zeros(int(block_index[m].max()) + 1 if m.any() else 0)
        np.maximum.at(sig_max, block_index[m], sig_b[m])
        block_prior = 1.0 / sig_max**2
    n_clk = max(len(clock_labels), 1)
    n_glob *= n_clk
    n_pass = len(labels)
    seg = np.searchsorted(gi, np.arange(n_pass))
    t_lo = np.array([t[gi == p][m[gi == p]].min() for p in range(n_pass)]) if n_pass else np.zeros(0)
    t_hi = np.array([t[gi == p][m[gi == p]].max() for p in range(n_pass)]) if n_pass else np.zeros(0)
    t_ref = 0.5 * (t_lo + t_hi)
    half_span_s = np.maximum(0.5 * (t_hi - t_lo), 1.0)
    t_rx = 0.5 * (t_lo.min() + t_hi.max()) if n_pass else 0.0
    half_rx_s = max(0.5 * (t_hi.max() - t_lo.min()), 1.0) if n_pass else 1.0
    # Polynomial bases in scaled time (|u| <= 1) for conditioning: the shared clock's and the per-pass ones.
    B_glob = ((t - t_rx) / half_rx_s)[:, None] ** np.arange(n_glob // n_clk)
    if n_clk > 1:
        B_glob = ((clk[:, None] == np.arange(n_clk))[:, :, None] * B_glob[:, None, :]).reshape(n, n_glob)
    basis = np.ones((n, 1)) if common else ((t - t_ref[gi]) / half_span_s[gi])[:, None] ** np.arange(deg + 1)
    # Priors: per prior'd per-pass term a pseudo-row per pass (measured 0), after the Doppler rows.
    n_extra = n_pass * len(prior_cols)
    sig_prior = np.repeat(1.0 / np.sqrt(prior[prior_cols]), n_pass)
    y, sigma, m = np.append(y, np.zeros(n_extra)), np.append(sigma, sig_prior), np.append(m, np.ones(n_extra, bool))
    # The blocks' priors: a pseudo-row per block (measured 0), after the per-pass ones.
    n_extra += block_prior.size
    y, sigma = np.append(y, np.zeros(block_prior.size)), np.append(sigma, 1.0 / np.sqrt(block_prior))
    m = np.append(m, np.ones(block_prior.size, bool))
    has_alt = alt_m is not None
    if has_alt:
        y, sigma, m = np.append(y, alt_m), np.append(sigma, alt_sigma_m), np.append(m, True)
    fixed = np.zeros(y.size, bool)
    fixed[n:] = True
    groups = np.concatenate([gi, [-1] * (n_extra + has_alt)])
    return PassRows(
        y=y, sigma=sigma, used=m, carrier_hz=f0, t_s=t, pass_index=gi, clock_index=clk, pos_sv_ecef_m=r_s,
        vel_sv_ecef_mps=v_s, fixed=fixed, groups=groups, order=order, labels=labels, clock_labels=clock_labels,
        pass_clock=pass_clk, seg=seg, t_ref_s=t_ref, half_span_s=half_span_s, rx_t_ref_s=t_rx, half_rx_s=half_rx_s,
        B_glob=B_glob, basis=basis, prior=prior, prior_cols=prior_cols, n=n, n_pass=n_pass, n_clk=n_clk,
        n_glob=n_glob, n_loc=n_loc, deg=deg, time_bias=tb, common=common, has_alt=has_alt,
        time_offset_model=time_offset_model, block_index=block_index, block_prior=block_prior)


def _scaled_pinv(G):
    """Pseudo-inverse of symmetric matrices (..., n, n) through their Jacobi scaling.

    A pass's time-offset column (Hz per s, the Doppler rate) is ~1e4 times
    its polynomial's; unscaled, a short high-rate pass's normal matrix
    reaches a condition number of 1e13-1e14 and its pseudo-inverse errs by
    ~0.1 (``G G^+ - I``), scaled it is ~5e4.
    """
    d = np.sqrt(np.abs(np.diagonal(G, axis1=-2, axis2=-1)))
    d = np.where(d > 0, d, 1.0)
    dd = d[..., :, None] * d[..., None, :]
    return np.linalg.pinv(G / dd, hermitian=True) / dd


class PassesModel:
    """Variable-projection model of a multi-pass fix, the callable :func:`~.robust_ls.solve_robust` iterates.

    Parameters
    ----------
    rows : PassRows
    """

    def __init__(self, rows):
        self.rows = rows
        # The receivers' common clock offset, taken out of the rows before the linear fit and put back into
        # its constant terms (set at the first call, :meth:`_offset_hz`).
        self._y0 = None
        # The satellites' own terms of the Doppler rate: the same at every iterate.
        self.motion = (sv_motion(rows.pos_sv_ecef_m, rows.vel_sv_ecef_mps,
                                 inertial=rows.time_offset_model == "inertial") if rows.time_bias else None)

    def normal(self, x, w):
        """Geometry (h, D, rate grad), the per-pass basis A, the linear terms' solver and their normal matrix's
        blocks with the inverses of the per-pass blocks and of the global tier's Schur complement.

        The global tier is the receivers' polynomials, then the blocks' common errors (module docstring).
        """
        r = self.rows
        n, seg = r.n, r.seg
        H = doppler_jacobian(r.pos_sv_ecef_m, r.vel_sv_ecef_mps, x, np.zeros((len(x), 3)), r.carrier_hz)
        h, D = np.einsum("pmi,mi->pm", H[..., 3:6], -r.vel_sv_ecef_mps), H[..., :3]
        A = np.broadcast_to(r.basis, (len(x),) + r.basis.shape)
        grad = None
        if r.time_bias:
            rate, grad = doppler_rate(r.pos_sv_ecef_m, r.vel_sv_ecef_mps, x, r.carrier_hz,
                                      inertial=r.time_offset_model == "inertial", motion=self.motion)
            A = np.concatenate([A, rate[..., None]], -1)
        B_glob, gi = r.B_glob, r.pass_index
        wd = w[:, :n]
        wA = wd[..., None] * A
        G_ss = np.add.reduceat(wA[..., :, None] * A[..., None, :], seg, axis=1) + np.diag(r.prior)
        # Inverted through their Jacobi scaling (:func:`_scaled_pinv`): unscaled, a short pass's cubic and time
        # offset (condition ~1e14) cost the projection ~6e-3 of a row's leverage; scaled, 8e-6.
        Gi_ss = _scaled_pinv(G_ss)
        G_gg = np.einsum("mi,pm,mj->pij", B_glob, wd, B_glob)
        G_sg = np.add.reduceat(wA[..., :, None] * B_glob[None, :, None, :], seg, axis=1)  # (k, P, l, g)
        if r.n_block:
            G_gg, G_sg = self._with_blocks(wd, wA, G_gg, G_sg)
        S = G_gg - np.einsum("pqli,pqlj->pij", G_sg, Gi_ss @ G_sg)
        Si = _scaled_pinv(S) if r.n_glob + r.n_block else S

        def lin(rhs):
            """Linear terms (global (k, g, q), per pass (k, P, l, q)) fitting rows ``rhs`` (k, n, q)."""
            b_s = np.add.reduceat(wA[..., :, None] * rhs[..., None, :], seg, axis=1)
            z_s = Gi_ss @ b_s
            b_g = np.einsum("mi,pm,pmq->piq", B_glob, wd, rhs)
            if r.n_block:
                b_g = np.concatenate([b_g, self._block_sums(wd[..., None] * rhs)], 1)
            c_g = Si @ (b_g - np.einsum("pqli,pqlk->pik", G_sg, z_s))
            return c_g, z_s - Gi_ss @ (G_sg @ c_g[:, None])

        def fitted(c_g, c_s):
            """Rows (k, n, q) of the linear terms."""
            out = np.einsum("mi,piq->pmq", B_glob, c_g[:, :r.n_glob]) + np.einsum("pmi,pmiq->pmq", A, c_s[:, gi])
            return out + c_g[:, r.n_glob + r.block_index] if r.n_block else out

        return h, D, grad, A, lin, fitted, (G_gg, G_sg, G_ss, Gi_ss, Si)

    def _block_sums(self, v):
        """Sums (k, n_block, c) of the rows ``v`` (k, n, c) over each block."""
        out = np.zeros((self.rows.n_block,) + v.shape[:1] + v.shape[2:])
        np.add.at(out, self.rows.block_index, np.moveaxis(v, 1, 0))
        return np.moveaxis(out, 0, 1)

    def _with_blocks(self, wd, wA, G_gg, G_sg):
        """The global tier's normal blocks with the blocks' states appended: (k, g, g) and (k, P, l, g)."""
        r = self.rows
        k, n_b = len(wd), r.n_block
        G_gb = self._block_sums(wd[..., None] * r.B_glob).transpose(0, 2, 1)  # (k, n_glob, n_block)
        G_bb = self._block_sums(wd[..., None])[..., 0] + r.block_prior  # diagonal, (k, n_block)
        G_sb = np.zeros((r.n_pass * n_b, k, wA.shape[-1]))
        np.add.at(G_sb, r.pass_index * n_b + r.block_index, np.moveaxis(wA, 1, 0))
        G_sb = G_sb.reshape(r.n_pass, n_b, k, -1).transpose(2, 0, 3, 1)  # (k, P, l, n_block)
        G_gg = np.concatenate([np.concatenate([G_gg, G_gb], 2),
                               np.concatenate([G_gb.transpose(0, 2, 1), G_bb[..., None] * np.eye(n_b)], 2)], 1)
        return G_gg, np.concatenate([G_sg, G_sb], -1)

    def pieces(self, x, w):
        """Prediction, projected position Jacobian and the linear terms (global, per pass) at ``x``."""
        r = self.rows
        h, D, grad, A, lin, fitted, blocks = self.normal(x, w)
        rhs = r.y[:r.n] - h
        y0 = self._offset_hz(rhs)
        c_g, c_s = lin((rhs - y0)[..., None])
        if y0:
            c_g = c_g.copy()
            c_g[:, :r.n_glob:r.n_glob // r.n_clk] += y0  # each receiver clock's constant term
        if r.time_bias:
            D = D + c_s[:, r.pass_index, -1, 0, None] * grad
        K_g, K_s = lin(D)
        pred = h + fitted(c_g, c_s)[..., 0]
        J = D - fitted(K_g, K_s)
        return pred, J, D, A, c_g[..., 0], c_s[..., 0], K_g, K_s, blocks

    def _offset_hz(self, rhs):
        """The rows' common offset from the geometry, ``median(y - h)`` of the first call's first problem
        (0 without shared receiver clocks).

        An LNB's offset (hundreds of kHz) left in the rows made the eliminated clock terms carry it, and
        their solve's round-off (~1e-10 of them) jittered the predictions by ~0.005 sigma: with a drift as
        well, the fix's chi-square varied by ~0.06 from call to call and its step test was never met (4,000
        iterations, ``not_converged``, where the rows less the offset converge in 11)."""
        if self._y0 is None:
            r = self.rows
            used = r.used[:r.n]
            self._y0 = float(np.median(rhs[0][used])) if r.common and r.n_glob and used.any() else 0.0
        return self._y0

    def __call__(self, x, idx, w):
        """Prediction (k, n_rows) and Jacobian (k, n_rows, 3) of the rows, pseudo-rows included, at ``x`` (k, 3)."""
        r = self.rows
        pred, J, _, _, c_g, c_s, K_g, K_s, _ = self.pieces(x, w)
        pred = np.concatenate([pred] + [c_s[:, :, j] for j in r.prior_cols] + [c_g[:, r.n_glob:]], -1)
        J = np.concatenate([J] + [-K_s[:, :, j] for j in r.prior_cols] + [-K_g[:, r.n_glob:]], axis=1)
        if r.has_alt:
            lat, lon, alt = ecef_to_geodetic(x)
            pred = np.concatenate([pred, alt[:, None]], -1)
            J = np.concatenate([J, C_e_n(lat, lon)[..., 2][:, None, :]], axis=1)
        return pred, J

    def leverage(self, x, idx, w):
        """Each row's leverage through the linear terms, ``w_i x_i^T G^-1 x_i`` (k, n_rows), at ``x`` (k, 3).

        ``x_i`` is the row's column of the linear terms (the shared clocks
        and blocks, its pass's terms), ``G`` their normal matrix with its
        priors, inverted through the same Schur complement as the fit.
        Added to the leverage of the projected Jacobian that
        :meth:`__call__` returns it is the row's leverage in the whole fix
        (Frisch-Waugh-Lovell): what the w-test of
        :func:`~leosop.positioning.robust_ls.solve_robust` needs, as a row
        that its pass's offsets can absorb leaves a small residual however
        wrong it is. Pseudo-rows get 0 (they are never tested).
        """
        r = self.rows
        _, _, _, A, _, _, (_, G_sg, _, Gi_ss, Si) = self.normal(x, w)
        gi = r.pass_index
        GA = np.einsum("pmij,pmj->pmi", Gi_ss[:, gi], A)
        v = r.B_all - np.einsum("pmlg,pml->pmg", G_sg[:, gi], GA)
        h = w[:, :r.n] * (np.einsum("pmi,pmi->pm", A, GA) + np.einsum("pmg,pgh,pmh->pm", v, Si, v))
        return np.concatenate([h, np.zeros((len(x), w.shape[-1] - r.n))], -1)

    def normal_matrix(self, x, w):
        """Full normal matrix of ``[pos, global terms, blocks, per-pass terms (pass-major)]`` at the solution (1, 3).

        Returns
        -------
        N : ndarray, (n_states, n_states)
            In scaled time (:attr:`PassRows.scale`).
        D, A : ndarray, (n, 3), (n, n_loc)
            The position derivative at fixed linear terms and the per-pass basis.
        c_g, c_s : ndarray, (1, n_glob + n_block), (1, n_pass, n_loc)
            The linear terms at ``x``.
        """
        r = self.rows
        n, n_pass, n_loc = r.n, r.n_pass, r.n_loc
        n_g = r.n_glob + r.n_block
        _, _, D, A, c_g, c_s, _, _, (G_gg, G_sg, G_ss, _, _) = self.pieces(x, w)
        wd, D, A = w[0, :n], D[0], A[0]
        N = np.zeros((r.n_states, r.n_states))
        N[:3, :3] = np.einsum("mi,m,mj->ij", D, wd, D)
        if r.has_alt:
            lat, lon, _ = ecef_to_geodetic(x[0])
            up = C_e_n(lat, lon)[:, 2]
            N[:3, :3] += np.outer(up, up) * w[0, -1]
        g = slice(3, 3 + n_g)
        N[g, :3] = np.einsum("mi,m,mj->ij", r.B_all, wd, D)
        N[g, g] = G_gg[0]
        N[3 + n_g:, :3] = np.add.reduceat((wd[:, None] * A)[:, :, None] * D[:, None, :], r.seg,
                                          axis=0).reshape(-1, 3)
        N[3 + n_g:, g] = G_sg[0].reshape(n_pass * n_loc, n_g)
        for p in range(n_pass):
            sl = slice(3 + n_g + p * n_loc, 3 + n_g + (p + 1) * n_loc)
            N[sl, sl] = G_ss[0, p]
        return np.tril(N) + np.tril(N, -1).T, D, A, c_g, c_s
