"""Benchmarks of ``leosop generate``.

``--parts snapshot``: a 10-minute snapshot recording (20 ms every 1 s,
2.5 MS/s, 7 satellites). Times the channel path (geometry, then samples
snapshot by snapshot) beside the baseline of synthesising the whole
continuous stream and keeping only the snapshots, both in this run, on the
first 60 s of the baseline (scaled to 600 s) so that the run stays short;
prints the ratio.

``--parts cli``: whole ``leosop generate`` runs, each in a child process:
the baseline ``--baseline-ref`` (default ``main``, exported with ``git
archive``), this tree with numba blocked (as if not installed:
:func:`~leosop.signal.pilot.comb_baseband` satellite by satellite) and this
tree compiled (:mod:`leosop.signal.combkernels`; numba's cache warmed by a
first run that is not counted), on two recordings: ``snapshot``, the recording of
tools/bench_lo_offset.py (4 MS/s, consumer front end, every satellite above
the horizon, ``--duration-s`` of 20 ms snapshots every second), and
``continuous``, tools/bench_replay.py's (2.5 MS/s, cf32, 7 satellites above
40 deg, ``--continuous-s``). Prints the wall time and the CPU time (user +
system of the child, ``os.wait4``: robust to other load on the machine) of
each, the baseline's CPU over each, and how far each recording is from the
baseline's: the samples (cf32: max |diff| in units of the strongest tone,
beside float32's own spacing there; ci8: the fraction of codes that differ,
by how much) and whether the SigMF metadata (the truth Doppler annotations
and the rest, the data's hash aside) is identical. ``--replay`` replays the
baseline's and the compiled snapshot recordings (static fix, no prior) and
prints the fixes' difference beside their sigma. Before them, the channel alone on the
snapshot recording's first second: numpy and compiled samples of the same
channel (before noise and front end), their CPU time and max |diff|.

    python tools/bench_generate.py --parts cli --duration-s 20 --continuous-s 5 [--replay] [--baseline-ref main]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from baseline_tree import export_package

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.signal.channel import SiteChannel, cn0_geometry_dbhz, site_geometry

FS = 2.5e6
SNAP, PERIOD, DURATION = 0.02, 1.0, 600.0
IDS = ["70002", "70524", "70546", "71563", "71585", "71607", "72129"]


def channel(duration_s):
    const = load_constellation().select_ids(IDS)
    xian = geodetic_to_ecef(np.radians(34.342), np.radians(108.940), 400.0)
    start = np.datetime64("2025-01-01T19:40:00", "ns")
    t_nodes, range_m, elev = site_geometry(const, xian, start, duration_s)
    return SiteChannel(t_nodes, range_m, FS, cn0_geometry_dbhz(45.0, range_m, elev), 5.0)


def snapshots(duration_s, rng):
    ch = channel(duration_s)
    n_snap = int(SNAP * FS)
    for k in range(int(duration_s / PERIOD)):
        ch.samples(int(k * PERIOD * FS), n_snap, rng).astype(np.complex64)


def continuous_then_cut(duration_s, rng, chunk=1 << 18):
    ch = channel(duration_s)
    for start in range(0, int(duration_s * FS), chunk):
        ch.samples(start, chunk, rng).astype(np.complex64)


def bench_snapshot():
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    snapshots(DURATION, rng)
    t_snap = time.perf_counter() - t0
    base_s = 60.0
    t0 = time.perf_counter()
    continuous_then_cut(base_s, rng)
    t_cont = (time.perf_counter() - t0) * DURATION / base_s
    print(f"10-min snapshot recording ({SNAP * 1e3:g} ms every {PERIOD:g} s, {FS:g} S/s, {len(IDS)} sats): "
          f"{t_snap:.2f} s")
    print(f"baseline, continuous stream then cut (60 s measured, x10): {t_cont:.1f} s")
    print(f"ratio baseline / snapshot: {t_cont / t_snap:.0f}x")


#: tools/bench_lo_offset.py's snapshot recording (site, start, rate, front end, clocks) and tools/bench_replay.py's
#: continuous one (its throughput recording's 7 satellites: seed 1's draw from those above 40 deg).
RECORDINGS = {
    "snapshot": ["--site", "48.137,11.575,520.0", "--start", "2025-01-01T19:40:00Z", "--sample-rate-hz", "4e6",
                 "--mask-deg", "25", "--seed", "7", "--orbit-error-along-m", "300", "--rx-offset-hz", "620000",
                 "--rx-drift-hz-per-s", "25", "--front-end", "consumer", "--snapshot-s", "0.02", "--period-s", "1"],
    "continuous": ["--site", "34.342,108.94,400.0", "--start", "2025-01-01T19:40:00Z", "--sample-rate-hz", "2.5e6",
                   "--mask-deg", "40", "--seed", "1"],
}

# A child's ``leosop generate``: argv = tree ("" this one), kernel ("numpy": numba blocked), the CLI's arguments.
_CHILD = """
import sys
if sys.argv[1]:
    sys.path.insert(0, sys.argv[1])
