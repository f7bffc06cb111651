"""Screened visibility against brute-force SatrecArray propagation, in one run; with ``--spans``, the
``leosop visibility`` command's time and peak memory over long spans, chunked against the whole-span code.

Default: the real 10,138-satellite Starlink snapshot of 2026-04-08 (from
../shared/data/tle), one site (Delft), 24 h at 1 s, 40 deg mask. Prints both
times, their ratio, and whether the visible (satellite, epoch) sets are
identical. Goal (DESIGN 6): screened >= 20x faster, identical sets.

``--spans 6 24 168`` runs ``leosop visibility --out`` for each span (hours)
in a child process of its own and prints its wall time and peak RSS
(``os.wait4``), this tree's streamed code beside the code of ``--baseline-ref``
(default ``main``, exported with ``git archive``), the ratios, and whether
the two wrote the same ``visibility.csv`` and ``passes.csv``. The baseline
holds the whole span in memory (~1.4 GB a day), so it runs only up to
``--baseline-max-hours``. Goal (issue 24): 24 h <= 10 s and <= 400 MB, 7 d
<= 7x the 24 h time at the same memory.

    python tools/bench_visibility.py [--hours 24] [--mask-deg 40] [--tle FILE]
    python tools/bench_visibility.py --spans 6 24 168 [--baseline-ref main]
"""

import argparse
import filecmp
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
from leosop.orbits.visibility import compute_visibility

REPO = Path(__file__).resolve().parents[1]
SNAPSHOT = REPO.parent / "shared" / "data" / "tle" / "starlink_3le_2026-04-08_Bochika.txt"


def run_cli(code_dir, out_dir, args):
    """Wall time [s] and peak RSS [MB] of ``leosop visibility ARGS --out OUT_DIR`` run from ``code_dir``."""
    env = dict(os.environ, PYTHONPATH=str(code_dir))
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "leosop", "visibility", *args, "--out", str(out_dir)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stderr = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{code_dir}: leosop visibility failed: {stderr.decode().strip()}")
    return time.perf_counter() - t0, usage.ru_maxrss / 1024


def bench_spans(args):
    """Streamed against whole-span ``leosop visibility --out`` for each of ``args.spans`` hours."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "baseline"
        base.mkdir()
        export_package(args.baseline_ref, base)
        print(f"{'span':>6} {'streamed s':>10} {'MB':>6} | {args.baseline_ref + ' s':>10} {'MB':>6} | "
              f"{'time ratio':>10} {'memory ratio':>12} | same files")
        for hours in args.spans:
            cli = ["--tle", args.tle, "--site", args.site, "--start", args.start, "--duration-s",
                   f"{hours * 3600:g}", "--step-s", f"{args.step_s:g}", "--mask-deg", f"{args.mask_deg:g}"]
            t_new, m_new = run_cli(REPO, tmp / f"new{hours}", cli)
            line = f"{hours:>5g}h {t_new:>10.1f} {m_new:>6.0f} | "
            if hours <= args.baseline_max_hours:
                t_old, m_old = run_cli(base, tmp / f"old{hours}", cli)
                same = all(filecmp.cmp(tmp / f"new{hours}" / f, tmp / f"old{hours}" / f, shallow=False)
                           for f in ("visibility.csv", "passes.csv"))
                line += f"{t_old:>10.1f} {m_old:>6.0f} | {t_old / t_new:>9.2f}x {m_old / m_new:>11.2f}x | {same}"
            else:
                line += f"{'(skipped: over --baseline-max-hours)':>42}"
            print(line, flush=True)


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
    parser.add_argument("--baseline-ref", default="main", help="git ref of the whole-span code (default main)")
    parser.add_argument("--baseline-max-hours", type=float, default=24.0,
                        help="longest span run with the baseline (default 24)")
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
