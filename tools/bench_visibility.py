"""Screened visibility against brute-force SatrecArray propagation, in one run; with ``--floor``, the
screened run against the propagation floor; with ``--spans``, the ``leosop visibility`` command's CPU time and
peak memory over long spans, this tree against a baseline revision.

Default: the real 10,138-satellite Starlink snapshot of 2026-04-08 (from
../shared/data/tle), one site (Delft), 24 h at 1 s, 40 deg mask. Prints both
times, their ratio, and whether the visible (satellite, epoch) sets are
identical. Goal (DESIGN 6): screened >= 20x faster, identical sets.

``--floor`` skips the brute-force run and measures instead the floor the
issue names, one SGP4 propagation per satellite and epoch (sgp4's
``SatrecArray`` alone over every satellite at ``--floor-epochs`` epochs,
scaled to the span), and what an exact screen cannot avoid: the visible
pairs, each propagated once at the per-pair cost of ``Satrec.sgp4_array``.

``--spans 24 168`` runs ``leosop visibility --out`` for each span (hours)
in a child process of its own and prints its CPU time (user + system), wall
time and peak RSS (``os.wait4``), this tree beside the code of
``--baseline-ref`` (default ``main``, exported with ``git archive``), the
ratios, and whether the two wrote the same ``visibility.csv``,
``passes.csv`` and ``visibility.json``; then each side's CPU time of the
longest span over the shortest. The baseline runs up to
``--baseline-max-hours``. The machine may be shared: the load average is
printed with every line, and CPU time is the number to compare. Goal
(issue 24): 24 h <= 10 s and <= 400 MB, 7 d <= 7x the 24 h time and the
same memory.

    python tools/bench_visibility.py [--hours 24] [--mask-deg 40] [--tle FILE] [--floor]
    python tools/bench_visibility.py --spans 24 168 [--baseline-ref main] [--baseline-max-hours 168]
"""

import argparse
import filecmp
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from baseline_tree import export_package

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.visibility import compute_visibility
from leosop.timebase import jd_utc

REPO = Path(__file__).resolve().parents[1]
SNAPSHOT = REPO.parent / "shared" / "data" / "tle" / "starlink_3le_2026-04-08_Bochika.txt"


