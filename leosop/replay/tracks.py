"""Doppler tracks: one comb followed across blocks and capture gaps."""

from dataclasses import dataclass

import numpy as np

__all__ = ["Detections", "Track", "Tracker", "join_fragments", "remove_outliers"]


@dataclass
class Track:
    """The measurements of one comb over a recording.

    Attributes
    ----------
    t_s : ndarray, (n,)
        Block centres, seconds from the recording's first sample.
    time_utc : ndarray of datetime64[ns], (n,)
        The same instants in UTC.
    doppler_hz, doppler_rate_hz_per_s, cn0_dbhz, sigma_hz : ndarray, (n,)
        Central-tone Doppler (DESIGN 4.2 sign, clocks included), its rate,
        C/N0 per tone and the Doppler's standard deviation.
    sat_id : str or None
        NORAD catalogue number once identified; None while unknown or when no
        satellite explains the track.
    match_rms_hz : float or None
        RMS of the identified satellite's Doppler residuals.
    id_status : str or None
        The identification's status (``ok`` when ``sat_id`` is vouched for;
        :data:`~leosop.replay.match.ID_STATUSES`); None before identification.
    """

    t_s: np.ndarray
    time_utc: np.ndarray
    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray
    sat_id: str | None = None
    match_rms_hz: float | None = None
    id_status: str | None = None

    def __len__(self):
        return len(self.t_s)


@dataclass(frozen=True)
class Detections:
    """The combs found in one block, each field (n_found,)."""

    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray

    def __len__(self):
        return len(self.doppler_hz)


#: Doppler gate of the association [Hz]: a constant part for the estimates'
#: errors, a part growing with the gap for an error of the track's rate, and
#: one for the change of the rate itself (a Starlink pass changes its rate by
#: up to ~50 Hz/s^2 near culmination at 11.3 GHz). Combs of different
#: satellites are kHz apart almost always, so a generous gate costs nothing.
GATE_HZ = 150.0
GATE_HZ_PER_S = 60.0
GATE_HZ_PER_S2 = 40.0
#: Rate sigma over (Doppler sigma / block length) for a chirp's joint
#: estimate: with the phase a + b tau + c tau^2 / 2 over a centred block of
#: length T, var(c) / var(b) = 60 / T^2, so sigma_rate = sqrt(60) sigma_f / T.
RATE_SIGMA_FACTOR = np.sqrt(60.0)
#: Detections a track's prediction is fitted to.
_FIT_POINTS = 8


