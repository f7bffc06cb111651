"""Stage 3 of the identification: every candidate fitted to every track at the solution, the best accepted.

A candidate is accepted only when its chi-square is consistent with the
track's sigma and clearly below the runner-up's; a satellite claimed by two
tracks goes to the track with more blocks kept, then the better fit.

A few blocks of a long track may be false detections (a weak block's
strongest peak tens of hertz off, often at the track's start). Each
candidate's fit leaves out its blocks beyond :data:`OUTLIER_Z` sigmas, at
most :data:`MAX_OUTLIER_FRACTION` of them, before its chi-square is tested:
otherwise two such blocks make a 50-block track of a satellite ``poor_fit``.
A wrong satellite misses most blocks by far more, which no such trimming
hides; its chi-square is tested on the blocks kept, as the right one's.
A short fragment (4-9 blocks, a satellite near the snapshot search's
comb limit caught for a few seconds) may leave out one block as long as
:data:`~leosop.replay.features.MIN_BLOCKS` remain: one comb crossing's
biased block (10-13 Hz, 7-8 sigma on the replay bench) otherwise makes it
``poor_fit``, and the blocks kept test a candidate as well as a clean
fragment of that length does.
"""

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .ephemeris import SPEED_SV_MPS, doppler_model
from .features import MIN_BLOCKS

__all__ = ["ID_STATUSES", "accept", "match"]

#: Every identification status of a track, ``ok`` first: ``ok`` (identified, vouched for);
#: ``too_short`` (under 3 usable blocks); ``no_solution`` (no receiver position and offset explains
#: the tracks); ``no_candidate`` (no satellite above the mask near its Doppler); ``poor_fit`` (the
#: best candidate's chi-square fails the track's sigma: no satellite of the snapshot explains it);
#: ``ambiguous`` (the runner-up fits within the margin); ``duplicate`` (its satellite went to a longer
#: track, or one as long that fits it better); ``too_few_identified`` (fewer identities than
#: the minimum, which do not prove the solution they rest on); ``conflicting_solution`` (another
#: solution, at another position or receiver offset, identifies this track as another satellite
#: and passes the same tests).
ID_STATUSES = ("ok", "too_short", "no_solution", "no_candidate", "poor_fit", "ambiguous", "duplicate",
               "too_few_identified", "conflicting_solution")

#: Candidates per track fitted in the identification (nearest in Doppler at the track's middle).
_ID_CANDIDATES = 24
#: A block this many sigmas off a candidate's fit is left out of its chi-square (Gaussian
#: noise reaches it once in ~2 million blocks).
OUTLIER_Z = 5.0
#: At most this fraction of a track's blocks (rounded down; at least one while
#: :data:`~leosop.replay.features.MIN_BLOCKS` remain) is left out.
MAX_OUTLIER_FRACTION = 0.1


def match(search, sol):
    """Best and runner-up candidate per track at a solution.

    Each pass of the fit evaluates the models of every track's candidates at once, in one flat batch
    (small arrays track by track would cost numpy's overhead per call many times over), then
    fits track by track on the same (candidates, blocks) arrays as a loop over the tracks would.

    Returns
    -------
    list of dict per track: sat, chi2, rms_hz, margin, runner_up (sat or -1), time_offset_s (the best
    candidate's fitted inertial time offset, :mod:`~leosop.replay.ephemeris`).
    """
    fits = [_candidates(search, sol, k) for k in range(len(search.tracks))]
    # The time offset enters non-linearly: re-linearise; a third pass with the outliers out.
    for it in range(3):
        now = [f for f in fits if f is not None and it < f.n_passes]
        for f, model in zip(now, _models(search, sol, now)):
            f.step(it, *model, sol["cov"], search.o)
    return [None if f is None else f.best() for f in fits]


