"""Unnamed fragments followed along their candidates' Doppler curves once the receiver is known.

A snapshot capture's full search keeps its strongest
:data:`~leosop.replay.pipeline.MAX_NEW_COMBS` combs, so a satellite near that
cut is caught in a few captures only; a fragment of 2-4 blocks, one of them
biased by another comb's tone passing close, is too little to name
(``too_short``, ``poor_fit``). Once the identification has a solution (the
receiver's position, its LO offset and drift), every satellite that could be
such a fragment's (above the mask, named by no track, its Doppler curve
through the fragment's blocks within the bounds of its own offset and
along-track error) predicts where its comb is in the other captures.
Capture by capture outward from the fragment, the comb is fitted there in
tracking mode, the other tracks' combs of that capture fitted alongside so
that none biases it; each detection updates the candidate's offset and time
offset, which carry the prediction to the next capture (the Doppler's rate
changes along a pass, so a time offset that only the fragment's few seconds
fix would miss by tens of hertz a minute away); a candidate whose fit
leaves those bounds while it is followed (its curve dragged onto another
satellite's comb) is dropped with what it found. The candidate whose curve
finds the most detections replaces the fragment by a track of the
fragment's blocks and those detections (two fragments followed along one
satellite become one track). The identification then tests that track
with every other one, under the same tests: nothing is named here, and
the replay keeps the new identification only when it names at least as
many tracks.

Static receivers only: a moving one's position along the recording is not
known well enough to predict a comb to the tracking gate.
"""

from dataclasses import dataclass, field

import numpy as np

from ..constants import C_MPS
from ..signal.multicomb import find_combs
from .ephemeris import RATE_STEP_S, SPEED_SV_MPS, Ephemeris, doppler_hz, doppler_model
from .refit import rows_by_block
from .stream import prepared_blocks, track_times
from .tracks import Track

__all__ = ["EXTEND_STATUSES", "extend_fragments"]

#: Identification statuses of the tracks that are followed: too short, too poorly fitted or too
#: ambiguous to name.
EXTEND_STATUSES = ("too_short", "poor_fit", "ambiguous")
#: Candidate satellites followed per fragment (best fits first).
CANDIDATES = 3
#: Consecutive captures without a detection (or skipped: its comb out of the band, or crossing another
#: track's) that end a candidate's extension in one direction.
MAX_MISSES = 8
#: Bounds and priors of a candidate's own offset [Hz] and its element set's along-track error [m]
#: (as the identification's ``sat_offset_max_hz``, ``sat_offset_sigma_hz``, ``along_track_max_m``,
#: ``along_track_sigma_m``), and the model sigma added to every block's [Hz].
SAT_OFFSET_MAX_HZ, SAT_OFFSET_SIGMA_HZ = 30.0, 8.0
ALONG_TRACK_MAX_M, ALONG_TRACK_SIGMA_M = 1500.0, 600.0
MODEL_SIGMA_HZ = 1.0


@dataclass
class _Candidate:
    """One satellite followed from one fragment: its curve's fit and the detections found."""

    track: int
    sat: int
    d0_hz: np.ndarray          # (n_blocks,) Doppler at zero time offset, at every block
    shift_rate_hz_per_s: np.ndarray     # (n_blocks,) its derivative in the time offset [Hz/s]
    rate_hz_per_s: np.ndarray  # (n_blocks,) its derivative in time [Hz/s]
    visible: np.ndarray        # (n_blocks,) bool, above the mask
    base: tuple                # the fragment's (blocks, doppler_hz, sigma_hz) the fit uses
    span: tuple                # the fragment's first and last block
    c_max_hz: float            # bound of its offset: its own plus 3 sigma of the position's Doppler error
    rows: list = field(default_factory=list)  # (block, doppler, rate, cn0, sigma) found
    c_hz: float = 0.0
    tau_s: float = 0.0
    lost: bool = False         # its fit left the bounds: it was following another comb

    def predict(self, j, lo_hz):
        """Central-tone Doppler [Hz] predicted at block ``j`` (with the LO offset ``lo_hz`` (n_blocks,))."""
        return lo_hz[j] + self.d0_hz[j] + self.c_hz + self.tau_s * self.shift_rate_hz_per_s[j]


