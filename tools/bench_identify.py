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

With ``--replay`` it times instead ``leosop replay`` of the bundled Xi'an recording with and without
``--init`` (issue 24: the global search), this tree against ``--baseline-ref`` (default ``main``, exported
with ``git archive`` into a temporary folder), each in a child process of its own: CPU time (user +
system, ``os.wait4``, of the child, robust to other load on the machine), wall time, their ratio, and whether the two
wrote the same JSON byte for byte.

Usage: python tools/bench_identify.py [--cases N] [--seed S] [--global] [--extras]
       python tools/bench_identify.py --replay [--baseline-ref main]
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from baseline_tree import export_package

from leosop.frames import C_e_n, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.positioning.measurements import sv_states_from_tle
from leosop.replay.identify import identify_tracks
from leosop.replay.simtracks import simulate_track, spurious_track, visible_indices

REPO = Path(__file__).resolve().parents[1]
SNAPSHOT = REPO.parent / "shared" / "data" / "tle" / "starlink_3le_2026-04-08_Bochika.txt"
RECORDING = REPO / "signals" / "starlink_xian_snapshots.sigmf-meta"
REPLAY_INIT = "34.98,109.71,0"  # ~70 km from the fix, as in the README


def run_replay(code_dir, extra):
    """CPU time [s], wall time [s] and stdout of ``leosop replay RECORDING --static --json EXTRA`` from ``code_dir``."""
    env = dict(os.environ, PYTHONPATH=str(code_dir))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "leosop", "replay", str(RECORDING), "--static", "--json", *extra],
                          env=env, capture_output=True, cwd=code_dir)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"{code_dir}: leosop replay failed: {proc.stderr.decode().strip()[-500:]}")
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, wall, proc.stdout


def bench_replay(ref):
    """``leosop replay`` with and without a prior, this tree against ``ref``: times, ratios, same JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        export_package(ref, base)
        print(f"{'replay':>12} {'this cpu s':>10} {'wall s':>7} | {ref + ' cpu s':>10} {'wall s':>7} | "
              f"{'cpu ratio':>9} | same JSON")
        for name, extra in (("no prior", []), ("--init", ["--init", REPLAY_INIT])):
            cpu_new, wall_new, out_new = run_replay(REPO, extra)
            cpu_old, wall_old, out_old = run_replay(base, extra)
            print(f"{name:>12} {cpu_new:>10.1f} {wall_new:>7.1f} | {cpu_old:>10.1f} {wall_old:>7.1f} | "
                  f"{cpu_old / cpu_new:>8.2f}x | {out_new == out_old}", flush=True)


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
    ap.add_argument("--replay", action="store_true", help="leosop replay of the bundled recording against the code "
                    "of --baseline-ref, with and without a prior")
    ap.add_argument("--baseline-ref", default="main", help="git ref of the code compared with --replay")
    args = ap.parse_args(argv)
    if args.replay:
        bench_replay(args.baseline_ref)
        return 0
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
