"""Which satellite is this comb? Doppler tracks identified against a TLE snapshot.

The unknowns are the receiver position (a prior within ~100 km, or none),
the receiver clock offset and drift (common to all tracks), each
satellite's own small frequency offset and each element set's along-track
error (a time offset of its predicted Doppler curve). The search runs in
three stages:

1. **Cell vote.** The receiver position is searched on cells (a local grid
   round the prior, or a Fibonacci grid of the whole Earth without one).
   Every track gives three features at three reference times (first, middle
   and last): the Doppler offset at the middle, the slope and the curvature
   of the residual "measured minus predicted". Slope and curvature do not
   depend on the clock offset; the offset is the clock, common to all
   tracks. A (cell, track, candidate) triple passes when its slope and
   curvature are within tolerance; it then votes for the clock offsets
   within its offset tolerance. A cell's score is the number of tracks that
   agree on one clock offset. Tolerances are first-order bounds: the
   Doppler's gradient with respect to the receiver position times the cell
   radius, the Doppler rate times the largest along-track time error, the
   clock drift, and the measurement noise. The best cells are split 3 x 3
   and voted again, down to ~1 km.
2. **Joint least squares** on the best cells' tentative assignment:
   position, clock offset and drift, a frequency offset and a time offset
   per satellite (with priors), tracks that do not fit dropped one by one.
3. **Identification** at the solution: every candidate above the mask is
   fitted to every track (its own offset and time offset, with priors); the
   best is accepted only when its chi-square is consistent with the
   track's sigma (inflated for model and position errors) and clearly below
   the runner-up's; else ``sat_id`` is None. A satellite claimed by two
   tracks goes to the better one.

Satellite states come from one SGP4 propagation of every satellite on a
coarse time grid, interpolated by cubic Hermite polynomials (position and
velocity at the nodes); the light time is applied as in
:func:`leosop.positioning.measurements.sv_states_from_tle` (state at the
transmit time, rotated into the ECEF frame of the reception time) in stages
2 and 3, and bounded by a 10 ms time tolerance in stage 1. This is the
familiar Doppler-positioning problem [Kassas 2019] with unknown data
association, solved by voting over a position grid before refining.
"""

import time
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..constants import C_MPS, OMEGA_E_RAD_PER_S, STARLINK_PILOT_HZ, WGS84_A_M
from ..errors import InputError
from ..frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef
from ..orbits.propagate import state_ecef

__all__ = ["Identification", "identify_tracks"]

#: Node spacing of the propagated grid [s]: the cubic Hermite interpolation
#: of a LEO orbit errs ~1 mm in position and ~0.1 mm/s in velocity at 10 s.
NODE_STEP_S = 10.0
#: Growth of the first-order tolerances for the neglected curvature of the
#: Doppler in position across a cell (cells << range).
_LINEAR_MARGIN = 1.3
#: Reference times per track: first, middle, last. Rows: offset at the
#: middle, slope, curvature of the residual at those times.
_FEATURES = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 1.0], [-0.5, 1.0, -0.5]])
#: Satellite speed converting along-track errors to time offsets [m/s] (LEO at ~550 km).
_SPEED_SV_MPS = 7600.0
#: Half-width of the window that smooths a track's value at a reference time [s].
_LOCAL_S = 0.25
#: Samples per track in the least squares and the identification.
_MAX_SAMPLES = 120
#: Largest light time, bounding its effect in the cell vote [s].
_LIGHT_TIME_MAX_S = 0.012
#: Largest Doppler rate of a LEO satellite at Ku band, a bound for the screen [Hz/s].
_RATE_MAX_HZ_PER_S = 5e3
#: Largest angular rate of a line of sight to a LEO satellite [rad/s] (7.6 km/s at 550 km overhead).
_SAT_RATE_MAX_RAD_PER_S = 0.014
#: Candidates per track fitted in the identification (nearest in Doppler at the track's middle).
_ID_CANDIDATES = 24
#: Chi-square (3 features) above which a cell's linearised fit does not count a track.
_TRACK_CHI2_GATE = 25.0
#: Cells voted at once, and at most this many (cell, track, satellite) triples (memory bound:
#: ~1 kB of intermediate arrays per triple that passes the first screen).
_CHUNK_CELLS = 400
_MAX_PAIRS = 300_000


@dataclass
class Identification:
    """What :func:`identify_tracks` found.

    Attributes
    ----------
    sat_id : list of (str or None), (n_tracks,)
        NORAD number per track (None: no satellite explains it clearly).
    match_rms_hz : ndarray, (n_tracks,)
        RMS Doppler residual of the identified satellite (NaN for None).
    margin : ndarray, (n_tracks,)
        Chi-square of the runner-up minus that of the best candidate (NaN
        when no candidate fitted).
    runner_up_id : list of (str or None), (n_tracks,)
    pos_ecef_m : ndarray, (3,)
        Receiver position of the search (a start for the fix); NaN if none.
    pos_cov_m2 : ndarray, (3, 3)
    clock_offset_hz, clock_drift_hz_per_s : float
        Receiver clock (Doppler of the central tone) at ``t_ref_utc``.
    t_ref_utc : numpy.datetime64
    n_candidates : int
        Satellites considered.
    elapsed_s : float
    """

    sat_id: list
    match_rms_hz: np.ndarray
    margin: np.ndarray
    runner_up_id: list
    pos_ecef_m: np.ndarray
    pos_cov_m2: np.ndarray
    clock_offset_hz: float
    clock_drift_hz_per_s: float
    t_ref_utc: np.datetime64
    n_candidates: int
    elapsed_s: float