def _candidates(search, sol, k):
    """Track ``k``'s candidates, those nearest in Doppler at its middle (rate-scaled), ready to fit; None
    when no satellite is above the mask. The rest are kHz away and would only add to the cost."""
    o, tr = search.o, search.tracks[k]
    pos, vel_rx = sol["pos"], sol["vel"]
    up = pos / np.linalg.norm(pos)
    sin_mask = np.sin(np.radians(o["mask_deg"] - o["id_mask_slack_deg"]))
    p_mid, v_mid, p_next, v_next = (a[k] for a in search.mid_states)
    los = p_mid - pos
    el_ok = (los @ up) / np.linalg.norm(los, axis=1) >= sin_mask
    cand = np.flatnonzero(el_ok & search.eph.ok)
    pos_mid = pos + (tr.t_mid_s - search.t_c) * vel_rx
    dm = doppler_model(p_mid[cand], v_mid[cand] - vel_rx, pos_mid, search.k)[0]
    slope = np.abs(doppler_model(p_next[cand], v_next[cand] - vel_rx, pos_mid + vel_rx, search.k)[0] - dm)
    off = np.abs(tr.f_ref_hz[1] - sol["clock"] - sol["drift"] * (tr.t_mid_s - search.t_c) - dm)
    cand = cand[np.argsort(off / (10.0 + slope * o["along_track_sigma_m"] / SPEED_SV_MPS))[:_ID_CANDIDATES]]
    return _CandidateFit(search, sol, tr, cand) if cand.size else None


def _models(search, sol, fits):
    """Doppler (n_cand, n_blocks), its gradient in the receiver position (n_cand, n_blocks, 3) and its rate in
    the time offset (n_cand, n_blocks) of each fit's candidates at their current time offsets, in one batch."""
    if not fits:
        return []
    vel_rx = sol["vel"]
    sat = np.concatenate([np.repeat(f.cand, f.t.size) for f in fits])
    t = np.concatenate([np.tile(f.t, f.cand.size) for f in fits])
    pos_t = np.concatenate([np.tile(f.pos_t, (f.cand.size, 1)) for f in fits])
    tau = np.concatenate([np.repeat(f.tau[:, 0], f.t.size) for f in fits])
    p, v = search.eph.state_received(sat, t, pos_t, tau)
    dop, grad = doppler_model(p, v - vel_rx, pos_t, search.k)
    rate = search.eph.doppler_shift_rate(sat, t, tau, pos_t, search.k)
    edges = np.cumsum([f.cand.size * f.t.size for f in fits])[:-1]
    return [(d.reshape(f.shape), g.reshape(*f.shape, 3), r.reshape(f.shape))
            for f, d, g, r in zip(fits, np.split(dop, edges), np.split(grad, edges), np.split(rate, edges))]