class Tracker:
    """Joins each block's detections into tracks (global nearest neighbour).

    A track predicts its Doppler at the next block from its last Doppler, its
    rate and the change of rate between its last two blocks, so it crosses
    capture gaps (snapshot recordings) as well as consecutive blocks. A
    detection no track claims starts a tentative track, confirmed by
    ``min_blocks`` detections no more than ``max_gap_tentative_s`` apart
    (false alarms do not line up like that); a confirmed track not fed for
    ``max_gap_s`` ends. Unconfirmed tracks are dropped.

    Parameters
    ----------
    max_gap_s : float
        Longest time without a detection before a confirmed track ends.
    min_blocks : int
        Detections that confirm a track.
    max_gap_tentative_s : float
        Longest gap inside a track before it is confirmed.
    """

    def __init__(self, *, max_gap_s=5.0, min_blocks=3, max_gap_tentative_s=2.5):
        self.max_gap_s = float(max_gap_s)
        self.min_blocks = int(min_blocks)
        self.max_gap_tentative_s = float(max_gap_tentative_s)
        self._active = []  # lists of rows (t_s, time_utc, f, rate, cn0, sigma)
        self._done = []
        self._memo = (None, {})  # the last predictions: (t_s, {id(rows): prediction})

    def _predict(self, rows, t_s):
        """Predicted Doppler at ``t_s`` and the gate around it.

        One detection: its Doppler and rate, the gate widened by three
        sigmas of the rate (a short block measures its rate poorly). Two: the
        line through them. From three on, a weighted quadratic (a line for
        three) through the last few Doppler values.
        """
        t_last, f_last, r_last, sigma_rate = rows[-1][0], rows[-1][2], rows[-1][3], rows[-1][6]
        dt = t_s - t_last
        gate = GATE_HZ + GATE_HZ_PER_S * dt + GATE_HZ_PER_S2 * dt**2
        if len(rows) == 1:
            r = r_last if np.isfinite(r_last) else 0.0
            return f_last + r * dt, r, gate + 3.0 * sigma_rate * dt
        recent = rows[-_FIT_POINTS:]
        tau = np.array([r[0] for r in recent]) - t_last
        f = np.array([r[2] for r in recent])
        sigma = np.array([r[5] for r in recent])
        w = 1.0 / np.where(np.isfinite(sigma) & (sigma > 0), sigma, 1.0)
        deg = 1 if len(recent) <= 3 or np.ptp(tau) == 0 else 2
        # Weighted least squares in powers of tau (a small polyfit without its overhead).
        a = tau[:, None] ** np.arange(deg + 1)
        c = np.linalg.lstsq(a * w[:, None], f * w, rcond=None)[0]
        rate = c[1] + (2.0 * c[2] * dt if deg == 2 else 0.0)
        return float(np.polyval(c[::-1], dt)), float(rate), gate

    def _predict_all(self, tracks, t_s):
        """:meth:`_predict` of every track in ``tracks`` (lists of rows), as a list: the tracks
        with a full history fitted together (one batched 3 x 3 solve), the others one by one."""
        out = [None] * len(tracks)
        full = [i for i, rows in enumerate(tracks) if len(rows) >= _FIT_POINTS]
        if full:
            recent = np.array([[(r[0], r[2], r[5]) for r in tracks[i][-_FIT_POINTS:]] for i in full])  # (n, P, 3)
            t_last = recent[:, -1, 0]
            tau = recent[:, :, 0] - t_last[:, None]
            sigma = recent[:, :, 2]
            w2 = 1.0 / np.where(np.isfinite(sigma) & (sigma > 0), sigma, 1.0) ** 2
            a = tau[..., None] ** np.arange(3)  # (n, P, 3)
            aw = a * w2[..., None]
            normal = np.einsum("npi,npj->nij", aw, a)
            c = np.linalg.solve(normal, np.einsum("npi,np->ni", aw, recent[:, :, 1])[..., None])[..., 0]
            dt = t_s - t_last
            f = c[:, 0] + c[:, 1] * dt + c[:, 2] * dt**2
            rate = c[:, 1] + 2.0 * c[:, 2] * dt
            gate = GATE_HZ + GATE_HZ_PER_S * dt + GATE_HZ_PER_S2 * dt**2
            for j, i in enumerate(full):
                out[i] = (float(f[j]), float(rate[j]), float(gate[j]))
        for i, rows in enumerate(tracks):
            if out[i] is None:
                out[i] = self._predict(rows, t_s)
        return out

    def predictions(self, t_s):
        """Doppler and rate at ``t_s`` of every track fed in the last block, (n,) each; None after a birth.

        For tracking-mode estimation of the next block (the estimator then
        fits each prediction instead of searching the spectrum). None when a
        track was born in the last block (it has no reliable rate yet, and a
        new comb calls for a full search anyway) or when there is no track.
        """
        if not self._active:
            return None
        t_last = max(rows[-1][0] for rows in self._active)
        live = [rows for rows in self._active if rows[-1][0] == t_last]
        if any(len(rows) < 2 for rows in live):
            return None
        self._memo = (t_s, dict(zip(map(id, self._active), self._predict_all(self._active, t_s))))
        f, r, _ = np.array([self._memo[1][id(rows)] for rows in live]).T
        return f, r

    def update(self, t_s, time_utc, det, block_s=None):
        """Take the detections of the block centred at ``t_s`` (``time_utc``), ``block_s`` long.

        The block length sets how well a detection's rate is known
        (``RATE_SIGMA_FACTOR * sigma_hz / block_s``); without it the rate is
        taken as exact.
        """
        from scipy.optimize import linear_sum_assignment

        keep = []
        for rows in self._active:
            confirmed = len(rows) >= self.min_blocks
            if t_s - rows[-1][0] <= (self.max_gap_s if confirmed else self.max_gap_tentative_s):
                keep.append(rows)
            elif confirmed:
                self._done.append(rows)
        self._active = keep
        claimed = np.zeros(len(det), bool)
        if self._active and len(det):
            if self._memo[0] == t_s and all(id(rows) in self._memo[1] for rows in self._active):
                pred, _, gate = np.array([self._memo[1][id(rows)] for rows in self._active]).T
            else:
                pred, _, gate = np.array(self._predict_all(self._active, t_s)).T
            cost = np.abs(det.doppler_hz[None, :] - pred[:, None]) / gate[:, None]
            big = 1e6
            i, j = linear_sum_assignment(np.where(cost <= 1.0, cost, big))
            for a, b in zip(i, j):
                if cost[a, b] <= 1.0:
                    self._active[a].append(self._row(t_s, time_utc, det, b, block_s))
                    claimed[b] = True
        for b in np.flatnonzero(~claimed):
            self._active.append([self._row(t_s, time_utc, det, b, block_s)])

    @staticmethod
    def _row(t_s, time_utc, det, k, block_s):
        sigma_rate = 0.0
        if block_s and np.isfinite(det.sigma_hz[k]):
            sigma_rate = RATE_SIGMA_FACTOR * det.sigma_hz[k] / block_s
        return (t_s, time_utc, det.doppler_hz[k], det.doppler_rate_hz_per_s[k], det.cn0_dbhz[k], det.sigma_hz[k],
                sigma_rate)

    def finish(self):
        """All tracks of at least ``min_blocks`` detections, in order of their first block."""
        rows_all = sorted((r for r in self._done + self._active if len(r) >= self.min_blocks),
                          key=lambda r: (r[0][0], r[0][2]))
        self._active, self._done = [], []
        tracks = []
        for rows in rows_all:
            t, utc, f, r, c, s, _ = zip(*rows)
            tracks.append(Track(np.array(t, float), np.array(utc, "datetime64[ns]"), np.array(f, float),
                                np.array(r, float), np.array(c, float), np.array(s, float)))
        return tracks