def extend_fragments(rec, raw, named, blocks, factor, comb, lo, pos_ecef_m, pos_cov_m2, constellation, *, mask_deg,
                     band_hz, gate_hz, threads=1, kernel=None):
    """The unnamed fragments of ``raw`` followed along their candidates' curves (module docstring).

    Parameters
    ----------
    rec : Recording
    raw : list of Track
        The tracks as detected (before the rate correction), in the order of ``named``.
    named : list of Track
        The same tracks after identification (``sat_id``, ``id_status``).
    blocks : list of Block
    factor : int
        Narrowing factor (:func:`~leosop.replay.pipeline.search_band`).
    comb : PilotComb
    lo : LoEstimate
        The receiver's offset and drift (the tone model fits through it, as the refit's).
    pos_ecef_m : array_like, (3,)
        The identification's receiver position.
    pos_cov_m2 : array_like, (3, 3)
        Its covariance: its error moves each satellite's Doppler by up to tens of hertz (~0.3 Hz per
        metre across the line of sight), which a candidate's offset takes up.
    constellation : Constellation
    mask_deg : float
        Elevation mask of the candidates.
    band_hz : float
        Largest central-tone Doppler the narrowed band holds, +- [Hz].
    gate_hz : float
        Half-width of the tracking window round each prediction [Hz].
    threads : int
        Threads reading and cleaning blocks (:func:`~leosop.replay.stream.prepared_blocks`).
    kernel : {None, "numba", "numpy"}
        The comb fits' and the cleaning's (:func:`~leosop.signal.multicomb.find_combs`): the replay's, for the
        whole recording.

    Returns
    -------
    tracks : list of Track
        ``raw`` with each followed fragment replaced by its longest extension (raw Dopplers); fragments
        extended along one satellite are one track (the first's; the others are left out).
    n_extended : int
        Fragments extended.
    """
    frags = [i for i, tr in enumerate(named) if tr.id_status in EXTEND_STATUSES and len(tr) >= 2]
    pos = np.asarray(pos_ecef_m, float).reshape(3)
    if not frags or not np.all(np.isfinite(pos)):
        return raw, 0
    fs = rec.sample_rate_hz / factor
    t_blk, utc_blk = track_times(blocks, factor, rec.sample_rate_hz)
    t0 = utc_blk[0]
    t_rel = (utc_blk - t0) / np.timedelta64(1, "s")
    lo_hz = lo.offset_hz + lo.drift_hz_per_s * ((utc_blk - lo.t_ref_utc) / np.timedelta64(1, "s"))
    eph = Ephemeris(constellation, t0, float(t_rel.max()))
    k = comb.carrier_hz / C_MPS
    taken = {str(tr.sat_id) for tr in named if tr.sat_id is not None}
    free = np.flatnonzero(eph.ok & ~np.isin(constellation.sat_ids.astype(str), list(taken)))
    sin_mask = np.sin(np.radians(mask_deg))
    index = {t: j for j, t in enumerate(t_blk)}
    cands = []
    for i in frags:
        rows = np.array([index[t] for t in raw[i].t_s])
        cands += _candidates(i, rows, raw[i], lo_hz, free, eph, t_rel, pos, np.asarray(pos_cov_m2, float), k,
                             sin_mask, gate_hz)
    if not cands:
        return raw, 0
    # Every track's combs per block (Doppler, rate), fitted alongside.
    others = {k: [(raw[i].doppler_hz[j], raw[i].doppler_rate_hz_per_s[j]) for i, j in rows]
              for k, rows in rows_by_block(raw, t_blk).items()}
    for direction in (1, -1):
        _follow(direction, cands, others, rec, blocks, factor, comb, fs, lo_hz, lo.drift_hz_per_s, band_hz, gate_hz,
                threads, kernel)
    return _merged(raw, frags, cands, index, t_blk, utc_blk, gate_hz)


