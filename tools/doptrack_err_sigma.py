"""DopTrack (Delfi-C3, 98 passes): horizontal error over posterior sigma of single-pass, per-day and all-pass fixes.

The issue-10 measure of the per-pass time-offset states (along-track errors of
the element sets), which position_static_passes estimates by default: every
fix from one pass, from each day's passes and from all 98, height known, no
start given, time offsets on (``--off``: off, for comparison). Prints, per
set, the number of fixes, failures (no finite solution), the median error,
the median and the largest err/sigma and how many are below 3; for the days
of 3 passes or more, each fix's horizontal NEES (``error' P^-1 error`` on
the 2 x 2 horizontal covariance, chi-square with 2 dof when consistent), its
mean and how many are within the 2-D 99 % region.

Usage: OPENBLAS_NUM_THREADS=1 python tools/doptrack_err_sigma.py [--data DIR] [--off] [--sets day,single,all]
(``--sets day`` alone: under 2 min of CPU; single passes ~5 min, all 98 ~2 min.)

Measured (time offsets on; the machine shared, 20-34 min wall per run), median over the fixes:

=========  =====================================  ==============================================
set        before (white per-pass sigma)          after (correlation-scaled sigma, horizon rule,
                                                   mirror mixture, second solve falls back)
=========  =====================================  ==============================================
per day    30 fixes, 0 failed, err 5,975 m,       30, 0 failed, err 4,497 m, sigma 1,686 m,
           sigma 794 m, err/sigma 6.99 (max 595,  err/sigma 2.12 (max 6.7), 20/30 below 3
           2020-04-05's single pass 3,327 km      (2020-04-05: 2.0, flagged ambiguous)
           off), 4/30 below 3
one pass   98, 4 failed, err 10.5 km, sigma       98, 0 failed, err 11.3 km, sigma 421 km (the
           3.6 km, err/sigma 2.80 (max 913),      mirror's distance in the sigma of ambiguous
           49/94 below 3                          passes), err/sigma 0.28 (max 198), 81/98
all 98     err 315 m, sigma 107 m, err/sigma 2.95 err 471 m, sigma 232 m, err/sigma 2.03
=========  =====================================  ==============================================

With the passes' disagreement tested on top (``solve_static_passes(pass_offsets=True)``, the
default). First as per-pass radial/cross-track offsets alone, their variance capped at 1 km: per day
30 fixes, 0 failed, err 4,505 m, sigma 2,627 m, err/sigma median 1.88 (max 3.58), 27/30 below 3;
all 98: err 478 m, sigma 1,213 m, err/sigma 0.39. The cap bound on the three worst days, the
variance component collapsed to 0 on a day whose test was significant (2020-04-07, chi-square 37.8
on 6 dof), and fitted to the disagreement's score a variance factor on the white sigmas explains it
far better than offsets (negative log-likelihood lower by 110 on all 98 passes, 126 over the 28
multi-pass days; offsets alone would have to be 3 km cross-track, 8 km on low passes, for 1-2 day old
element sets). Now both, fitted jointly by maximum likelihood (factor >= 1, offsets capped at 1 km):
per day 30 fixes, 0 failed, err 4,505 m, sigma 3,764 m, err/sigma median 1.09 (max 2.69), 30/30
below 3; all 98: err 478 m, sigma 498 m, err/sigma 0.96.

With the outlier test counting each row's whole leverage and testing every
pass also when the chi-square sum passes (``robust_ls``; ``--sets day``):
tested at the plain 1e-3 per pass it thinned the correlated rows (per day
err 4,486 m, err/sigma median 1.09, max 3.89, 29/30 below 3); at 1e-3 over
the pass's rows (Bonferroni), per day 30 fixes, 0 failed, err 3,778 m,
sigma 4,094 m, err/sigma median 1.05 (max 2.67), 30/30 below 3; one pass
98 fixes, 0 failed, err 11.3 km, sigma 377 km, err/sigma median 0.18 (max
117), 85/98 below 3; all 98: err 525 m, sigma 550 m, err/sigma 0.96 (was
478 m, 498 m, 0.96). 6.5 min for ``--sets single,all`` on an idle machine.

With the passes' variance factor as a Student-t covariance (``pass_disagreement``: the
maximum-likelihood factor times dof / (dof - 2); docs/notes/few-pass-variance-factor.md),
8 min of CPU for the three sets:

=========  ==========================================  ==========================================
set        before (maximum-likelihood factor)          after (Student-t factor)
=========  ==========================================  ==========================================
per day    30 fixes, 0 failed, err 3,778 m, sigma      30, 0 failed, err 3,778 m, sigma 4,708 m,
           4,094 m, err/sigma 1.05 (max 2.67), 30/30   err/sigma 0.89 (max 2.67), 30/30 below 3;
           below 3; horizontal NEES of the 23 days of  NEES mean 2.93, median 2.07, 23/23 within
           3-6 passes mean 3.79, median 2.88, 22/23
           within chi2(2) 9.21
one pass   98, 0 failed, err 11.3 km, sigma 377 km,    unchanged (2 dof: the t has no covariance)
           err/sigma 0.18 (max 117), 85/98 below 3
all 98     err 525 m, sigma 550 m, err/sigma 0.96      err 525 m, sigma 553 m, err/sigma 0.95
=========  ==========================================  ==========================================

What the residuals show: at 0.5 s the per-pass residuals (1.5-6 Hz RMS) are
far from white (lag-1 correlation up to 0.8, integrated correlation times
up to ~48 rows), so white sigmas were 2-7x too small; the remaining excess
(10 of 30 days above 3) is a bias common to a pass that no residual shows:
the element sets' cross-track and radial errors (the time offsets take the
along-track part). The ionosphere is not it: at 145.87 MHz its Doppler is
40.3 dSTEC/dt / (c f) = 0.92 Hz per TECU/s; April 2020 was solar minimum
(vertical TEC ~5-15 TECU at 52 N), and the slant factor changes by ~0.01/s
during a pass, so dSTEC/dt ~0.05-0.15 TECU/s: 0.05-0.15 Hz, smooth over the
pass (largely taken up by its cubic) and 10-100x below the residual RMS.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_doppler_position import DATA, _horizontal, _nees_h, fix_passes  # noqa: E402

from leosop.positioning.datasets import read_doptrack  # noqa: E402
from leosop.progress import progress  # noqa: E402

#: The 2-D 99 % region of a consistent horizontal NEES: chi-square with 2 dof, -2 ln(0.01).
CHI2_2DOF_99 = 9.21
#: Days with at least this many passes enter the NEES summary (two-pass fixes are flagged ``few_passes``).
NEES_MIN_PASSES = 3


def _row(name, fixes, p0):
    stats = np.array([_horizontal(f, p0) for f in fixes]).reshape(-1, 2)
    e, s = stats.T
    r = e / s
    ok = np.isfinite(r)
    line = f"{name:>9s} {len(fixes):5d} {int((~ok).sum()):6d} {np.nanmedian(e):10.0f} {np.nanmedian(s):10.1f} "
    line += f"{np.nanmedian(r):8.2f} {np.nanmax(r):8.2f} {int((r[ok] < 3).sum()):5d}/{int(ok.sum())}"
    print(line, flush=True)
    return r


def _nees_days(fixes, by_day, p0):
    """Horizontal NEES of each day with NEES_MIN_PASSES passes or more, their mean and the share within 99 %."""
    nees = np.array([_nees_h(f, p0) for f, s in zip(fixes, by_day) if len(s) >= NEES_MIN_PASSES])
    print(f"{'':>9s} horizontal NEES, {nees.size} days of {NEES_MIN_PASSES}+ passes: "
          f"{' '.join(f'{x:.2f}' for x in nees)}")
    print(f"{'':>9s} mean {np.nanmean(nees):.2f} (2 when consistent), median {np.nanmedian(nees):.2f} (1.39), "
          f"{int((nees < CHI2_2DOF_99).sum())}/{nees.size} within the 2-D 99 % region ({CHI2_2DOF_99})")


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
        fixes = [fix_passes(s, **kw) for s in progress(by_day, desc="days")]
        r = _row("per day", fixes, p0)
        print(f"{'':>9s} per-day err/sigma: {' '.join(f'{x:.1f}' for x in r)}")
        _nees_days(fixes, by_day, p0)
    if "single" in sets:
        _row("one pass", [fix_passes([p], **kw) for p in progress(passes, desc="passes")], p0)
    if "all" in sets:
        _row("all", [fix_passes(passes, **kw)], p0)


if __name__ == "__main__":
    main()