if sys.argv[2] == "numpy":
    sys.modules["numba"] = None  # as if numba were not installed
from leosop.cli import main
sys.exit(main(sys.argv[3:]))
"""


def _child(kernel, argv, tree=""):
    """Wall and CPU time [s] of one ``leosop generate`` in a child process (of the package under ``tree``)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(tree), kernel, "generate", *argv],
                            stdout=subprocess.DEVNULL, env={**os.environ, "PYTHONPATH": ""} if tree else None)
    _, status, usage = os.wait4(proc.pid, 0)
    if status:
        sys.exit(f"leosop generate ({kernel}) failed: {argv}")
    return time.perf_counter() - t0, usage.ru_utime + usage.ru_stime


def _visible(work, site_argv, n_sats, seed):
    """``n_sats`` of the satellites the generator keeps at the start, drawn with ``seed`` (bench_replay's).

    The probe, compiled, also warms numba's cache for the timed runs."""
    probe = work / "probe.sigmf-meta"
    _child("numba", ["-o", str(probe), *site_argv, "--duration-s", "0.1"])
    ids = [s["sat_id"] for s in json.loads(probe.read_text())["global"]["leosop:satellites"]]
    return [str(i) for i in np.random.default_rng(seed).permutation(ids)[:n_sats]]


def _compare(a, b):
    """How far two recordings' samples are apart, and whether their metadata is identical (text)."""
    meta = [json.loads(p.read_text()) for p in (a, b)]
    for m in meta:
        m["global"].pop("core:sha512")
    dtype = meta[0]["global"]["core:datatype"]
    x, y = (np.fromfile(p.with_suffix(".sigmf-data"), np.complex64 if dtype == "cf32_le" else np.int8) for p in (a, b))
    same = meta[0] == meta[1]
    if dtype == "cf32_le":
        ulp = np.spacing(np.maximum(np.abs(x.real), np.abs(x.imag)))
        d = np.abs(x.astype(complex) - y)
        text = f"max |diff| {d.max():.2g} (float32 spacing there {ulp[np.argmax(d)]:.2g})"
    else:
        d = np.abs(x.astype(int) - y)
        text = f"{np.mean(d > 0):.2%} of ci8 codes differ, by at most {d.max()}"
    return f"{text}; metadata {'identical' if same else 'DIFFERS'}"


def _channel_check(duration_s):
    """The snapshot recording's channel (all satellites up, its clocks), numpy against compiled, first second."""
    from leosop.signal.channel import cn0_geometry_dbhz

    const = load_constellation()
    site = geodetic_to_ecef(np.radians(48.137), np.radians(11.575), 520.0)
    start = np.datetime64("2025-01-01T19:40:00", "ns")
    t_nodes, range_m, elev = site_geometry(const, site, start, duration_s)
    up = np.flatnonzero(np.max(elev, axis=1) > np.radians(25.0))
    rng = np.random.default_rng(7)
    kw = dict(clock_offset_hz=620e3 + rng.uniform(0.0, 5.0, up.size), phase_rad=rng.uniform(0.0, 6.3, up.size),
              rx_drift_hz_per_s=25.0)
    cn0 = cn0_geometry_dbhz(45.0, range_m[up], elev[up])
    out = {}
    for kernel in ("numba", "numpy"):
        ch = SiteChannel(t_nodes, range_m[up], 4e6, cn0, kernel=kernel, **kw)
        ch.samples(0, 10)  # numba's compiled code loaded
        t0 = time.process_time()
        out[kernel] = np.concatenate([ch.samples(int(k * 4e6), 80_000) for k in range(int(duration_s))])
        out[kernel + "_s"] = time.process_time() - t0
    d = np.max(np.abs(out["numba"] - out["numpy"]))
    print(f"channel, {up.size} satellites above 25 deg, {int(duration_s)} x 20 ms at 4 MS/s, no noise: numpy "
          f"{out['numpy_s']:.2f} s CPU, compiled {out['numba_s']:.2f} s ({out['numpy_s'] / out['numba_s']:.1f}x); "
          f"max |diff| {d:.2g} of a unit tone (rms of the sum {np.sqrt(np.mean(np.abs(out['numpy']) ** 2)):.1f})")


