"""Stage 1 of the identification: the cell vote (see :mod:`leosop.replay.identify`).

The receiver position is searched on cells; every (cell, track, candidate)
triple whose residual slope and curvature fit within first-order
tolerances votes for the common receiver offsets it admits; a cell's score
is the number of tracks agreeing on one offset, refined by a linearised fit
of position offset, receiver offset and drift. The best cells are split
3 x 3 and voted again.
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..constants import OMEGA_E_RAD_PER_S, WGS84_A_M
from ..frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef
from .ephemeris import RATE_STEP_S, SPEED_SV_MPS, doppler_hz, doppler_model, dot3
from .features import FEATURES

__all__ = ["CellSearch", "fibonacci_cells", "grid_around", "TRACK_CHI2_GATE"]

#: Growth of the first-order tolerances for the neglected curvature of the
#: Doppler in position across a cell (cells << range).
_LINEAR_MARGIN = 1.3
#: Largest light time, bounding its effect in the cell vote [s].
_LIGHT_TIME_MAX_S = 0.012
#: Largest Doppler rate of a LEO satellite at Ku band, a bound for the screen [Hz/s].
_RATE_MAX_HZ_PER_S = 5e3
#: Largest angular rate of a line of sight to a LEO satellite [rad/s] (7.6 km/s at 550 km overhead).
_SAT_RATE_MAX_RAD_PER_S = 0.014
#: Bound of a satellite's acceleration in the ECEF frame [m/s^2]: gravity <= 9.9 above the surface,
#: Coriolis 2 omega v <= 1.2 at 8 km/s, centrifugal < 0.04; twice that for the Hermite interpolant.
_SAT_ACCEL_MAX_MPS2 = 20.0
#: Chi-square (3 features) above which a cell's linearised fit does not count a track.
TRACK_CHI2_GATE = 25.0
#: Cells voted at once, and at most this many (cell, track, satellite) triples (memory bound:
#: ~1 kB of intermediate arrays per triple that passes the first screen).
_CHUNK_CELLS = 400
_MAX_PAIRS = 300_000


def fibonacci_cells(spacing_m, alt_m):
    """Nearly uniform points on the ellipsoid, ~``spacing_m`` apart, (n, 3)."""
    n = int(np.ceil(4 * np.pi * WGS84_A_M**2 / spacing_m**2))
    k = np.arange(n) + 0.5
    lat = np.arcsin(1 - 2 * k / n)
    lon = np.mod(np.pi * (1 + 5**0.5) * k, 2 * np.pi)
    return geodetic_to_ecef(lat, lon, alt_m)


def grid_around(centre_ecef_m, offsets_m, alt_m):
    """Points at horizontal offsets (n, 2) [east, north] of each centre (c, 3), at ``alt_m``: (c * n, 3)."""
    lat, lon, _ = ecef_to_geodetic(centre_ecef_m)
    enu = np.concatenate([offsets_m, np.zeros((len(offsets_m), 1))], axis=1)
    pts = centre_ecef_m[:, None, :] + np.einsum("cij,nj->cni", C_e_n(lat, lon), enu)
    lat2, lon2, _ = ecef_to_geodetic(pts.reshape(-1, 3))
    return geodetic_to_ecef(lat2, lon2, alt_m)



def _speed_turn_max(pos_sv, vel_sv):
    """The satellite's speed bound over +-0.5 s [m/s] and the Earth's turn rate at it, ``omega |r|`` [m/s], (...).

    Per reference state, for :func:`_range_accel_bound`.
    """
    speed_max = np.sqrt(dot3(vel_sv, vel_sv)) + 0.5 * _SAT_ACCEL_MAX_MPS2
    return speed_max, OMEGA_E_RAD_PER_S * np.sqrt(dot3(pos_sv, pos_sv))


def _range_accel_bound(pos_sv, speed_max, turn_max, pos_rx):
    """Bound of |range rate change| over 1 s of the satellite's inertial time offset [m/s], (...).

    The offset moves the satellite's ECEF state along ``w = v + omega x r`` and ``a + omega x v``
    (:mod:`~leosop.replay.ephemeris`), so d(range rate) = ((v . w) - range rate (u . w)) / range
    + u . (a + omega x v) <= |v| |w| / range + |a| + omega |v|, with |v| and the range bounded over
    the +-0.5 s by the acceleration bound (which also covers omega |v| < 0.6 m/s^2); ``speed_max``
    and ``turn_max`` from :func:`_speed_turn_max`.
    """
    los_m = pos_sv - pos_rx
    rng_min = np.maximum(np.sqrt(dot3(los_m, los_m)) - 0.5 * speed_max, 1e-3)
    return speed_max * (speed_max + turn_max) / rng_min + _SAT_ACCEL_MAX_MPS2


def _features_of(x):
    """``FEATURES @ x`` over the reference times, (m, 3 features, 3) from ``x`` (m, 3 times, 3).

    Each feature is the sum of its non-zero terms in the order of the times (``FEATURES`` holds 0, +-1
    and +-0.5: the products are exact and the zero terms add nothing but the sign of a zero), without
    the (m, 3, 3, 3) products of a broadcast.
    """
    out = np.empty_like(x)
    for f, row in enumerate(FEATURES):
        terms = [x[:, r] if w == 1.0 else w * x[:, r] for r, w in enumerate(row) if w != 0.0]
        out[:, f] = terms[0]
        for t in terms[1:]:
            out[:, f] += t
    return out


def _morton_order(cells):
    """Cell indices (n,) along a Z-order curve of latitude and longitude (neighbours mostly adjacent)."""
    u = cells / np.sqrt(dot3(cells, cells))[:, None]
    q_lat = np.clip(((np.arcsin(np.clip(u[:, 2], -1, 1)) / np.pi + 0.5) * 1024).astype(np.int64), 0, 1023)
    q_lon = np.clip(((np.arctan2(u[:, 1], u[:, 0]) / (2 * np.pi) + 0.5) * 1024).astype(np.int64), 0, 1023)
    key = np.zeros(len(cells), np.int64)
    for b in range(10):
        key |= ((q_lat >> b) & 1) << (2 * b + 1) | ((q_lon >> b) & 1) << (2 * b)
    return np.argsort(key, kind="stable")


class CellSearch:
    """The tracks, the ephemeris and the options of one identification, and its cell vote.

    With ``threads`` > 1 the vote's chunks of cells run on that many threads (the same votes; the
    memory of that many chunks at once, up to ~0.3 GB each).
    """

    def __init__(self, tracks, eph, hz_per_mps, opts, region=None, threads=1):
        self.tracks, self.eph, self.k, self.o, self.threads = tracks, eph, hz_per_mps, opts, int(threads)
        self.moving = opts["rx_speed_sigma_mps"] > 0
        self.t_c = float(np.mean([tr.t_mid_s for tr in tracks]))
        sin_m = np.sin(np.radians(opts["mask_deg"] - opts["mask_slack_deg"]))
        cos_m = np.sqrt(1 - sin_m**2)
        n_sats = len(eph.ok)
        t_ref = np.array([tr.t_ref_s for tr in tracks])
        # Unit vectors of the satellites at each track's middle time and their footprint half-angles.
        p, v = eph.state(np.arange(n_sats)[None, :], t_ref[:, None, 1])  # (n_tracks, n_sats, 3)
        # Every satellite's state at each track's middle time and 1 s later, (n_tracks, n_sats, 3) each:
        # the identification's Doppler screen of its candidates (:func:`~leosop.replay.match.match`).
        self.mid_states = (p, v, *eph.state(np.arange(n_sats)[None, :], t_ref[:, None, 1] + 1.0))
        r = np.linalg.norm(p, axis=-1)
        self.unit = p / np.where(r > 0, r, 1.0)[..., None]
        lam = np.arccos(np.clip(WGS84_A_M * cos_m / np.where(eph.ok, r, 1e12), -1, 1)) - np.arcsin(sin_m)
        self.half_angle = np.where(eph.ok, lam, -1.0)
        if region is not None:  # (centre ECEF, radius): satellites that no point of it sees are dropped
            centre, radius_m = region
            cos_sep = self.unit @ (centre / np.linalg.norm(centre))
            self.half_angle[np.arccos(np.clip(cos_sep, -1, 1)) > self.half_angle + radius_m / WGS84_A_M] = -1.0
        # States of the satellites some track may pair with (all but those no point of the region
        # sees) at each track's reference times and with their inertial orbits 0.5 s either side (the
        # Doppler's rate in an element set's time offset), (n_tracks, n_cand, 3 offsets, 3 ref times, 3),
        # indexed through ``local``: memory grows with tracks x candidates, ~50 of a 10,000-satellite
        # snapshot with a prior.
        self.cand_per_track = [np.flatnonzero(h > 0) for h in self.half_angle]
        cand = np.flatnonzero((self.half_angle > 0).any(axis=0))
        self.local = np.full(n_sats, -1)
        self.local[cand] = np.arange(len(cand))
        shift = np.array([0.0, -RATE_STEP_S, RATE_STEP_S])[:, None]  # (3 offsets, 1)
        self.ref_pos, self.ref_vel = eph.state_shifted(cand[None, :, None, None], t_ref[:, None, None, :], shift)
        self.ref_speed_max, self.ref_turn_max = _speed_turn_max(self.ref_pos[:, :, 0], self.ref_vel[:, :, 0])
        # The unshifted states at the middle reference time, contiguous for the vote's first screen.
        self.mid_pos = np.ascontiguousarray(self.ref_pos[:, :, 0, 1])
        self.mid_vel = np.ascontiguousarray(self.ref_vel[:, :, 0, 1])

    def _pairs(self, cells, radius_m):
        """(cell, track, sat) triples with the satellite above the mask from somewhere in the cell, (m, 3).

        Sorted by track, cell, satellite. Only the satellites whose footprint reaches the cap that bounds
        all the cells are tested cell by cell (triangle inequality on the sphere, 1e-6 rad to spare).
        """
        cu = cells / np.sqrt(dot3(cells, cells))[:, None]
        centre = cu.sum(axis=0)
        centre /= max(np.linalg.norm(centre), 1e-300)
        cap = np.arccos(np.clip(np.min(cu @ centre), -1, 1)) + radius_m / WGS84_A_M + 1e-6
        out = []
        for k in range(len(self.tracks)):
            sats = self.cand_per_track[k]
            sats = sats[self.unit[k][sats] @ centre >= np.cos(np.minimum(self.half_angle[k][sats] + cap, np.pi))]
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
        # Cells are voted independently of each other: chunks of neighbours (Morton order) screen
        # their satellites together, and a chunk with too many triples is cut between cells.
        order = _morton_order(cells)
        chunks = [order[a:a + _CHUNK_CELLS] for a in range(0, n_cells, _CHUNK_CELLS)]

        def vote_chunk(chunk):
            pairs = self._pairs(cells[chunk], radius_m)
            per_cell = np.cumsum(np.bincount(pairs[:, 0], minlength=len(chunk)))
            out, lo = [], 0
            while lo < len(chunk):
                hi = max(lo + 1, int(np.searchsorted(per_cell, per_cell[lo - 1] * (lo > 0) + _MAX_PAIRS, "right")))
                sub = pairs[(pairs[:, 0] >= lo) & (pairs[:, 0] < hi)] - [lo, 0, 0]
                out.append((chunk[lo:hi], self._vote_chunk(cells[chunk[lo:hi]], radius_m, sub)))
                lo = hi
            return out

        if self.threads > 1 and len(chunks) > 1:
            # numpy releases the GIL in the chunks' array work; each thread holds one chunk's arrays.
            with ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="leosop-vote") as pool:
                parts = list(pool.map(vote_chunk, chunks))
        else:
            parts = map(vote_chunk, chunks)
        for part in parts:
            for i, (cnt, cst, asg, clk, mv) in part:
                count[i], cost[i], assign[i], clock[i], moved[i] = cnt, cst, asg, clk, mv
        return count, cost, assign, clock, moved

    def _vote_chunk(self, cells, radius_m, pairs):
        o = self.o
        n_cells, n_tr = len(cells), len(self.tracks)
        c, k, s = pairs.T
        # Per track, gathered per triple where needed: reference times and values (n_tracks, 3), spans.
        t_ref = np.array([tr.t_ref_s for tr in self.tracks])
        f_ref = np.array([tr.f_ref_hz for tr in self.tracks])
        span = np.maximum(t_ref[:, 2] - t_ref[:, 0], 1e-3)
        # Cheap screen at the middle time: the offset must fit the clock range.
        reach = _LINEAR_MARGIN * (radius_m + o["cross_track_max_m"] + o["alt_tol_m"])
        dt_max = o["along_track_max_m"] / SPEED_SV_MPS + _LIGHT_TIME_MAX_S
        s_loc = self.local[s]
        dm, gm = doppler_model(self.mid_pos[k, s_loc], self.mid_vel[k, s_loc], cells[c], self.k)
        near = np.abs(f_ref[k, 1] - dm) <= (o["lo_offset_max_hz"] + reach * np.sqrt(dot3(gm, gm))
                                            + dt_max * _RATE_MAX_HZ_PER_S + o["sat_offset_max_hz"]
                                            + (o["lo_drift_max_hz_per_s"] * np.abs(t_ref[:, 1] - self.t_c))[k])
        c, k, s = c[near], k[near], s[near]
        t_ref, f_ref, span = t_ref[k], f_ref[k], span[k]  # (m, 3), (m, 3), (m,)
        pos_rx = cells[c][:, None, :]
        sat = s_loc[near]
        feat_sigma = np.array([tr.feat_sigma for tr in self.tracks])[k]
        drift = o["lo_drift_max_hz_per_s"]
        t_mid = t_ref[:, 1]
        extra = np.stack([o["sat_offset_max_hz"] + drift * np.abs(t_mid - self.t_c), np.full_like(span, drift),
                          np.zeros_like(span)], axis=1)
        if self.moving:  # the receiver's own velocity (3 sigma) moves each feature by up to k v x the LOS change
            v3 = 3 * self.k * o["rx_speed_sigma_mps"]
            turn = np.minimum(2.0, _SAT_RATE_MAX_RAD_PER_S * span)
            extra = extra + v3 * np.stack([np.ones_like(span), turn / span, turn], axis=1)
        # The slope's screen first (most triples fail it): it needs the first and last reference times
        # alone (FEATURES row 1), and is the same arithmetic as its part of the screen below, bit for bit.
        keep = self._slope_screen(k, sat, pos_rx, f_ref, span, reach, dt_max, feat_sigma[:, 1], extra[:, 1])
        c, k, s, t_ref, f_ref, span, pos_rx, sat = c[keep], k[keep], s[keep], t_ref[keep], f_ref[keep], \
            span[keep], pos_rx[keep], sat[keep]
        feat_sigma, t_mid, extra = feat_sigma[keep], t_mid[keep], extra[keep]
        p0, v0 = self.ref_pos[k, sat, 0], self.ref_vel[k, sat, 0]  # (m, 3 ref times, 3)
        dop, grad = doppler_model(p0, v0, pos_rx, self.k)
        scale = np.stack([np.ones_like(span), 1 / span, np.ones_like(span)], axis=1)  # (m, 3)
        feat = ((f_ref - dop) @ FEATURES.T) * scale
        # d feature / d pos, negated: FEATURES @ grad summed over the reference times in order (as einsum).
        feat_jac = _features_of(grad) * scale[..., None]
        feat_grad = np.sqrt(dot3(feat_jac, feat_jac))
        b_max = o["lo_offset_max_hz"]
        # The Doppler rates cost twice the rest: first a screen with a bound of them (most triples fail it).
        rate_max = self.k * _range_accel_bound(p0, self.ref_speed_max[k, sat], self.ref_turn_max[k, sat],
                                               pos_rx)  # (m, 3 ref times)
        tol_max = (reach * feat_grad + dt_max * (rate_max @ np.abs(FEATURES).T) * scale + 4 * feat_sigma + extra
                   + o["model_sigma_hz"] * 3) * (1 + 1e-9)
        maybe = (np.abs(feat[:, 1]) <= tol_max[:, 1]) & (np.abs(feat[:, 2]) <= tol_max[:, 2]) & \
                (np.abs(feat[:, 0]) <= b_max + tol_max[:, 0])
        c, k, s, sat, feat, feat_jac, feat_grad = c[maybe], k[maybe], s[maybe], sat[maybe], feat[maybe], \
            feat_jac[maybe], feat_grad[maybe]
        t_mid, scale, feat_sigma, extra = t_mid[maybe], scale[maybe], feat_sigma[maybe], extra[maybe]
        pos_rx = pos_rx[maybe]
        rate = doppler_hz(self.ref_pos[k, sat, 2], self.ref_vel[k, sat, 2], pos_rx, self.k) - \
            doppler_hz(self.ref_pos[k, sat, 1], self.ref_vel[k, sat, 1], pos_rx, self.k)
        feat_rate = np.abs(rate @ FEATURES.T) * scale
        tol_other = dt_max * feat_rate + 4 * feat_sigma + extra + o["model_sigma_hz"] * 3
        tol = reach * feat_grad + tol_other
        # Sigma of the features for the cell's linearised fit: the non-position tolerances (~2 sigma)
        # and the curvature of the Doppler across the cell (~ radius^2 / range, range >= 550 km, over 2 sigma).
        sig_fit = 0.5 * tol_other + ((radius_m / 3e5) * radius_m + 0.5 * o["cross_track_max_m"]) * feat_grad
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

    def _slope_screen(self, k, sat, pos_rx, f_ref, span, reach, dt_max, slope_sigma, slope_extra):
        """Triples (m,) whose residual slope fits its bound, as the first part of ``maybe`` in
        :meth:`_vote_chunk` computes it, from the states at the first and last reference times alone.

        FEATURES' slope row is (-1, 0, 1): its products are exact and its zero term adds nothing, so
        ``a[:, 2] - a[:, 0]`` is what the product with FEATURES gives; likewise the sums of the
        gradients and of the rate bounds. ``slope_sigma`` and ``slope_extra`` (m,) are the slope's
        columns of the feature sigmas and the extra tolerance.
        """
        o = self.o
        ends = (slice(None), slice(None, None, 2))  # reference times 0 and 2
        p, v = self.ref_pos[k, sat, 0][ends], self.ref_vel[k, sat, 0][ends]  # (m, 2, 3)
        dop, grad = doppler_model(p, v, pos_rx, self.k)
        inv_span = 1 / span
        slope = ((f_ref[:, 2] - dop[:, 1]) - (f_ref[:, 0] - dop[:, 0])) * inv_span
        jac = (grad[:, 1] - grad[:, 0]) * inv_span[:, None]
        rate_max = self.k * _range_accel_bound(p, self.ref_speed_max[k, sat][ends], self.ref_turn_max[k, sat][ends],
                                               pos_rx)  # (m, 2)
        tol = (reach * np.sqrt(dot3(jac, jac)) + dt_max * (rate_max[:, 0] + rate_max[:, 1]) * inv_span
               + 4 * slope_sigma + slope_extra + o["model_sigma_hz"] * 3) * (1 + 1e-9)
        return np.abs(slope) <= tol

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
        prior = np.array([radius_m, radius_m, o["alt_tol_m"], o["lo_offset_max_hz"],
                          o["lo_drift_max_hz_per_s"]]) ** -2.0
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
            inlier_pair = pair_cost <= TRACK_CHI2_GATE
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
            order = np.argsort(cost + TRACK_CHI2_GATE * (len(self.tracks) - count), kind="stable")
            top = order[:keep]
            if spacing_m <= self.o["final_spacing_m"]:
                return [(moved[i], assign[i], clock[i]) for i in top[: self.o["n_final"]]]
            spacing_m /= 3
            radius = spacing_m / np.sqrt(2)
            offsets = spacing_m * np.array([(e, n) for e in (-1, 0, 1) for n in (-1, 0, 1)], float)
            cells = grid_around(moved[top], offsets, alt)

    # Joint least squares -------------------------------------------------