def _merged(raw, frags, cands, index, t_blk, utc_blk, gate_hz):
    """``raw`` with each fragment replaced by its candidate with the most detections; fragments whose
    candidates follow one satellite become one track (the first's), and a block where two satellites'
    new detections are within two gates of each other (one comb taken by both) is left out of both."""
    best = {}
    for i in frags:
        mine = [c for c in cands if c.track == i and c.rows and not c.lost]
        if mine:
            best[i] = max(mine, key=lambda c: len(c.rows))
    if not best:
        return raw, 0
    by_sat = {}
    for i, c in best.items():
        by_sat.setdefault(c.sat, []).append(i)
    new = {}  # satellite -> {block: (doppler, rate, cn0, sigma)} of its new detections
    for sat, frs in by_sat.items():
        new[sat] = {}
        for i in frs:
            for r in best[i].rows:
                new[sat].setdefault(r[0], r[1:])
    clash = {sat: [j for j, r in rows.items() if any(o != sat and j in other and abs(other[j][0] - r[0]) <= 2 * gate_hz
                                                     for o, other in new.items())]
             for sat, rows in new.items()}  # all found before any is removed: both sides lose the block
    for sat, blocks in clash.items():
        for j in blocks:
            del new[sat][j]
    out, drop = list(raw), set()
    for sat, frs in by_sat.items():
        rows = {}
        for i in frs:  # the fragments' own blocks first
            tr = raw[i]
            for m, t in enumerate(tr.t_s):
                rows.setdefault(index[t], (tr.doppler_hz[m], tr.doppler_rate_hz_per_s[m], tr.cn0_dbhz[m],
                                           tr.sigma_hz[m]))
        for j, r in new[sat].items():
            rows.setdefault(j, r)
        j = np.array(sorted(rows))
        cols = np.array([rows[b] for b in j], float)
        out[frs[0]] = Track(t_blk[j], utc_blk[j], *cols.T)
        drop.update(frs[1:])
    return [tr for k, tr in enumerate(out) if k not in drop], len(best)


