"""Benchmark of track identification on the real 10,138-satellite Starlink snapshot.

Random sites (|lat| <= 55 deg) and times (seeded); 5-8 satellites above 15 deg
make tracks of random length (3 s or 5 captures up to the whole recording), continuous (0.1 s blocks
over 60 s) or snapshot (one 20 ms capture per second for 150 s), with a
receiver clock offset up to +-20 kHz and drift, per-satellite offsets of
0-5 Hz, along-track element errors up to +-1 km and noise of 0.05-1 Hz.
Optionally (--extras) a spurious track is added and one satellite is
removed from the snapshot: both must come back unidentified.

Baseline for the run time: exact SGP4 (``sv_states_from_tle``, light time)
of every candidate at every sample time of the tracks, the cost of the
predicted curves without the interpolated grid; printed as a ratio.

Usage: python tools/bench_identify.py [--cases N] [--seed S] [--global] [--extras]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from leosop.frames import C_e_n, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.positioning.measurements import sv_states_from_tle
from leosop.replay.identify import identify_tracks
from leosop.replay.simtracks import simulate_track, spurious_track, visible_indices

SNAPSHOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "tle" / "starlink_3le_2026-04-08_Bochika.txt"


def make_case(const, rng, continuous, extras):
    """Tracks, truth ids (None for extras), the snapshot to search, site and a prior 100 km off."""
    lat, lon = np.radians(rng.uniform(-55, 55)), np.radians(rng.uniform(-180, 180))
    rx = geodetic_to_ecef(lat, lon, rng.uniform(0, 1500))
    start = np.datetime64("2026-04-08T00:00:00", "ns") + np.timedelta64(int(rng.uniform(0, 86400)), "s")
    step_s, n = (0.1, 600) if continuous else (1.0, 150)
    times = start + (np.arange(n) * step_s * 1e9).astype("timedelta64[ns]")
    vis = visible_indices(const, rx, times[[0, n // 2, -1]], 15.0)
    pick = rng.choice(vis, min(len(vis), rng.integers(5, 9)), replace=False)
    clock, drift = rng.uniform(-20e3, 20e3), rng.uniform(-1, 1)
    tracks = []
    for s in pick:
        length = rng.integers(30 if continuous else 5, n + 1)  # >= 3 s / 5 captures
        first = rng.integers(0, n - length + 1)
        sub = times[first:first + length]
        tr = simulate_track(const, s, rx, sub, rng, clock_hz=clock + drift * (sub[0] - start) / np.timedelta64(1, "s"),
                            clock_drift_hz_per_s=drift, sat_offset_hz=rng.uniform(0, 5),
                            along_track_m=rng.uniform(-1000, 1000), sigma_hz=rng.uniform(0.05, 1.0))
        tracks.append(tr)
    truth = [str(const.sat_ids[s]) for s in pick]
    snapshot = const
    if extras:
        snapshot = const.subset(const.sat_ids != truth[0])
        truth[0] = None
        tracks.append(spurious_track(times, rng))
        truth.append(None)
    az = rng.uniform(0, 2 * np.pi)
    init = rx + C_e_n(lat, lon) @ np.array([100e3 * np.sin(az), 100e3 * np.cos(az), 0.0])
    return tracks, truth, snapshot, rx, init


def baseline_s(const, tracks):
    """Exact SGP4 with light time of every satellite at every sample time (one track's times)."""
    t = np.concatenate([tr.time_utc for tr in tracks])
    t = np.unique(t)[:: max(1, len(np.unique(t)) // 20)]  # 20 instants, scaled up below
    start = time.perf_counter()
    ids = np.repeat(const.sat_ids, len(t))
    sv_states_from_tle(const, ids, np.tile(t, len(const)))
    return (time.perf_counter() - start) * sum(len(tr) for tr in tracks) / len(t)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=6, help="cases per recording kind (default %(default)s)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--global", dest="global_search", action="store_true", help="also without --init")
    ap.add_argument("--extras", action="store_true", help="add a spurious track and a missing satellite")
    ap.add_argument("--baseline", action="store_true", help="time the exact-SGP4 baseline once")
    args = ap.parse_args(argv)
    if not SNAPSHOT.is_file():
        print(f"{SNAPSHOT} not found", file=sys.stderr)
        return 1
    const = load_constellation(SNAPSHOT)
    rng = np.random.default_rng(args.seed)
    modes = [("init", True)] + ([("global", False)] if args.global_search else [])
    for kind in ("continuous", "snapshot"):
        cases = [make_case(const, rng, kind == "continuous", args.extras) for _ in range(args.cases)]
        median_s = {}
        for mode, with_init in modes:
            ok = wrong = missed = none_ok = 0
            elapsed, pos_err = [], []
            for tracks, truth, snapshot, rx, init in cases:
                res = identify_tracks(tracks, snapshot, init_pos_ecef_m=init if with_init else None, mask_deg=10.0)
                elapsed.append(res.elapsed_s)
                pos_err.append(np.linalg.norm(res.pos_ecef_m - rx))
                for got, want in zip(res.sat_id, truth):
                    ok += got is not None and got == want
                    none_ok += got is None and want is None
                    wrong += got is not None and got != want
                    missed += got is None and want is not None
            print(f"{kind:10s} {mode:6s}: {len(cases)} cases, {sum(len(c[0]) for c in cases)} tracks: "
                  f"identified {ok}, wrong {wrong}, unidentified {missed}, correctly None {none_ok}; "
                  f"time median {np.median(elapsed):.2f} s max {np.max(elapsed):.2f} s; "
                  f"position error median {np.nanmedian(pos_err):.0f} m")
            median_s[mode] = np.median(elapsed)
        if args.baseline:
            base = baseline_s(const, cases[0][0])
            print(f"{kind:10s} baseline exact SGP4 of all candidates at all samples: {base:.1f} s "
                  f"(ratio to the median identification with --init {base / median_s['init']:.0f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
