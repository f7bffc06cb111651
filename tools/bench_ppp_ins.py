"""Tight PPP/INS on the simulated car over many seeds: NEES of the float position, fixed/float RMS, first fix, outage.

For each seed: one run of ``leosop.apps.repro.ppp_ins_study.scenario`` (real GRG orbits/clocks, 1 Hz GPS,
fog-grade IMU by default). Float-position NEES (3 dof, ENU) averaged over the seeds at every epoch after
the first 5 min; a consistent filter gives 3, and the 95% band of the mean of N seeds is
chi2(3N)/N. Baseline in the same run: the INS alone (no GNSS after the first epoch) is not printed here
(it drifts by kilometres); the float solution without AR is the baseline of the fixed one.

Run: ``OPENBLAS_NUM_THREADS=1 python tools/bench_ppp_ins.py [--seeds 20] [--duration 1200] [--grade fog]
[--outage]``
"""

import argparse
import os
from pathlib import Path
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from leosop.frames import C_e_n, ecef_to_geodetic  # noqa: E402
from leosop.apps.repro import ppp_ins_study  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=1200.0)
    ap.add_argument("--grade", default="fog", choices=sorted(ppp_ins_study.GRADES))
    ap.add_argument("--outage", action="store_true", help="a 60 s outage 2/3 into each run")
    a = ap.parse_args()
    products = ppp_ins_study._products(Path(__file__).resolve().parents[2] / "shared" / "data")
    nees, rows = [], []
    t0 = time.perf_counter()
    outage = 2.0 * a.duration / 3.0 if a.outage else None
    for seed in range(a.seeds):
        truth, res = ppp_ins_study.scenario(seed, duration_s=a.duration, outage_at_s=outage, products=products,
                                            grade=a.grade)
        lat, lon, _ = ecef_to_geodetic(truth[0])
        e = (res.pos_float_ecef_m - truth) @ C_e_n(lat, lon)
        nees.append(np.einsum("ki,kij,kj->k", e, np.linalg.inv(res.cov_pos_enu_m2), e))
        st = ppp_ins_study.statistics(truth, res, last_s=a.duration / 2, outage_at_s=outage)
        rows.append(st)
        print(f"seed {seed:2d}: " + ", ".join(f"{k} {'-' if v is None else f'{v:.3f}'}" for k, v in st.items()),
              flush=True)
    nees = np.array(nees)[:, 300:]
    mean = nees.mean(axis=0)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * a.seeds) / a.seeds
    print(f"{a.seeds} seeds, {a.duration:g} s, grade {a.grade}, {time.perf_counter() - t0:.0f} s")
    inside = 100 * np.mean((mean > lo) & (mean < hi))
    print(f"float NEES (3 dof) averaged over seeds, epochs from 300 s: mean {mean.mean():.2f}, median "
          f"{np.median(mean):.2f}; inside the 95% band [{lo:.2f}, {hi:.2f}] at {inside:.0f}% of epochs, "
          f"above it at {100 * np.mean(mean > hi):.0f}%")
    for k in rows[0]:
        v = [r[k] for r in rows if r[k] is not None]
        print(f"{k}: median {np.median(v):.3f}, max {np.max(v):.3f} ({len(v)}/{len(rows)} runs)" if v else f"{k}: -")


if __name__ == "__main__":
    main()
