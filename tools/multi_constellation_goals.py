"""The measured goals of issue 10 (multi-constellation LEO navigation) over many seeds.

Runs the bundled degraded-sky scenarios (leosop/data/scenarios) at
measurement level, N seeds each, loose and tight, with every family and with
Starlink alone (leosop.apps.repro.multi.run_case; Dask-parallel through
leosop.apps.studies), and prints

- high latitude (68 N, 25 deg mask, real 2021-08-06 snapshot; skipped when
  the data folder, $LEOSOP_DATA, lacks it): fused mean errors, availability, INS alone
  (goals: tight <= 10 m and <= 0.05 m/s, availability 1.0, INS ~1 km);
- the default flight with all four families against Starlink alone;
- the outage (3 satellites from 300 to 480 s): mean and final error over the
  window against the same window of the open-sky run (goal: tight within
  5x open sky, loose drifting like the INS);
- the urban canyon (60 deg mask);
- filter consistency of every mixed case: NEES of position and velocity per
  dimension (goal 0.5-2), NIS per degree of freedom with its 99 % interval,
  lag-1 correlation of the whitened innovations with its null 3-sigma bound.

Usage: LEOSOP_DATA=../shared/data OPENBLAS_NUM_THREADS=1 python tools/multi_constellation_goals.py
       [--seeds 20] [--scheduler serial] [--only high-latitude xian-baoji-multi outage urban-canyon]
"""

import argparse

import numpy as np
from scipy import stats

from leosop.apps.repro.multi import available, run_case
from leosop.apps.scenarios import load_scenario, scenario_tle
from leosop.apps.studies import map_chunks

COUPLINGS = ("loose", "tight")
NAMES = ("high-latitude", "xian-baoji-multi", "outage", "urban-canyon")


def _cases(names, seeds):
    chunks = []
    tle = {name: scenario_tle(load_scenario(name)) for name in names}
    for name in names:
        for sky in ("all", "starlink") if name == "xian-baoji-multi" else ("all",):
            chunks += [(name, sky, c, s, True, tle[name]) for c in COUPLINGS for s in seeds]
    if "outage" in names:
        chunks += [("outage", "all", c, s, False, tle["outage"]) for c in COUPLINGS for s in seeds]
    return chunks


def _consistency(runs):
    nees = np.concatenate([r["nees"] for r in runs])
    nis, dof = sum(r["nis"] for r in runs), sum(r["nis_dof"] for r in runs)
    if dof == 0:
        return "no update: the INS alone (no consistency to measure)"
    lo, hi = stats.chi2.ppf([0.005, 0.995], dof) / dof
    lag = np.concatenate([r["lag"] for r in runs], axis=1)
    r1 = np.corrcoef(*lag)[0, 1]
    return (f"NEES/6 {nees.mean() / 6:.2f} (goal 0.5-2)  NIS/dof {nis / dof:.3f} (99% [{lo:.3f}, {hi:.3f}])  "
            f"lag-1 {r1:+.3f} (null |r| < {3 / np.sqrt(lag.shape[1]):.3f})")


def _mean(runs, key):
    return np.mean([r[key] for r in runs])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--scheduler")
    parser.add_argument("--only", nargs="+", choices=NAMES, default=NAMES, help="these scenarios (default all)")
    args = parser.parse_args()
    seeds = list(range(args.seeds))
    names = list(args.only)
    missing = available("high-latitude")
    if missing and "high-latitude" in names:
        print(f"high-latitude: skipped ({missing})")
        names.remove("high-latitude")
    chunks = _cases(names, seeds)
    res = {ch[:5]: r for ch, r in zip(chunks, map_chunks(run_case, chunks, scheduler=args.scheduler, desc="runs"))}

    def runs(name, sky, coupling, outage=True):
        return [res[(name, sky, coupling, s, outage)] for s in seeds]

    print(f"{args.seeds} seeds, measurement level; mean 3D errors over each flight")
    for name in names:
        print(f"\n{name}:")
        skies = ("all", "starlink") if name == "xian-baoji-multi" else ("all",)
        for sky in skies:
            for c in COUPLINGS:
                rs = runs(name, sky, c)
                print(f"  {sky:8s} {c:5s}  pos {_mean(rs, 'pos'):8.2f} m  vel {_mean(rs, 'vel'):.4f} m/s  "
                      f"availability {_mean(rs, 'availability'):.3f}  fixes {_mean(rs, 'n_fixes'):5.0f}  "
                      f"INS alone {_mean(rs, 'ins_pos'):7.1f} m")
                if sky == "all":
                    print(f"                 {_consistency(rs)}")
        if name == "outage":
            for c in COUPLINGS:
                w, o = runs(name, "all", c), runs(name, "all", c, outage=False)
                ratio = _mean(w, "window_pos") / _mean(o, "window_pos")
                print(f"  outage window, {c:5s}: {_mean(w, 'window_pos'):7.2f} m (end "
                      f"{_mean(w, 'window_end_pos'):.2f} m)  open sky {_mean(o, 'window_pos'):.2f} m  "
                      f"ratio {ratio:.2f} (goal tight <= 5)")


if __name__ == "__main__":
    main()