def _rotate_z(vec, angle_rad):
    """``vec`` (..., 3) in a frame turned by ``angle_rad`` (...) about z."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([c * vec[..., 0] + s * vec[..., 1], -s * vec[..., 0] + c * vec[..., 1], vec[..., 2]], axis=-1)


class _Ephemeris:
    """SGP4 states of all satellites on a time grid, Hermite-interpolated."""

    def __init__(self, constellation, t0_utc, span_s):
        pad = 2.0 * NODE_STEP_S
        n = int(np.ceil((span_s + 2 * pad) / NODE_STEP_S)) + 1
        self.t_grid_s = -pad + NODE_STEP_S * np.arange(n)
        times = t0_utc + np.round(self.t_grid_s * 1e9).astype("timedelta64[ns]")
        pos, vel, status = state_ecef(constellation, times)
        self.ok = (status == 0).all(axis=1) & np.isfinite(pos).all(axis=(1, 2))
        self.pos, self.vel = np.nan_to_num(pos), np.nan_to_num(vel)

    def state(self, sat, t_s):
        """Position and velocity (..., 3) of satellites ``sat`` at ``t_s`` (broadcast)."""
        x = (np.asarray(t_s, float) - self.t_grid_s[0]) / NODE_STEP_S
        i = np.clip(np.floor(x).astype(int), 0, len(self.t_grid_s) - 2)
        s = (x - i)[..., None]
        p0, p1 = self.pos[sat, i], self.pos[sat, i + 1]
        v0, v1 = self.vel[sat, i] * NODE_STEP_S, self.vel[sat, i + 1] * NODE_STEP_S
        s2, s3 = s * s, s * s * s
        pos = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * v0 + (3 * s2 - 2 * s3) * p1 + (s3 - s2) * v1
        vel = ((6 * s2 - 6 * s) * (p0 - p1) + (3 * s2 - 4 * s + 1) * v0 + (3 * s2 - 2 * s) * v1) / NODE_STEP_S
        return pos, vel

    def state_received(self, sat, t_s, pos_rx_ecef_m):
        """Apparent state: position at the transmit time in the ECEF frame of the reception time
        ``t_s``, velocity its derivative over reception time (as
        :func:`~leosop.positioning.measurements.sv_states_from_tle`)."""
        pos, vel = self.state(sat, t_s)
        for _ in range(2):  # each pass gains |range rate| / c ~ 3e-5
            tau = np.linalg.norm(pos - pos_rx_ecef_m, axis=-1) / C_MPS
            pos, vel = self.state(sat, t_s - tau)
        pos, vel = _rotate_z(pos, OMEGA_E_RAD_PER_S * tau), _rotate_z(vel, OMEGA_E_RAD_PER_S * tau)
        # d/dt_rx of R(omega tau) r(t_rx - tau): the light time's rate tau_dot = range rate / c
        # scales the velocity (up to ~6 Hz at Ku band) and turns the frame (< 0.5 Hz).
        los = pos - pos_rx_ecef_m
        tau_dot = np.sum(los * vel, axis=-1) / np.linalg.norm(los, axis=-1) / C_MPS
        turn = np.stack([pos[..., 1], -pos[..., 0], np.zeros_like(tau)], axis=-1)
        return pos, vel * (1 - tau_dot)[..., None] + (OMEGA_E_RAD_PER_S * tau_dot)[..., None] * turn


def _doppler(pos_sv, vel_sv, pos_rx, hz_per_mps, los=False):
    """Doppler (...) and its gradient (..., 3) in the receiver position [Hz/m].

    ``vel_sv`` is relative to the receiver (satellite minus receiver
    velocity). With ``los`` the unit line of sight (..., 3) is returned too.
    """
    los_m = pos_sv - pos_rx
    rng = np.linalg.norm(los_m, axis=-1)
    u = los_m / rng[..., None]
    rr = np.sum(u * vel_sv, axis=-1)
    grad = hz_per_mps * (vel_sv - rr[..., None] * u) / rng[..., None]
    return (-hz_per_mps * rr, grad, u) if los else (-hz_per_mps * rr, grad)


@dataclass
class _Track:
    """One track as the search sees it (times in s from the search epoch)."""

    t_s: np.ndarray
    doppler_hz: np.ndarray
    sigma_hz: np.ndarray
    t_ref_s: np.ndarray  # (3,)
    f_ref_hz: np.ndarray  # (3,)
    feat_sigma: np.ndarray  # (3,) offset, slope, curvature
    sample: np.ndarray  # indices used in the least squares

    @property
    def t_mid_s(self):
        return self.t_ref_s[1]


def _local_value(t, f, sigma, t0, m):
    """Weighted straight line through the ``m`` samples nearest ``t0`` (within ``_LOCAL_S``): value, sigma at ``t0``.

    The window is short so that the curve's own curvature (up to ~50 Hz/s^2) biases the value by
    less than ~1 Hz: snapshot tracks (one capture a second) use the nearest sample alone.
    """
    near = np.argsort(np.abs(t - t0))[:m]
    near = near[np.abs(t[near] - t0) <= _LOCAL_S] if np.abs(t[near[0]] - t0) <= _LOCAL_S else near[:1]
    m = len(near)
    if m == 1 or np.ptp(t[near]) == 0:
        w = 1.0 / sigma[near] ** 2
        return np.sum(w * f[near]) / np.sum(w), 1.0 / np.sqrt(np.sum(w))
    a = np.stack([np.ones(m), t[near] - t0], axis=1) / sigma[near, None]
    cov = np.linalg.inv(a.T @ a)
    coef = cov @ (a.T @ (f[near] / sigma[near]))
    return coef[0], np.sqrt(cov[0, 0])


def _prepare(track, t0_utc):
    t = (np.asarray(track.time_utc, "datetime64[ns]") - t0_utc) / np.timedelta64(1, "s")
    f = np.asarray(track.doppler_hz, float)
    sigma = np.asarray(track.sigma_hz, float)
    good = np.isfinite(t) & np.isfinite(f)
    if good.sum() < 3:
        return None
    t, f, sigma = t[good], f[good], sigma[good]
    fill = np.nanmedian(np.where(sigma > 0, sigma, np.nan)) if np.any(sigma > 0) else 1.0
    sigma = np.where(np.isfinite(sigma) & (sigma > 0), sigma, fill if np.isfinite(fill) else 1.0)
    order = np.argsort(t)
    t, f, sigma = t[order], f[order], sigma[order]
    t_ref = np.array([t[0], t[len(t) // 2], t[-1]])
    m = int(np.clip(len(t) // 3, 1, 5))
    vals = np.array([_local_value(t, f, sigma, tr, m) for tr in t_ref])
    span = max(t_ref[2] - t_ref[0], 1e-3)
    feat = _FEATURES / np.array([1.0, span, 1.0])[:, None]
    feat_sigma = np.sqrt((feat**2) @ (vals[:, 1] ** 2))
    sample = np.unique(np.linspace(0, len(t) - 1, min(len(t), _MAX_SAMPLES)).round().astype(int))
    return _Track(t, f, sigma, t_ref, vals[:, 0], feat_sigma, sample)


def _fibonacci_cells(spacing_m, alt_m):
    """Nearly uniform points on the ellipsoid, ~``spacing_m`` apart, (n, 3)."""
    n = int(np.ceil(4 * np.pi * WGS84_A_M**2 / spacing_m**2))
    k = np.arange(n) + 0.5
    lat = np.arcsin(1 - 2 * k / n)
    lon = np.mod(np.pi * (1 + 5**0.5) * k, 2 * np.pi)
    return geodetic_to_ecef(lat, lon, alt_m)


def _grid_around(centre_ecef_m, offsets_m, alt_m):
    """Points at horizontal offsets (n, 2) [east, north] of each centre (c, 3), at ``alt_m``: (c * n, 3)."""
    lat, lon, _ = ecef_to_geodetic(centre_ecef_m)
    enu = np.concatenate([offsets_m, np.zeros((len(offsets_m), 1))], axis=1)
    pts = centre_ecef_m[:, None, :] + np.einsum("cij,nj->cni", C_e_n(lat, lon), enu)
    lat2, lon2, _ = ecef_to_geodetic(pts.reshape(-1, 3))
    return geodetic_to_ecef(lat2, lon2, alt_m)


class _Search:
    """The state shared by the stages of one identification."""

    def __init__(self, tracks, eph, hz_per_mps, opts, region=None):
        self.tracks, self.eph, self.k, self.o = tracks, eph, hz_per_mps, opts
        self.moving = opts["rx_speed_sigma_mps"] > 0
        self.t_c = float(np.mean([tr.t_mid_s for tr in tracks]))
        sin_m = np.sin(np.radians(opts["mask_deg"] - opts["mask_slack_deg"]))
        cos_m = np.sqrt(1 - sin_m**2)
        n_sats = len(eph.ok)
        t_ref = np.array([tr.t_ref_s for tr in tracks])
        # Unit vectors of the satellites at each track's middle time and their footprint half-angles.
        p, _ = eph.state(np.arange(n_sats)[None, :], t_ref[:, None, 1])  # (n_tracks, n_sats, 3)
        r = np.linalg.norm(p, axis=-1)
        self.unit = p / np.where(r > 0, r, 1.0)[..., None]
        lam = np.arccos(np.clip(WGS84_A_M * cos_m / np.where(eph.ok, r, 1e12), -1, 1)) - np.arcsin(sin_m)
        self.half_angle = np.where(eph.ok, lam, -1.0)
        if region is not None:  # (centre ECEF, radius): satellites that no point of it sees are dropped
            centre, radius_m = region
            cos_sep = self.unit @ (centre / np.linalg.norm(centre))
            self.half_angle[np.arccos(np.clip(cos_sep, -1, 1)) > self.half_angle + radius_m / WGS84_A_M] = -1.0
        # States of the satellites some track may pair with (all but those no point of the region
        # sees) at each track's reference times and 0.5 s either side, (n_tracks, n_cand, 3 offsets,
        # 3 ref times, 3), indexed through ``local``: memory grows with tracks x candidates, ~50 of a
        # 10,000-satellite snapshot with a prior.
        cand = np.flatnonzero((self.half_angle > 0).any(axis=0))
        self.local = np.full(n_sats, -1)
        self.local[cand] = np.arange(len(cand))
        t_eval = t_ref[:, None, :] + np.array([0.0, -0.5, 0.5])[:, None]  # (n_tracks, 3, 3)
        self.ref_pos, self.ref_vel = eph.state(cand[None, :, None, None], t_eval[:, None])

    def _pairs(self, cells, radius_m):
        """(cell, track, sat) triples with the satellite above the mask from somewhere in the cell, (m, 3)."""
        cu = cells / np.linalg.norm(cells, axis=1)[:, None]
        out = []
        for k in range(len(self.tracks)):
            ok = self.half_angle[k] > 0
            sats = np.flatnonzero(ok)
            cos_reach = np.cos(self.half_angle[k][sats] + radius_m / WGS84_A_M)
            c, j = np.nonzero(cu @ self.unit[k][sats].T >= cos_reach)
            out.append(np.stack([c, np.full(len(c), k), sats[j]], axis=1))
        return np.concatenate(out)

    def vote(self, cells, radius_m):
        """Score cells.

        Returns
        -------
        count : ndarray of int, (n_cells,)
            Tracks agreeing on one clock offset and explained by the cell's linearised fit.
        cost : ndarray, (n_cells,)
            Chi-square of a linearised fit of position offset, clock and drift to the
            agreeing tracks' features.
        assign : ndarray of int, (n_cells, n_tracks)
            Best satellite per track (-1 for none).
        clock_hz : ndarray, (n_cells,)
        moved_ecef_m : ndarray, (n_cells, 3)
            Cell centres moved by the fitted position offset (at most 1.5 radii).
        """
        n_cells, n_tr = len(cells), len(self.tracks)
        count = np.zeros(n_cells, int)
        cost = np.full(n_cells, np.inf)
        assign = np.full((n_cells, n_tr), -1)
        clock = np.zeros(n_cells)
        moved = cells.copy()
        a = 0
        while a < n_cells:
            size = min(_CHUNK_CELLS, n_cells - a)
            pairs = self._pairs(cells[a:a + size], radius_m)
            while len(pairs) > _MAX_PAIRS and size > 1:
                size = max(1, size * _MAX_PAIRS // len(pairs))
                pairs = self._pairs(cells[a:a + size], radius_m)
            sl = slice(a, a + size)
            count[sl], cost[sl], assign[sl], clock[sl], moved[sl] = self._vote_chunk(cells[sl], radius_m, pairs)
            a += size
        return count, cost, assign, clock, moved

    def _vote_chunk(self, cells, radius_m, pairs):
        o = self.o
        n_cells, n_tr = len(cells), len(self.tracks)
        c, k, s = pairs.T
        t_ref = np.array([tr.t_ref_s for tr in self.tracks])[k]  # (m, 3)
        f_ref = np.array([tr.f_ref_hz for tr in self.tracks])[k]
        span = np.maximum(t_ref[:, 2] - t_ref[:, 0], 1e-3)
        # Cheap screen at the middle time: the offset must fit the clock range.
        reach = _LINEAR_MARGIN * (radius_m + o["cross_track_max_m"] + o["alt_tol_m"])
        dt_max = o["along_track_max_m"] / _SPEED_SV_MPS + _LIGHT_TIME_MAX_S
        s_loc = self.local[s]
        dm, gm = _doppler(self.ref_pos[k, s_loc, 0, 1], self.ref_vel[k, s_loc, 0, 1], cells[c], self.k)
        near = np.abs(f_ref[:, 1] - dm) <= (o["clock_search_hz"] + reach * np.linalg.norm(gm, axis=1)
                                            + dt_max * _RATE_MAX_HZ_PER_S + o["sat_offset_max_hz"]
                                            + o["clock_drift_max_hz_per_s"] * np.abs(t_ref[:, 1] - self.t_c))
        c, k, s, t_ref, f_ref, span = c[near], k[near], s[near], t_ref[near], f_ref[near], span[near]
        pos_rx = cells[c][:, None, :]
        p, v = self.ref_pos[k, s_loc[near]], self.ref_vel[k, s_loc[near]]  # (m, 3 offsets, 3 ref times, 3)
        dop, grad = _doppler(p[:, 0], v[:, 0], pos_rx, self.k)
        rate = _doppler(p[:, 2], v[:, 2], pos_rx, self.k)[0] - _doppler(p[:, 1], v[:, 1], pos_rx, self.k)[0]
        scale = np.stack([np.ones_like(span), 1 / span, np.ones_like(span)], axis=1)  # (m, 3)
        feat = ((f_ref - dop) @ _FEATURES.T) * scale
        feat_jac = np.einsum("fr,mrx->mfx", _FEATURES, grad) * scale[..., None]  # d feature / d pos, negated
        feat_grad = np.linalg.norm(feat_jac, axis=-1)
        feat_rate = np.abs(rate @ _FEATURES.T) * scale
        feat_sigma = np.array([tr.feat_sigma for tr in self.tracks])[k]
        drift = o["clock_drift_max_hz_per_s"]
        t_mid = t_ref[:, 1]
        extra = np.stack([o["sat_offset_max_hz"] + drift * np.abs(t_mid - self.t_c), np.full_like(span, drift),
                          np.zeros_like(span)], axis=1)
        if self.moving:  # the receiver's own velocity (3 sigma) moves each feature by up to k v x the LOS change
            v3 = 3 * self.k * o["rx_speed_sigma_mps"]
            turn = np.minimum(2.0, _SAT_RATE_MAX_RAD_PER_S * span)
            extra = extra + v3 * np.stack([np.ones_like(span), turn / span, turn], axis=1)
        tol_other = dt_max * feat_rate + 4 * feat_sigma + extra + o["model_sigma_hz"] * 3
        tol = reach * feat_grad + tol_other
        # Sigma of the features for the cell's linearised fit: the non-position tolerances (~2 sigma)
        # and the curvature of the Doppler across the cell (~ radius^2 / range, range >= 550 km, over 2 sigma).
        sig_fit = 0.5 * tol_other + ((radius_m / 3e5) * radius_m + 0.5 * o["cross_track_max_m"]) * feat_grad
        b_max = o["clock_search_hz"]
        ok = (np.abs(feat[:, 1]) <= tol[:, 1]) & (np.abs(feat[:, 2]) <= tol[:, 2]) & \
             (np.abs(feat[:, 0]) <= b_max + tol[:, 0])
        c, k, s, feat, tol = c[ok], k[ok], s[ok], feat[ok], tol[ok]
        feat_jac, sig_fit, t_mid = feat_jac[ok], sig_fit[ok], t_mid[ok]
        # Clock vote on bins: each pair covers [offset - tol, offset + tol].
        width = max(50.0, 2 * b_max / 400)
        n_bins = int(np.ceil(2 * b_max / width)) + 1
        lo = np.clip(np.floor((feat[:, 0] - tol[:, 0] + b_max) / width).astype(int), 0, n_bins)
        hi = np.clip(np.floor((feat[:, 0] + tol[:, 0] + b_max) / width).astype(int) + 1, 0, n_bins)
        diff = np.zeros((n_cells, n_tr, n_bins + 1), np.int32)
        np.add.at(diff, (c, k, lo), 1)
        np.add.at(diff, (c, k, hi), -1)
        votes = (np.cumsum(diff, axis=2)[..., :n_bins] > 0).sum(axis=1)  # (cells, bins)
        best = votes.max(axis=1)
        start = np.argmax(votes == best[:, None], axis=1)
        idx = np.arange(n_bins)
        end = np.where((idx >= start[:, None]) & (votes < best[:, None]), idx, n_bins).min(axis=1)
        clock = -b_max + width * 0.5 * (start + end)
        # Cost of each pair at its cell's clock; best pair per (cell, track).
        d_off = (feat[:, 0] - clock[c]) / (tol[:, 0] + 0.5 * width * (end - start)[c])
        cost2 = d_off**2 + (feat[:, 1] / tol[:, 1]) ** 2 + (feat[:, 2] / tol[:, 2]) ** 2
        agree = np.abs(d_off) <= 1.0
        sel = np.flatnonzero(agree)
        return self._linear_fit(cells, radius_m, c[sel], k[sel], s[sel], feat[sel], feat_jac[sel], sig_fit[sel],
                                t_mid[sel], clock, cost2[sel])

    def _linear_fit(self, cells, radius_m, c, k, s, feat, feat_jac, sig, t_mid, clock, cost0):
        """Each cell's position offset (east, north, up), clock and drift fitted to its pairs' features (linearised).

        Every track starts with its pair of least ``cost0``; after each fit, each track takes the pair
        its cell's fit explains best, and tracks no pair of which is explained are left out.

        Returns
        -------
        count, chi2, assign, clock, moved
            As :meth:`vote`.
        """
        o = self.o
        n_cells, n_tr = len(cells), len(self.tracks)
        lat, lon, _ = ecef_to_geodetic(cells)
        enu = C_e_n(lat, lon)  # (n_cells, 3, 3)
        A = np.zeros((len(c), 3, 5))
        A[:, :, :3] = np.einsum("mfx,mxy->mfy", feat_jac, enu[c])
        A[:, 0, 3] = 1.0
        A[:, 0, 4] = t_mid - self.t_c
        A[:, 1, 4] = 1.0
        w = 1.0 / sig**2
        prior = np.array([radius_m, radius_m, o["alt_tol_m"], o["clock_search_hz"],
                          o["clock_drift_max_hz_per_s"]]) ** -2.0
        zero = np.zeros(n_cells)
        x0 = np.stack([zero, zero, zero, clock, zero], axis=1)
        key = c * n_tr + k
        pair_cost = cost0
        inlier_pair = np.ones(len(c), bool)
        for _ in range(3):
            order = np.lexsort((pair_cost, key))
            chosen = order[np.unique(key[order], return_index=True)[1]]
            chosen = chosen[inlier_pair[chosen]]
            N = np.tile(np.diag(prior), (n_cells, 1, 1))
            np.add.at(N, c[chosen], np.einsum("mfi,mf,mfj->mij", A[chosen], w[chosen], A[chosen]))
            rhs = prior * x0
            np.add.at(rhs, c[chosen], np.einsum("mfi,mf,mf->mi", A[chosen], w[chosen], feat[chosen]))
            x = np.linalg.solve(N, rhs[..., None])[..., 0]
            res = feat - np.einsum("mfi,mi->mf", A, x[c])
            pair_cost = np.sum(w * res**2, axis=1)
            inlier_pair = pair_cost <= _TRACK_CHI2_GATE
        order = np.lexsort((pair_cost, key))
        chosen = order[np.unique(key[order], return_index=True)[1]]
        chosen = chosen[inlier_pair[chosen]]
        assign = np.full(n_cells * n_tr, -1)
        assign[key[chosen]] = s[chosen]
        chi2 = np.bincount(c[chosen], pair_cost[chosen], n_cells) + np.sum(prior * (x - x0) ** 2, axis=1)
        d_en = x[:, :2]
        norm = np.linalg.norm(d_en, axis=1, keepdims=True)
        d_en = d_en * np.minimum(1.0, 1.5 * radius_m / np.maximum(norm, 1e-9))
        moved = cells + np.einsum("cxy,cy->cx", enu[:, :, :2], d_en)
        lat2, lon2, _ = ecef_to_geodetic(moved)
        assign = assign.reshape(n_cells, n_tr)
        return (assign >= 0).sum(axis=1), chi2, assign, x[:, 3], geodetic_to_ecef(lat2, lon2, o["alt_m"])

    def search_cells(self, cells, spacing_m, keep):
        """Vote, keep the best cells, split them 3 x 3, until the spacing is ~1 km.

        Returns
        -------
        list of (cell_ecef_m, assign, clock_hz), best first.
        """
        alt = self.o["alt_m"]
        radius = spacing_m / np.sqrt(2)
        while True:
            count, cost, assign, clock, moved = self.vote(cells, radius)
            # A track the cell does not explain costs as much as the worst one it explains: junk
            # tracks (spurious, or from satellites missing in the snapshot) then cannot pull the
            # search to cells where they find chance partners.
            order = np.argsort(cost + _TRACK_CHI2_GATE * (len(self.tracks) - count), kind="stable")
            top = order[:keep]
            if spacing_m <= self.o["final_spacing_m"]:
                return [(moved[i], assign[i], clock[i]) for i in top[: self.o["n_final"]]]
            spacing_m /= 3
            radius = spacing_m / np.sqrt(2)
            offsets = spacing_m * np.array([(e, n) for e in (-1, 0, 1) for n in (-1, 0, 1)], float)
            cells = _grid_around(moved[top], offsets, alt)

    # Joint least squares -------------------------------------------------

    def _stack(self, track_ids):
        rows = [(k, self.tracks[k].sample) for k in track_ids]
        t = np.concatenate([self.tracks[k].t_s[i] for k, i in rows])
        f = np.concatenate([self.tracks[k].doppler_hz[i] for k, i in rows])
        sig = np.concatenate([self.tracks[k].sigma_hz[i] for k, i in rows])
        which = np.concatenate([np.full(len(i), j) for j, (_, i) in enumerate(rows)])
        return t, f, np.sqrt(sig**2 + self.o["model_sigma_hz"] ** 2), which

    def solve(self, pos0, assign, clock0, prior_sigma_m):
        """Position, clock and per-satellite offsets on one assignment.

        Returns
        -------
        dict with pos, cov, clock, drift, nrms per track (NaN when dropped), used tracks.
        """
        used = [k for k in range(len(self.tracks)) if assign[k] >= 0]
        lat0, lon0, _ = ecef_to_geodetic(pos0)
        C = C_e_n(lat0, lon0)
        up = C[:, 2]
        while len(used) >= 1:
            sol = self._gauss_newton(pos0, assign, used, clock0, prior_sigma_m, C, up)
            if sol is None:
                return None
            worst = int(np.argmax(sol["nrms_used"]))
            if sol["nrms_used"][worst] <= self.o["track_gate"] or len(used) <= 2:
                return sol
            used = used[:worst] + used[worst + 1:]
        return None

    def _gauss_newton(self, pos0, assign, used, clock0, prior_sigma_m, C, up):
        o = self.o
        t, f, sig, which = self._stack(used)
        sats = np.array([assign[k] for k in used])
        m = len(used)
        sat = sats[which]
        sig_c = o["sat_offset_sigma_hz"]
        sig_tau = o["along_track_sigma_m"] / _SPEED_SV_MPS
        n_vel = 3 if self.moving else 0
        x = np.zeros(5 + 2 * m + n_vel)  # dpos(3), clock, drift, c_j, tau_j[, vel(3)]
        x[3] = clock0
        dt = t - self.t_c
        for _ in range(10):
            vel_rx = x[5 + 2 * m:] if n_vel else np.zeros(3)
            pos = pos0 + x[:3] + dt[:, None] * vel_rx
            tau = x[5 + m:5 + 2 * m][which]
            p, v = self.eph.state_received(sat, t + tau, pos)
            dop, grad, u = _doppler(p, v - vel_rx, pos, self.k, los=True)
            pa, va = self.eph.state(sat, t + tau + 0.5)
            pb, vb = self.eph.state(sat, t + tau - 0.5)
            rate = _doppler(pa, va, pos, self.k)[0] - _doppler(pb, vb, pos, self.k)[0]
            model = dop + x[3] + x[4] * dt + x[5:5 + m][which]
            res = (f - model) / sig
            J = np.zeros((len(t), len(x)))
            J[:, :3] = grad
            J[:, 3] = 1
            J[:, 4] = dt
            J[np.arange(len(t)), 5 + which] = 1
            J[np.arange(len(t)), 5 + m + which] = rate
            if n_vel:
                J[:, 5 + 2 * m:] = self.k * u + grad * dt[:, None]
            J /= sig[:, None]
            # Priors: satellite offsets and time offsets, horizontal position, height[, velocity].
            axes = [(0, C[:, 0], prior_sigma_m), (0, C[:, 1], prior_sigma_m), (0, up, o["alt_sigma_m"])]
            if n_vel:
                axes += [(5 + 2 * m, C[:, 0], o["rx_speed_sigma_mps"]), (5 + 2 * m, C[:, 1], o["rx_speed_sigma_mps"]),
                         (5 + 2 * m, up, o["rx_climb_sigma_mps"])]
            P = np.zeros((2 * m + len(axes), len(x)))
            pr = np.zeros(len(P))
            P[np.arange(m), 5 + np.arange(m)] = 1 / sig_c
            pr[:m] = -x[5:5 + m] / sig_c
            P[m + np.arange(m), 5 + m + np.arange(m)] = 1 / sig_tau
            pr[m:2 * m] = -x[5 + m:5 + 2 * m] / sig_tau
            for r, (i0, axis, s) in enumerate(axes):
                P[2 * m + r, i0:i0 + 3] = axis / s
                pr[2 * m + r] = -(axis @ x[i0:i0 + 3]) / s
            A = np.vstack([J, P])
            y = np.concatenate([res, pr])
            dx = np.linalg.solve(A.T @ A, A.T @ y)
            x += dx
            if np.linalg.norm(dx[:3]) < 0.05 and abs(dx[3]) < 0.01:
                break
        if not np.all(np.isfinite(x)):
            return None
        cov = np.linalg.inv(A.T @ A)
        nrms = np.sqrt(np.bincount(which, res**2, m) / np.bincount(which, minlength=m))
        return {"pos": pos0 + x[:3], "cov": cov[:3, :3], "clock": x[3], "drift": x[4], "used": used,
                "vel": x[5 + 2 * m:] if n_vel else np.zeros(3), "nrms_used": nrms, "chi2": float(res @ res)}

    # Identification ------------------------------------------------------

    def identify(self, sol):
        """Best and runner-up candidate per track at a solution.

        Returns
        -------
        list of dict per track: sat, chi2, rms_hz, margin, runner_up (sat or -1).
        """
        o = self.o
        pos, cov, vel_rx = sol["pos"], sol["cov"], sol["vel"]
        up = pos / np.linalg.norm(pos)
        sin_mask = np.sin(np.radians(o["mask_deg"] - o["id_mask_slack_deg"]))
        out = []
        for tr in self.tracks:
            p_mid, _ = self.eph.state(np.arange(len(self.eph.ok)), tr.t_mid_s)
            los = p_mid - pos
            el_ok = (los @ up) / np.linalg.norm(los, axis=1) >= sin_mask
            cand = np.flatnonzero(el_ok & self.eph.ok)
            # Only the candidates nearest in Doppler at the middle (rate-scaled) can fit; the rest
            # are kHz away and would only add to the cost.
            pos_mid = pos + (tr.t_mid_s - self.t_c) * vel_rx
            pm, vm = self.eph.state(cand, tr.t_mid_s)
            dm = _doppler(pm, vm - vel_rx, pos_mid, self.k)[0]
            pm2, vm2 = self.eph.state(cand, tr.t_mid_s + 1.0)
            slope = np.abs(_doppler(pm2, vm2 - vel_rx, pos_mid + vel_rx, self.k)[0] - dm)
            off = np.abs(tr.f_ref_hz[1] - sol["clock"] - sol["drift"] * (tr.t_mid_s - self.t_c) - dm)
            cand = cand[np.argsort(off / (10.0 + slope * o["along_track_sigma_m"] / _SPEED_SV_MPS))[:_ID_CANDIDATES]]
            idx = tr.sample
            t, f = tr.t_s[idx], tr.doppler_hz[idx]
            sig2 = tr.sigma_hz[idx] ** 2 + o["model_sigma_hz"] ** 2
            base = f - sol["clock"] - sol["drift"] * (t - self.t_c)
            if cand.size == 0:
                out.append(None)
                continue
            sat = cand[:, None]
            tau = np.zeros((len(cand), 1))
            sig_c, sig_tau = o["sat_offset_sigma_hz"], o["along_track_sigma_m"] / _SPEED_SV_MPS
            pos_t = pos + (t - self.t_c)[:, None] * vel_rx
            for _ in range(2):  # the time offset enters non-linearly: re-linearise once
                p, v = self.eph.state_received(sat, t[None, :] + tau, pos_t)
                dop, grad = _doppler(p, v - vel_rx, pos_t, self.k)
                pa, va = self.eph.state(sat, t[None, :] + tau + 0.5)
                pb, vb = self.eph.state(sat, t[None, :] + tau - 0.5)
                rate = _doppler(pa, va, pos_t, self.k)[0] - _doppler(pb, vb, pos_t, self.k)[0]
                # The fix's own uncertainty inflates the sigma, but only up to a cap: a fix too poor
                # to test a candidate must not make every candidate pass.
                var = sig2[None, :] + np.minimum(np.einsum("ntx,xy,nty->nt", grad, cov, grad),
                                                 o["pos_sigma_cap_hz"] ** 2)
                r = base[None, :] - dop
                w = 1 / var
                # Weighted least squares for (c, dtau) with priors c ~ N(0, sig_c), tau ~ N(0, sig_tau).
                a11 = w.sum(1) + 1 / sig_c**2
                a12 = (w * rate).sum(1)
                a22 = (w * rate**2).sum(1) + 1 / sig_tau**2
                b1 = (w * r).sum(1)
                b2 = (w * rate * r).sum(1) - tau[:, 0] / sig_tau**2
                det = a11 * a22 - a12**2
                c_hz = (a22 * b1 - a12 * b2) / det
                dtau = (a11 * b2 - a12 * b1) / det
                tau = tau + dtau[:, None]
            resid = r - c_hz[:, None] - dtau[:, None] * rate
            chi2 = (w * resid**2).sum(1) + (c_hz / sig_c) ** 2 + (tau[:, 0] / sig_tau) ** 2
            chi2 = np.where(np.isfinite(chi2), chi2, np.inf)
            order = np.argsort(chi2)
            best = order[0]
            second = chi2[order[1]] if len(order) > 1 else np.inf
            out.append({"sat": int(cand[best]), "chi2": float(chi2[best]), "n": len(t),
                        "rms_hz": float(np.sqrt(np.mean(resid[best] ** 2))), "margin": float(second - chi2[best]),
                        "runner_up": int(cand[order[1]]) if len(order) > 1 else -1})
        return out

    def accept(self, ids):
        """Sat index per track (-1 when not accepted) from :meth:`identify`'s output."""
        o = self.o
        sat = np.full(len(ids), -1)
        for k, d in enumerate(ids):
            if d is None:
                continue
            limit = chi2_dist.ppf(1 - o["false_alarm"], d["n"])
            if d["chi2"] <= limit and d["margin"] >= o["min_margin"]:
                sat[k] = d["sat"]
        for s in np.unique(sat[sat >= 0]):  # one comb per satellite: the better fit keeps it
            ks = np.flatnonzero(sat == s)
            if len(ks) > 1:
                keep = ks[np.argmin([ids[k]["chi2"] / ids[k]["n"] for k in ks])]
                sat[ks[ks != keep]] = -1
        if (sat >= 0).sum() < o["min_identified"]:  # one or two matches do not prove the fix they rest on
            sat[:] = -1
        return sat