def run_cli(code_dir, out_dir, args):
    """CPU time [s], wall time [s] and peak RSS [MB] of ``leosop visibility ARGS --out OUT_DIR`` run from
    ``code_dir``."""
    env = dict(os.environ, PYTHONPATH=str(code_dir))
    t0 = time.perf_counter()
    # cwd too: ``python -m`` puts the working directory before PYTHONPATH on sys.path.
    proc = subprocess.Popen([sys.executable, "-m", "leosop", "visibility", *args, "--out", str(out_dir)], env=env,
                            cwd=code_dir, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stderr = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{code_dir}: leosop visibility failed: {stderr.decode().strip()}")
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - t0, usage.ru_maxrss / 1024


def load():
    """The 1-minute load average, as text."""
    return f"{os.getloadavg()[0]:.1f}"


def bench_spans(args):
    """Streamed against whole-span ``leosop visibility --out`` for each of ``args.spans`` hours."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "baseline"
        base.mkdir()
        export_package(args.baseline_ref, base)
        print(f"{'span':>6} {'CPU s':>6} {'wall s':>6} {'MB':>5} | {args.baseline_ref + ' CPU s':>10} {'wall s':>6} "
              f"{'MB':>5} | {'CPU ratio':>9} {'MB ratio':>8} | same files | load")
        cpu = {"new": {}, "old": {}}
        for hours in args.spans:
            cli = ["--tle", str(Path(args.tle).resolve()), "--site", args.site, "--start", args.start, "--duration-s",
                   f"{hours * 3600:g}", "--step-s", f"{args.step_s:g}", "--mask-deg", f"{args.mask_deg:g}"]
            c_new, t_new, m_new = run_cli(REPO, tmp / f"new{hours}", cli)
            cpu["new"][hours] = c_new
            line = f"{hours:>5g}h {c_new:>6.1f} {t_new:>6.1f} {m_new:>5.0f} | "
            if hours <= args.baseline_max_hours:
                c_old, t_old, m_old = run_cli(base, tmp / f"old{hours}", cli)
                cpu["old"][hours] = c_old
                same = all(filecmp.cmp(tmp / f"new{hours}" / f, tmp / f"old{hours}" / f, shallow=False)
                           for f in ("visibility.csv", "passes.csv", "visibility.json"))
                line += (f"{c_old:>10.1f} {t_old:>6.1f} {m_old:>5.0f} | {c_old / c_new:>8.2f}x {m_old / m_new:>7.2f}x "
                         f"| {str(same):>10}")
            else:
                line += f"{'(skipped: over --baseline-max-hours)':>59}"
            print(f"{line} | {load()}", flush=True)
            shutil.rmtree(tmp / f"new{hours}")
            shutil.rmtree(tmp / f"old{hours}", ignore_errors=True)
        for side, name in (("new", "this tree"), ("old", args.baseline_ref)):
            if len(cpu[side]) > 1:
                short, long = min(cpu[side]), max(cpu[side])
                print(f"{name}: CPU {long:g} h / {short:g} h = {cpu[side][long] / cpu[side][short]:.2f} "
                      f"(span ratio {long / short:g})")


def bench_floor(const, times, site, mask_deg, floor_epochs):
    """The screened run's CPU time against the propagation floors (see the module docstring)."""
    t0 = time.process_time()
    vis = compute_visibility(const, times, site, mask_deg, show_progress=False)
    t_run = time.process_time() - t0
    jd, fr = jd_utc(times[:floor_epochs])
    t0 = time.process_time()
    const.satrec_array.sgp4(jd, fr)
    per_point = (time.process_time() - t0) / (len(const) * len(jd))
    n_vis = len(vis.epoch_index)
    sats = vis.sat_index[::max(1, n_vis // 400)][:400]
    t0 = time.process_time()
    for k in sats:  # single-satellite calls of one minute, as a pass is propagated
        const.satrecs[k].sgp4_array(jd[:60], fr[:60])
    per_pair = (time.process_time() - t0) / (len(sats) * len(jd[:60]))
    print(f"screened compute_visibility: {t_run:8.2f} s CPU ({n_vis} visible pairs) | load {load()}")
    print(f"floor, SGP4 of every satellite and epoch: {per_point * 1e9:.0f} ns a point (SatrecArray, "
          f"{len(jd)} epochs) x {len(const) * len(times) / 1e6:.0f} M = {per_point * len(const) * len(times):.1f} s; "
          f"the screened run is {per_point * len(const) * len(times) / t_run:.0f}x faster")
    print(f"floor of an exact screen, the visible pairs propagated once: {per_pair * 1e9:.0f} ns a pair "
          f"(Satrec.sgp4_array) x {n_vis / 1e6:.2f} M = {per_pair * n_vis:.2f} s; the run is "
          f"{t_run / (per_pair * n_vis):.1f}x that")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tle", default=str(SNAPSHOT))
    parser.add_argument("--start", default="2026-04-08T00:00:00")
    parser.add_argument("--hours", type=float, default=24.0)
    parser.add_argument("--step-s", type=float, default=1.0)
    parser.add_argument("--mask-deg", type=float, default=40.0)
    parser.add_argument("--site", default="51.9989,4.3733585,95")
    parser.add_argument("--spans", type=float, nargs="+", metavar="HOURS",
                        help="time and peak memory of leosop visibility --out for these spans, against the baseline")
    parser.add_argument("--baseline-ref", default="main", help="git ref of the baseline code (default main)")
    parser.add_argument("--baseline-max-hours", type=float, default=24.0,
                        help="longest span run with the baseline (default 24)")
    parser.add_argument("--floor", action="store_true",
                        help="the screened run against the propagation floors, no brute-force run")
    parser.add_argument("--floor-epochs", type=int, default=600,
                        help="epochs of the SatrecArray floor sample (default 600)")
    args = parser.parse_args()
    if args.spans:
        bench_spans(args)
        return

    const = load_constellation(args.tle)
    lat, lon, alt = (float(x) for x in args.site.split(","))
    site = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    n = int(args.hours * 3600 / args.step_s)
    times = np.datetime64(args.start, "ns") + (np.arange(n) * args.step_s * 1e9).astype("timedelta64[ns]")
    print(f"{len(const)} satellites x {n} epochs = {len(const) * n / 1e6:.0f} M satellite-epochs, "
          f"mask {args.mask_deg:g} deg, site {args.site}")
    if args.floor:
        bench_floor(const, times, site, args.mask_deg, args.floor_epochs)
        return

    t0 = time.perf_counter()
    fast = compute_visibility(const, times, site, args.mask_deg, screen=True)
    t_fast = time.perf_counter() - t0
    print(f"screened:    {t_fast:8.2f} s  ({len(fast.epoch_index)} visible pairs)", flush=True)
    t0 = time.perf_counter()
    slow = compute_visibility(const, times, site, args.mask_deg, screen=False)
    t_slow = time.perf_counter() - t0
    print(f"brute force: {t_slow:8.2f} s  ({len(slow.epoch_index)} visible pairs)")
    same = np.array_equal(fast.epoch_index, slow.epoch_index) and np.array_equal(fast.sat_index, slow.sat_index)
    print(f"speed-up: {t_slow / t_fast:.1f}x   identical visible sets: {same}")
    print(f"visible per epoch: min {fast.n_visible.min()}, median {np.median(fast.n_visible):g}, "
          f"max {fast.n_visible.max()}")


if __name__ == "__main__":
    main()