#: Neighbours of each detection in the local cubic that predicts it: a LEO
#: Doppler curve's quartic term over ~10 s is well below a hertz.
_NEIGHBOURS = 10
#: An estimate further than this many predicted sigmas (plus the model's
#: slack) from its neighbours' cubic is an outlier: a fine search that
#: locked on a sidelobe (another comb's tone within a few bins) is off by
#: tens to hundreds of hertz.
OUTLIER_SIGMAS = 6.0
OUTLIER_SLACK_HZ = 2.0


def _neighbour_residuals(t, f, sigma):
    """Residual of each point from a cubic through its nearest neighbours, and its sigma, (n,) each."""
    n = len(t)
    k = min(_NEIGHBOURS, n - 1)
    idx = np.argsort(np.abs(t[:, None] - t[None, :]), axis=1, kind="stable")[:, 1:k + 1]  # (n, k), self excluded
    dt = t[idx] - t[:, None]
    scale = np.maximum(np.max(np.abs(dt), axis=1, keepdims=True), 1e-9)
    deg = min(3, k - 2)
    A = (dt / scale)[..., None] ** np.arange(deg + 1)  # (n, k, deg+1)
    w = 1.0 / sigma[idx] ** 2
    N = np.einsum("nki,nk,nkj->nij", A, w, A)
    b = np.einsum("nki,nk,nk->ni", A, w, f[idx])
    coef = np.linalg.solve(N, b[..., None])[..., 0]
    pred_var = np.linalg.inv(N)[:, 0, 0]  # prediction at dt = 0 is the constant term
    return f - coef[:, 0], np.sqrt(sigma**2 + pred_var)