#: Options of :func:`identify_tracks` (``**options``) and their defaults:
#: ``mask_slack_deg`` / ``id_mask_slack_deg`` lower the mask for the search / the identification
#: (the position is not known yet); ``cross_track_max_m``, ``along_track_max_m`` bound the element
#: errors, ``along_track_sigma_m`` is the prior of the fitted time offsets; ``alt_tol_m`` the
#: height error of the cells, ``alt_sigma_m`` its prior in the least squares; ``sat_offset_max_hz``
#: / ``sat_offset_sigma_hz`` bound and weigh the satellites' own offsets;
#: ``clock_drift_max_hz_per_s`` bounds the receiver drift; ``model_sigma_hz`` is added to every
#: track's sigma; ``track_gate`` (normalised RMS) drops a track from the least squares;
#: ``false_alarm`` sets the chi-square acceptance, ``min_margin`` the chi-square lead over the
#: runner-up; ``pos_sigma_cap_hz`` caps the fix-uncertainty inflation; ``min_identified`` is the
#: fewest identities a solution must give; ``final_spacing_m`` ends the cell refinement and
#: ``n_final`` cells go on to the least squares; ``rx_speed_sigma_mps`` > 0 makes the receiver
#: move at a constant velocity estimated in the least squares (horizontal prior sigma; vertical
#: ``rx_climb_sigma_mps``), 0 holds it static.
_DEFAULTS = dict(
    mask_slack_deg=5.0, id_mask_slack_deg=2.0, cross_track_max_m=300.0, alt_tol_m=1000.0,
    along_track_max_m=1500.0, along_track_sigma_m=600.0, sat_offset_max_hz=30.0, sat_offset_sigma_hz=8.0,
    clock_drift_max_hz_per_s=5.0, model_sigma_hz=1.0, alt_sigma_m=300.0, track_gate=4.0, false_alarm=1e-4,
    min_margin=25.0, final_spacing_m=1500.0, n_final=3, pos_sigma_cap_hz=3.0, min_identified=3,
    rx_speed_sigma_mps=0.0, rx_climb_sigma_mps=2.0,
)