def _replay_pair(paths):
    """Static fixes of the numpy and compiled snapshot recordings, their difference beside their sigma."""
    from leosop.replay.pipeline import replay
    from leosop.signal.iq import open_sigmf

    const = load_constellation()
    fixes = [replay(open_sigmf(p), const, static=True, lo_offset_max_hz=3e6).position.fixes for p in paths]
    d = np.linalg.norm(fixes[0].pos_ecef_m - fixes[1].pos_ecef_m)
    sig = [float(np.sqrt(np.trace(f.cov[:3, :3]))) for f in fixes]
    print(f"replay (static, global search): fixes {d:.3g} m apart; 3-D sigma baseline {sig[0]:.3g} m, "
          f"compiled {sig[1]:.3g} m")


def bench_cli(duration_s, continuous_s, replay_too, work, baseline_ref):
    _channel_check(min(duration_s, 10.0))
    runs = {"snapshot": [*RECORDINGS["snapshot"], "--duration-s", f"{duration_s:g}"],
            "continuous": [*RECORDINGS["continuous"], "--duration-s", f"{continuous_s:g}",
                           "--sat", *_visible(work, RECORDINGS["continuous"], 7, 1)]}
    base = work / "baseline"
    base.mkdir(exist_ok=True)
    export_package(baseline_ref, base)
    for kind, argv in runs.items():
        length = f"{duration_s:g} s of snapshots" if kind == "snapshot" else f"{continuous_s:g} s"
        paths = {}
        for name, kernel, tree in ((baseline_ref, "numpy", base), ("numba blocked", "numpy", ""),
                                   ("compiled", "numba", "")):
            paths[name] = work / f"{kind}_{name.replace(' ', '_')}.sigmf-meta"
            wall, cpu = _child(kernel, ["-o", str(paths[name]), *argv], tree)
            if name == baseline_ref:
                cpu0 = cpu
            print(f"{kind} ({length}), {name}: {wall:.1f} s wall, {cpu:.1f} s CPU ({cpu0 / cpu:.1f}x less than "
                  f"{baseline_ref}); " + ("" if name == baseline_ref else _compare(paths[baseline_ref], paths[name])),
                  flush=True)
        if kind == "snapshot" and replay_too:
            _replay_pair([paths[baseline_ref], paths["compiled"]])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", nargs="+", default=["snapshot", "cli"], choices=("snapshot", "cli"))
    ap.add_argument("--duration-s", type=float, default=20.0, help="the cli part's snapshot recording (default 20)")
    ap.add_argument("--continuous-s", type=float, default=5.0, help="the cli part's continuous recording (default 5)")
    ap.add_argument("--replay", action="store_true", help="replay both snapshot recordings and compare the fixes")
    ap.add_argument("--workdir", help="keep the recordings here (default a temporary directory)")
    ap.add_argument("--baseline-ref", default="main", help="git ref of the baseline generator (default main)")
    args = ap.parse_args(argv)
    if "snapshot" in args.parts:
        bench_snapshot()
    if "cli" in args.parts:
        work = Path(args.workdir or tempfile.mkdtemp(prefix="bench_generate_"))
        work.mkdir(parents=True, exist_ok=True)
        bench_cli(args.duration_s, args.continuous_s, args.replay, work, args.baseline_ref)


if __name__ == "__main__":
    main()
