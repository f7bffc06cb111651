"""Tracker: detections of several satellites joined into one track each.

Doppler curves come from SGP4 (the bundled constellation seen from Xi'an), so
the rates and their changes are those of real LEO passes.
"""

import numpy as np

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.replay.tracks import Detections, Tracker
from leosop.signal.channel import SiteChannel, site_geometry
from leosop.apps.scenarios import XIAN_BAOJI


def _passes(n_sats, duration_s, step_s):
    """Doppler and rate of the n_sats highest satellites, (n_sats, n_t), on a step_s grid."""
    from leosop.frames import azimuth_elevation_range
    from leosop.orbits.propagate import state_ecef

    const = load_constellation()
    pos_rx = geodetic_to_ecef(np.radians(34.342), np.radians(108.94), 400.0)
    start = XIAN_BAOJI.start_utc
    pos, _, _ = state_ecef(const, np.array([start]))
    _, elev, _ = azimuth_elevation_range(pos[:, 0], pos_rx)
    pick = const.subset(np.argsort(-np.nan_to_num(elev, nan=-9))[:n_sats])
    t_nodes, range_m, _ = site_geometry(pick, pos_rx, start, duration_s)
    channel = SiteChannel(t_nodes, range_m, 2.5e6, 45.0, 0.0)
    t = np.arange(0.0, duration_s + 1e-9, step_s)
    return t, channel.doppler_hz(t), channel.doppler_rate_hz_per_s(t), start


def test_snapshots_with_dropouts_and_clutter_give_one_track_per_satellite():
    t, dop, rate, start = _passes(7, 150.0, 1.0)
    rng = np.random.default_rng(3)
    tracker = Tracker(max_gap_s=10.0, min_blocks=3)  # this seed misses one satellite 5 s in a row
    owner = []  # per block, the satellite index of each detection (-1 clutter)
    for k, t_k in enumerate(t):
        seen = rng.random(7) > 0.2  # a fifth of the snapshots miss each satellite
        idx = np.flatnonzero(seen)
        # Noise of a 20 ms snapshot at ~45 dB-Hz per tone (comb CRLB with unknown
        # rate): ~10 Hz on the Doppler, ~50 Hz/s on the rate.
        f = dop[idx, k] + rng.normal(0, 10.0, idx.size)
        r = rate[idx, k] + rng.normal(0, 50.0, idx.size)
        clutter = rng.uniform(-3e5, 3e5, 1)  # one false alarm per block, never repeated
        order = rng.permutation(idx.size + 1)
        f_all = np.concatenate([f, clutter])[order]
        r_all = np.concatenate([r, [0.0]])[order]
        owner.append(np.concatenate([idx, [-1]])[order])
        det = Detections(f_all, r_all, np.full(f_all.size, 45.0), np.full(f_all.size, 10.0))
        tracker.update(t_k, start + np.timedelta64(int(t_k * 1e9), "ns"), det)
    tracks = tracker.finish()
    assert len(tracks) == 7
    for tr in tracks:
        # every detection of a track belongs to one satellite: compare with the truth curves
        k = np.searchsorted(t, tr.t_s)
        sat = np.argmin(np.abs(dop[:, k] - tr.doppler_hz[None, :]).sum(axis=1))
        assert np.all(np.abs(tr.doppler_hz - dop[sat, k]) < 60.0)  # 6 sigma of the 10 Hz noise
        n_true = sum(np.sum(o == sat) for o in owner)
        # Only detections of a tentative start can be lost (gaps > 2.5 s before it is confirmed).
        assert n_true - 5 <= len(tr) <= n_true


def test_a_gap_longer_than_max_gap_splits_the_track():
    t, dop, rate, start = _passes(1, 40.0, 1.0)
    tracker = Tracker(max_gap_s=5.0, min_blocks=3)
    for k, t_k in enumerate(t):
        if 10 <= t_k < 20:  # 10 s outage
            continue
        det = Detections(dop[:, k], rate[:, k], np.array([45.0]), np.array([1.0]))
        tracker.update(t_k, start + np.timedelta64(int(t_k * 1e9), "ns"), det)
    tracks = tracker.finish()
    assert [len(tr) for tr in tracks] == [10, 21]


def test_remove_outliers_takes_exactly_the_injected_sidelobe_locks():
    from leosop.replay.tracks import Track, remove_outliers

    t, dop, rate, start = _passes(3, 150.0, 1.0)
    rng = np.random.default_rng(11)
    for s in range(3):  # three real curves, incl. the highest pass's fast rate change
        f = dop[s] + rng.normal(0, 0.5, t.size)
        bad = rng.choice(t.size, 6, replace=False)
        bad[:2] = [0, t.size - 1]  # ends too, where the local cubic extrapolates
        f[bad] += rng.choice([-1, 1], 6) * rng.uniform(40, 150, 6)  # 1-3 bins of a 20 ms block
        tr = Track(t, start + (t * 1e9).astype("timedelta64[ns]"), f, rate[s], np.full(t.size, 45.0),
                   np.full(t.size, 0.5))
        clean = remove_outliers(tr)
        assert set(np.round(clean.t_s)) == set(np.round(np.delete(t, bad)))


def test_join_fragments_rejoins_a_comb_lost_for_a_while_and_keeps_others_apart():
    from leosop.replay.tracks import Track, join_fragments

    t, dop, rate, start = _passes(3, 60.0, 0.5)
    rng = np.random.default_rng(5)

    def piece(s, lo, hi):
        k = (t >= lo) & (t < hi)
        f = dop[s, k] + rng.normal(0, 0.1, k.sum())
        return Track(t[k], start + (t[k] * 1e9).astype("timedelta64[ns]"), f, rate[s, k],
                     np.full(k.sum(), 45.0), np.full(k.sum(), 0.1))

    # Satellite 0 in three pieces (gaps of 3 s and 6 s), satellites 1 and 2 whole.
    pieces = [piece(0, 0, 10), piece(0, 13, 30), piece(0, 36, 60), piece(1, 0, 60), piece(2, 5, 50)]
    joined = join_fragments(pieces, max_gap_s=10.0)
    assert sorted(len(tr) for tr in joined) == sorted([len(pieces[0]) + len(pieces[1]) + len(pieces[2]),
                                                       len(pieces[3]), len(pieces[4])])
    for tr in joined:
        k = np.searchsorted(t, tr.t_s)
        assert np.min(np.max(np.abs(dop[:, k] - tr.doppler_hz), axis=1)) < 1.0  # one satellite each