def identify_tracks(tracks, constellation, *, init_pos_ecef_m=None, mask_deg=10.0, carrier_hz=STARLINK_PILOT_HZ,
                    clock_search_hz=25e3, prior_radius_m=150e3, alt_m=None, global_spacing_m=150e3,
                    keep_cells=None, **options):
    """Identify Doppler tracks against element sets; sets ``track.sat_id`` and ``track.match_rms_hz`` in place.

    Parameters
    ----------
    tracks : list of Track
        ``time_utc``, ``doppler_hz`` and ``sigma_hz`` are used.
    constellation : Constellation
        Candidates (e.g. a 10,000-satellite Starlink snapshot).
    init_pos_ecef_m : array_like, (3,), optional
        Prior receiver position, within ``prior_radius_m``; None: global search.
    mask_deg : float
        Elevation mask of the candidates.
    carrier_hz : float
        Carrier of ``doppler_hz``.
    clock_search_hz : float
        Largest receiver clock offset searched, +-.
    prior_radius_m : float
        Horizontal radius searched round the prior.
    alt_m : float, optional
        Receiver height; default that of the prior, or 0 without one.
    global_spacing_m : float
        First cell spacing of the global search.
    keep_cells : int, optional
        Cells kept per refinement level (default 40 with a prior, 300 without).
    **options
        Tolerances and thresholds; see ``_DEFAULTS`` in this module.

    Returns
    -------
    Identification
        Also written into the tracks: ``sat_id`` (None when unidentified) and
        ``match_rms_hz`` (None when unidentified).

    Notes
    -----
    With a prior: ~1 s for 5-8 tracks against 10,138 satellites. Without:
    the whole Earth on ~23,000 cells of 150 km first, ~1 min (see
    ``tools/bench_identify.py``).
    """
    start = time.perf_counter()
    unknown = set(options) - set(_DEFAULTS)
    if unknown:
        raise InputError(f"identify_tracks: unknown option(s) {', '.join(sorted(unknown))}")
    if not clock_search_hz > 0:
        raise InputError(f"clock_search_hz={clock_search_hz!r}: expected a positive number")
    opts = {**_DEFAULTS, **options, "mask_deg": float(mask_deg), "clock_search_hz": float(clock_search_hz)}
    n_tr = len(tracks)
    nan3 = np.full(3, np.nan)
    t_all = np.concatenate([np.asarray(tr.time_utc, "datetime64[ns]") for tr in tracks]) if tracks else None
    t0 = t_all.min() if tracks else np.datetime64("NaT", "ns")
    prepared = [_prepare(tr, t0) for tr in tracks]
    live = [k for k, p in enumerate(prepared) if p is not None]
    result = Identification([None] * n_tr, np.full(n_tr, np.nan), np.full(n_tr, np.nan), [None] * n_tr, nan3,
                            np.full((3, 3), np.nan), np.nan, np.nan, t0, 0, 0.0)
    if not live:
        result.elapsed_s = time.perf_counter() - start
        return _apply(tracks, result)
    eph = _Ephemeris(constellation, t0, float((t_all.max() - t0) / np.timedelta64(1, "s")))
    if init_pos_ecef_m is not None:
        prior = np.asarray(init_pos_ecef_m, float).reshape(3)
        opts["alt_m"] = float(ecef_to_geodetic(prior)[2]) if alt_m is None else float(alt_m)
    else:
        opts["alt_m"] = 0.0 if alt_m is None else float(alt_m)
    region = None if init_pos_ecef_m is None else (prior, 1.5 * prior_radius_m)
    search = _Search([prepared[k] for k in live], eph, float(carrier_hz) / C_MPS, opts, region)
    if init_pos_ecef_m is not None:
        spacing = prior_radius_m / 5
        n = int(np.ceil(prior_radius_m / spacing))
        grid = spacing * np.array([(e, m) for e in range(-n, n + 1) for m in range(-n, n + 1)], float)
        grid = grid[np.hypot(grid[:, 0], grid[:, 1]) <= prior_radius_m + spacing / 2]
        cells = _grid_around(prior[None, :], grid, opts["alt_m"])
        finals = search.search_cells(cells, spacing, keep_cells or 40)
        prior_sigma = prior_radius_m
    else:
        cells = _fibonacci_cells(global_spacing_m, opts["alt_m"])
        finals = search.search_cells(cells, global_spacing_m * 1.1, keep_cells or 300)
        prior_sigma = 20e3
    best = None
    for cell, assign, clock in finals:
        sol = search.solve(cell, assign, clock, prior_sigma)
        if sol is None:
            continue
        for _ in range(2):  # identify, re-solve on the accepted identities, identify again
            ids = search.identify(sol)
            sat = search.accept(ids)
            if (sat >= 0).sum() < 2:
                break
            again = search.solve(sol["pos"], sat, sol["clock"], prior_sigma)
            if again is None:
                break
            sol = again
        score = ((sat >= 0).sum(), -sum(ids[k]["chi2"] for k in np.flatnonzero(sat >= 0)))
        if best is None or score > best[0]:
            best = (score, sol, ids, sat)
    result.n_candidates = int(eph.ok.sum())
    if best is not None:
        _, sol, ids, sat = best
        result.pos_ecef_m, result.pos_cov_m2 = sol["pos"], sol["cov"]
        t_c = search.t_c
        result.clock_offset_hz, result.clock_drift_hz_per_s = float(sol["clock"]), float(sol["drift"])
        result.t_ref_utc = t0 + np.timedelta64(int(round(t_c * 1e9)), "ns")
        for j, k in enumerate(live):
            d = ids[j]
            if d is None:
                continue
            result.margin[k] = d["margin"]
            result.runner_up_id[k] = str(constellation.sat_ids[d["runner_up"]]) if d["runner_up"] >= 0 else None
            if sat[j] >= 0:
                result.sat_id[k] = str(constellation.sat_ids[sat[j]])
                result.match_rms_hz[k] = d["rms_hz"]
    result.elapsed_s = time.perf_counter() - start
    return _apply(tracks, result)


def _apply(tracks, result):
    for tr, sid, rms in zip(tracks, result.sat_id, result.match_rms_hz):
        tr.sat_id = sid
        tr.match_rms_hz = None if sid is None else float(rms)
    return result