def remove_outliers(track):
    """The track without the detections that do not follow its curve.

    One at a time, the detection furthest (in its predicted sigma) from a
    cubic through its nearest neighbours is removed while it exceeds
    ``OUTLIER_SIGMAS`` sigmas plus ``OUTLIER_SLACK_HZ``; so one outlier never
    condemns its neighbours.

    Returns
    -------
    Track
        A new track (the same one if nothing is removed); short tracks
        (fewer than 5 detections) are returned as they are.
    """
    keep = np.ones(len(track), bool)
    sigma = np.where(np.isfinite(track.sigma_hz) & (track.sigma_hz > 0), track.sigma_hz, 1.0)
    while keep.sum() >= 5:
        i = np.flatnonzero(keep)
        r, s = _neighbour_residuals(track.t_s[i], track.doppler_hz[i], sigma[i])
        score = np.abs(r) / (OUTLIER_SIGMAS * s + OUTLIER_SLACK_HZ)
        worst = np.argmax(score)
        if score[worst] <= 1.0:
            break
        keep[i[worst]] = False
    if keep.all():
        return track
    return Track(track.t_s[keep], track.time_utc[keep], track.doppler_hz[keep], track.doppler_rate_hz_per_s[keep],
                 track.cn0_dbhz[keep], track.sigma_hz[keep], track.sat_id, track.match_rms_hz)


def _extrapolate(t, f, sigma, t_new):
    """Weighted quadratic (line for fewer than 4 points) through (t, f), evaluated at ``t_new``."""
    t, f, sigma = t[-_FIT_POINTS:], f[-_FIT_POINTS:], sigma[-_FIT_POINTS:]
    w = 1.0 / np.where(np.isfinite(sigma) & (sigma > 0), sigma, 1.0)
    deg = 1 if t.size < 4 or np.ptp(t) == 0 else 2
    return np.polyval(np.polyfit(t - t[-1], f, deg, w=w), np.asarray(t_new) - t[-1])


def join_fragments(tracks, max_gap_s):
    """Tracks that continue one another joined into one (a comb lost for a while and found again).

    A later track B continues an earlier A when B starts after A ends, within
    ``max_gap_s``, and A's curve extrapolated to B's first detections (and
    B's curve back to A's last) falls within the tracker's gate. Each A is
    joined to the B that fits best, repeatedly, so chains join too.

    Returns
    -------
    list of Track
        In order of their first block.
    """
    tracks = sorted(tracks, key=lambda tr: tr.t_s[0])
    joined = True
    while joined:
        joined = False
        for i, a in enumerate(tracks):
            best, best_cost = None, 1.0
            for j, b in enumerate(tracks):
                dt = b.t_s[0] - a.t_s[-1]
                if j == i or not 0 < dt <= max_gap_s or len(a) < 2 or len(b) < 2:
                    continue
                gate = GATE_HZ + GATE_HZ_PER_S * dt + GATE_HZ_PER_S2 * dt**2
                fwd = _extrapolate(a.t_s, a.doppler_hz, a.sigma_hz, b.t_s[:3]) - b.doppler_hz[:3]
                back = _extrapolate(b.t_s[:_FIT_POINTS], b.doppler_hz[:_FIT_POINTS], b.sigma_hz[:_FIT_POINTS],
                                    a.t_s[-1]) - a.doppler_hz[-1]
                cost = max(np.max(np.abs(fwd)), abs(float(back))) / gate
                if cost < best_cost:
                    best, best_cost = j, cost
            if best is not None:
                b = tracks[best]
                cat = lambda name: np.concatenate([getattr(a, name), getattr(b, name)])  # noqa: E731
                tracks[i] = Track(cat("t_s"), cat("time_utc"), cat("doppler_hz"), cat("doppler_rate_hz_per_s"),
                                  cat("cn0_dbhz"), cat("sigma_hz"))
                del tracks[best]
                joined = True
                break
    return tracks