class _CandidateFit:
    """One track's candidates: each one's frequency offset and time offset fitted by weighted least squares
    with priors, re-linearised pass by pass (:meth:`step`), its outlier blocks left out in the last pass."""

    def __init__(self, search, sol, tr, cand):
        o = search.o
        idx = tr.sample
        self.cand, self.t = cand, tr.t_s[idx]
        self.shape = (cand.size, self.t.size)
        self.sig2 = tr.sigma_hz[idx] ** 2 + o["model_sigma_hz"] ** 2
        self.base = tr.doppler_hz[idx] - sol["clock"] - sol["drift"] * (self.t - search.t_c)
        self.pos_t = sol["pos"] + (self.t - search.t_c)[:, None] * sol["vel"]
        self.sig_c, self.sig_tau = o["sat_offset_sigma_hz"], o["along_track_sigma_m"] / SPEED_SV_MPS
        self.tau = np.zeros((cand.size, 1))
        self.keep = np.ones(self.shape)  # 0 for a candidate's outlier blocks
        self.c_hz = np.zeros(cand.size)
        self.n_out = max(int(MAX_OUTLIER_FRACTION * self.t.size), min(1, self.t.size - MIN_BLOCKS))
        self.n_passes = 3 if self.n_out else 2

    def step(self, it, dop, grad, rate, cov, o):
        """Pass ``it`` of the fit, from the models at the current time offsets (:func:`_models`)."""
        # The fix's own uncertainty inflates the sigma, but only up to a cap: a fix too poor
        # to test a candidate must not make every candidate pass.
        var = self.sig2[None, :] + np.minimum(np.einsum("ntx,xy,nty->nt", grad, cov, grad),
                                              o["pos_sigma_cap_hz"] ** 2)
        r = self.base[None, :] - dop
        if it > 0 and self.n_out:
            # Deleted residuals (tau already moved by dtau): a block's own weight pulls a short fit
            # towards it (leverage h), hiding a 10 Hz block of 4 at 3-4 sigma; 1 - h restores it.
            a11, a12, a22, det = self.normal
            h = (a22[:, None] - 2 * a12[:, None] * rate + a11[:, None] * rate**2) / (det[:, None] * var)
            z = np.abs(r - self.c_hz[:, None]) / np.sqrt(var * np.maximum(1.0 - h, 1e-3))
            worst = np.argsort(-z, axis=1)[:, :self.n_out]
            self.keep = np.ones_like(z)
            np.put_along_axis(self.keep, worst, np.take_along_axis(z, worst, 1) <= OUTLIER_Z, 1)
        w = self.keep / var
        sig_c, sig_tau = self.sig_c, self.sig_tau
        # Weighted least squares for (c, dtau) with priors c ~ N(0, sig_c), tau ~ N(0, sig_tau).
        a11 = w.sum(1) + 1 / sig_c**2
        a12 = (w * rate).sum(1)
        a22 = (w * rate**2).sum(1) + 1 / sig_tau**2
        b1 = (w * r).sum(1)
        b2 = (w * rate * r).sum(1) - self.tau[:, 0] / sig_tau**2
        det = a11 * a22 - a12**2
        self.normal = (a11, a12, a22, det)
        self.c_hz = (a22 * b1 - a12 * b2) / det
        dtau = (a11 * b2 - a12 * b1) / det
        self.tau = self.tau + dtau[:, None]
        self.w, self.resid = w, r - self.c_hz[:, None] - dtau[:, None] * rate

    def best(self):
        """The best candidate and the runner-up after the last pass (:func:`match`'s dict)."""
        chi2 = (self.w * self.resid**2).sum(1) + (self.c_hz / self.sig_c) ** 2 + (self.tau[:, 0] / self.sig_tau) ** 2
        chi2 = np.where(np.isfinite(chi2), chi2, np.inf)
        order = np.argsort(chi2)
        best = order[0]
        second = chi2[order[1]] if len(order) > 1 else np.inf
        used = self.keep[best] > 0
        return {"sat": int(self.cand[best]), "chi2": float(chi2[best]), "n": int(used.sum()),
                "rms_hz": float(np.sqrt(np.mean(self.resid[best, used] ** 2))), "margin": float(second - chi2[best]),
                "runner_up": int(self.cand[order[1]]) if len(order) > 1 else -1,
                "time_offset_s": float(self.tau[best, 0])}


def accept(search, ids):
    """Satellite index and status per track from :func:`match`'s output.

    Returns
    -------
    sat : ndarray of int, (n_tracks,)
        Accepted satellite index, -1 when not accepted.
    status : ndarray of str, (n_tracks,)
        ``ok`` for an accepted track, else why not (:data:`ID_STATUSES`).
    """
    o = search.o
    sat = np.full(len(ids), -1)
    status = np.full(len(ids), "no_candidate", dtype=object)
    for k, d in enumerate(ids):
        if d is None:
            continue
        if d["chi2"] > chi2_dist.ppf(1 - o["false_alarm"], d["n"]):
            status[k] = "poor_fit"
        elif d["margin"] < o["min_margin"]:
            status[k] = "ambiguous"
        else:
            sat[k], status[k] = d["sat"], "ok"
    # One comb per satellite: the track with the most blocks kept has it (each passed the tests; a
    # fragment's few blocks, one left out, can fit better per block and carry less), then the better fit.
    for s in np.unique(sat[sat >= 0]):
        ks = np.flatnonzero(sat == s)
        if len(ks) > 1:
            keep = ks[min(range(len(ks)), key=lambda j: (-ids[ks[j]]["n"], ids[ks[j]]["chi2"] / ids[ks[j]]["n"]))]
            lose = ks[ks != keep]
            sat[lose], status[lose] = -1, "duplicate"
    if (sat >= 0).sum() < o["min_identified"]:  # one or two matches do not prove the fix they rest on
        status[sat >= 0] = "too_few_identified"
        sat[:] = -1
    return sat, status