def _candidates(i, rows, tr, lo_hz, free, eph, t_rel, pos, pos_cov, k, sin_mask, gate_hz):
    """The satellites whose curve runs through fragment ``i``'s blocks ``rows``, best fits first: their own
    offset and time offset within bounds, and no block of the fragment further off their fitted curve than
    the tracking gate (such a block would not have been followed). A fragment of three blocks or more may
    leave out its worst one for a candidate (a weak block's peak tens of hertz off, or a comb crossing's).
    The offset's bound is the satellite's own plus 3 sigma of the Doppler error the receiver position's
    covariance ``pos_cov`` puts on it at the fragment's middle."""
    mid = rows[len(rows) // 2]
    p, _ = eph.state(free, np.full(free.size, t_rel[mid]))
    los = p - pos
    up = pos / np.linalg.norm(pos)
    sats = free[(los @ up) / np.linalg.norm(los, axis=1) >= sin_mask]
    if sats.size == 0:
        return []
    d0, rate, _ = _curves(eph, sats, t_rel[rows], pos, k)
    p_mid, v_mid = eph.state_received(sats, np.full(sats.size, t_rel[mid]), pos)
    grad = doppler_model(p_mid, v_mid, pos, k)[1]
    c_max = SAT_OFFSET_MAX_HZ + 3.0 * np.sqrt(np.einsum("ni,ij,nj->n", grad, pos_cov, grad))
    r_hz = tr.doppler_hz[None, :] - lo_hz[rows] - d0
    use = np.ones(r_hz.shape, bool)
    c, tau, chi2, resid = _fit(r_hz, rate, tr.sigma_hz, use)
    if len(rows) >= 3:
        worst = np.argmax(np.abs(resid), axis=1)
        redo = np.abs(resid[np.arange(len(sats)), worst]) > gate_hz
        use[np.flatnonzero(redo), worst[redo]] = False
        c, tau, chi2, resid = _fit(r_hz, rate, tr.sigma_hz, use)
        resid = np.where(use, resid, 0.0)
    ok = ((np.abs(c) <= c_max) & (np.abs(tau) <= ALONG_TRACK_MAX_M / SPEED_SV_MPS)
          & (np.max(np.abs(resid), axis=1) <= gate_hz))
    per_block = chi2 / use.sum(axis=1)  # a candidate that left a block out is not favoured for it
    keep = np.flatnonzero(ok)[np.argsort(per_block[ok])][:CANDIDATES]
    out = []
    t_all = t_rel[:, None] + np.array([0.0, -RATE_STEP_S, RATE_STEP_S])
    for m in keep:
        d_all, shift_rate_hz_per_s, vis = (a.reshape(t_all.shape) for a in _curves(
            eph, np.array([sats[m]]), t_all.ravel(), pos, k, sin_mask))
        out.append(_Candidate(i, int(sats[m]), d_all[:, 0], shift_rate_hz_per_s[:, 0],
                              (d_all[:, 2] - d_all[:, 1]) / (2 * RATE_STEP_S), vis[:, 0],
                              (rows[use[m]], tr.doppler_hz[use[m]], tr.sigma_hz[use[m]]), (rows.min(), rows.max()),
                              float(c_max[m]), c_hz=float(c[m]), tau_s=float(tau[m])))
    return out


def _curves(eph, sats, t_s, pos, k, sin_mask=None):
    """Doppler at zero time offset and its derivative in the time offset, (n_sats, n_t) each, and (with
    ``sin_mask``) whether each satellite is above the mask."""
    sat = np.repeat(sats, t_s.size)
    t = np.tile(t_s, sats.size)
    ps, vs = eph.state_received(sat, t, pos)
    d0 = doppler_hz(ps, vs, pos, k).reshape(sats.size, t_s.size)
    shift_rate_hz_per_s = eph.doppler_shift_rate(sat, t, 0.0, pos, k).reshape(sats.size, t_s.size)
    vis = None
    if sin_mask is not None:
        los = ps - pos
        vis = ((los @ (pos / np.linalg.norm(pos))) / np.linalg.norm(los, axis=1) >= sin_mask).reshape(d0.shape)
    return d0, shift_rate_hz_per_s, vis


def _fit(r_hz, rate, sigma_hz, use=True):
    """Offset and time offset per row of ``r_hz`` (n, m) (model ``c + tau rate``, with priors) from the
    blocks ``use`` (n, m): c, tau (n,), chi-square (n,), residuals (n, m)."""
    w = use / (np.asarray(sigma_hz, float) ** 2 + MODEL_SIGMA_HZ**2)
    sig_tau = ALONG_TRACK_SIGMA_M / SPEED_SV_MPS
    a11 = w.sum(-1) + 1 / SAT_OFFSET_SIGMA_HZ**2
    a12 = (w * rate).sum(-1)
    a22 = (w * rate**2).sum(-1) + 1 / sig_tau**2
    b1, b2 = (w * r_hz).sum(-1), (w * rate * r_hz).sum(-1)
    det = a11 * a22 - a12**2
    c, tau = (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det
    resid = r_hz - c[:, None] - tau[:, None] * rate
    chi2 = (w * resid**2).sum(-1) + (c / SAT_OFFSET_SIGMA_HZ) ** 2 + (tau / sig_tau) ** 2
    return c, tau, chi2, resid


def _follow(direction, cands, index_others, rec, blocks, factor, comb, fs, lo_hz, drift, band_hz, gate_hz, threads,
            kernel):
    """Follow every candidate in one direction (+1 later, -1 earlier) from its fragment's ends.

    A candidate stops below the mask, after :data:`MAX_MISSES` captures in a row without a detection (a
    capture where its prediction leaves the band or comes within two gates of another track's comb, a
    crossing the fit could not tell apart, counts as one), or when its fit leaves the bounds."""
    n = len(blocks)
    start = {id(c): c.span[1] + 1 if direction > 0 else c.span[0] - 1 for c in cands}
    live = [c for c in cands if 0 <= start[id(c)] < n and not c.lost]
    if not live:
        return
    first = (min if direction > 0 else max)(start[id(c)] for c in live)
    todo = list(range(first, n) if direction > 0 else range(first, -1, -1))
    misses = dict.fromkeys(map(id, live), 0)
    stream = prepared_blocks(rec, [blocks[j] for j in todo], factor, comb, threads=threads, kernel=kernel)
    try:
        for j, block in zip(todo, stream):
            started = {id(c): (j - start[id(c)]) * direction >= 0 for c in live}
            live = [c for c in live if not c.lost and misses[id(c)] < MAX_MISSES
                    and (c.visible[j] or not started[id(c)])]
            if not live:
                break
            near = index_others.get(j, [])
            f_other = np.array([f for f, _ in near])
            here = []
            for c in (c for c in live if started[id(c)]):
                p = c.predict(j, lo_hz)
                if abs(p) <= band_hz and not np.any(np.abs(f_other - p) <= 2 * gate_hz):
                    here.append(c)
                else:
                    misses[id(c)] += 1
            if not here:
                continue
            f_all = np.concatenate([f_other, [c.predict(j, lo_hz) for c in here]])
            rate_all = np.concatenate([[r for _, r in near], [c.rate_hz_per_s[j] + drift for c in here]])
            found = find_combs(None, fs, comb=comb, predicted_hz=f_all,
                               predicted_rate_hz_per_s=np.nan_to_num(rate_all), search=False, gate_hz=gate_hz,
                               max_combs=f_all.size, lo_offset_hz=lo_hz[j], clean=False, spectrum=block.iq_fft,
                               kernel=kernel)
            # A comb beyond the gate (find_combs keeps one up to two bins further) is not the candidate's.
            hit = {int(p) - f_other.size: m for m, p in enumerate(found.predicted_index)
                   if p >= f_other.size and abs(found.doppler_hz[m] - f_all[p]) <= gate_hz}
            for h, c in enumerate(here):
                if h not in hit:
                    misses[id(c)] += 1
                    continue
                m = hit[h]
                misses[id(c)] = 0
                c.rows.append((j, found.doppler_hz[m], found.doppler_rate_hz_per_s[m], found.cn0_dbhz[m],
                               found.sigma_hz[m]))
                _refit(c, lo_hz)
    finally:
        stream.close()


def _refit(c, lo_hz):
    """The candidate's offset and time offset from its fragment's blocks and its detections; a fit beyond
    the bounds (the candidate's curve dragged onto another satellite's comb) loses the candidate and its
    detections."""
    rows, f, sigma = c.base
    j = np.concatenate([rows, [r[0] for r in c.rows]]).astype(int)
    f = np.concatenate([f, [r[1] for r in c.rows]])
    sigma = np.concatenate([sigma, [r[4] for r in c.rows]])
    cc, tau, _, _ = _fit((f - lo_hz[j] - c.d0_hz[j])[None, :], c.shift_rate_hz_per_s[j][None, :], sigma)
    c.c_hz, c.tau_s = float(cc[0]), float(tau[0])
    if abs(c.c_hz) > c.c_max_hz or abs(c.tau_s) > ALONG_TRACK_MAX_M / SPEED_SV_MPS:
        c.lost = True
        c.rows.clear()
