"""DopTrack (Delfi-C3, 98 passes): horizontal error over posterior sigma of single-pass, per-day and all-pass fixes.

The issue-10 measure of the per-pass time-offset states (along-track errors of
the element sets), which position_static_passes estimates by default: every
fix from one pass, from each day's passes and from all 98, height known, no
start given, time offsets on (``--off``: off, for comparison). Prints, per
set, the number of fixes, failures (no finite solution), the median error,
the median and the largest err/sigma and how many are below 3.

Usage: OPENBLAS_NUM_THREADS=1 python tools/doptrack_err_sigma.py [--data DIR] [--off] [--sets day,single,all]
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_doppler_position import DATA, _horizontal, fix_passes  # noqa: E402

from leosop.positioning.datasets import read_doptrack  # noqa: E402
from leosop.progress import progress  # noqa: E402


def _row(name, fixes, p0):
    stats = np.array([_horizontal(f, p0) for f in fixes]).reshape(-1, 2)
    e, s = stats.T
    r = e / s
    ok = np.isfinite(r)
    line = f"{name:>9s} {len(fixes):5d} {int((~ok).sum()):6d} {np.nanmedian(e):10.0f} {np.nanmedian(s):10.1f} "
    line += f"{np.nanmedian(r):8.2f} {np.nanmax(r):8.2f} {int((r[ok] < 3).sum()):5d}/{int(ok.sum())}"
    print(line, flush=True)
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--off", action="store_true", help="time offsets off (the comparison)")
    ap.add_argument("--sets", default="day,single,all", help="comma-separated: day, single, all")
    args = ap.parse_args()
    passes = read_doptrack(args.data / "leo-doppler" / "doptrack_delfi-c3_2020-04")
    kw = {"time_bias": not args.off}
    p0 = passes[0]
    print(f"DopTrack Delfi-C3, {len(passes)} passes, time offsets {'off' if args.off else 'on'}; horizontal error")
    print(f"{'set':>9s} {'fixes':>5s} {'failed':>6s} {'med_err_m':>10s} {'med_sig_m':>10s} {'med_e/s':>8s} "
          f"{'max_e/s':>8s} {'e/s<3':>7s}")
    days = np.array([str(p.meas.time_utc[0])[:10] for p in passes])
    by_day = [[p for p, d in zip(passes, days) if d == day] for day in np.unique(days)]
    sets = args.sets.split(",")
    if "day" in sets:
        r = _row("per day", [fix_passes(s, **kw) for s in progress(by_day, desc="days")], p0)
        print(f"{'':>9s} per-day err/sigma: {' '.join(f'{x:.1f}' for x in r)}")
    if "single" in sets:
        _row("one pass", [fix_passes([p], **kw) for p in progress(passes, desc="passes")], p0)
    if "all" in sets:
        _row("all", [fix_passes(passes, **kw)], p0)


if __name__ == "__main__":
    main()
