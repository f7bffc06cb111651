"""Tight PPP/INS through a 60 s GNSS outage on the simulated car: drift, wide-lane and narrow-lane re-fix.

For each seed and IMU grade: one run of ``leosop.apps.repro.ppp_ins_study.scenario`` (real GRG orbits/clocks,
1 Hz GPS, every arc restarts after the outage, so all ambiguities are new floats) with the default options
(changed by ``--set``) and, as the baseline in the same run, with ``--baseline`` (default: no wide-lane from
the INS geometry after the outage, ``wl_inertial=False``). Printed per run and as median / worst over the
seeds:

- ``max_err_m``: largest 3-D error of the INS during the outage;
- ``sigma_end_m``: the filter's 3-D position sigma at the last outage epoch;
- ``wl_s``: seconds after the outage until ``min_fixed`` wide-lanes are fixed;
- ``refix_s``: seconds after the outage until the first narrow-lane fix;
- ``wrong``: fixed epochs after the outage whose 3-D error exceeds half a narrow-lane wavelength (5 cm);
  ``wrong_run`` the same over the whole run; ``first_fix_s`` the first fix of the run;
- ``wl_checked``, ``wl_mismatch``: satellite-epochs where a wide-lane fixed from the INS geometry is also
  fixed by the Melbourne-Wuebbena rule on the same arc, and those where the two differ
  (``PppInsResult.n_wl_checked``, ``n_wl_mismatch``).

Beside them, the closed form of the horizontal drift from gyro angle random walk alone (tilt random walk
``q``; per axis ``g q t^2.5 / sqrt(20)``), the floor no filter tuning removes.

With ``--budget``, the error budget of the first seed's outage (main options): the filter's INS-error
covariance at the first outage epoch (``PppInsResult.cov_ins``) propagated to the last one along the true
trajectory (:func:`leosop.apps.repro.ppp_ins_study.outage_budget`), the 1-sigma ENU drift each group of initial
errors and each sensor's noise would give alone, the total (correlations included) and the filter's own
sigma there. Tilt and horizontal accelerometer bias are anti-correlated after the GNSS aiding (what the
position sees is their sum), so they are shown together and alone.

Run: ``OPENBLAS_NUM_THREADS=1 python tools/bench_ppp_ins_outage.py [--seeds 10] [--grades fog navigation]
[--duration 900] [--jobs 2] [--set wl_min_epochs=3 ...] [--baseline wl_inertial=False ...] [--budget]``
"""

import argparse
import dataclasses
import os
from pathlib import Path
import time
from concurrent.futures import ProcessPoolExecutor

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.constants import G0_MPS2  # noqa: E402
from leosop.apps.repro import ppp_ins_study  # noqa: E402
from leosop.gnss import ppp_ins  # noqa: E402

OUTAGE_S = 60.0


def one(args):
    seed, grade, main, duration, outage_at, overrides, with_budget = args
    products = ppp_ins_study._products(Path(__file__).resolve().parents[2] / "shared" / "data")
    opts = dataclasses.replace(ppp_ins.PppInsOptions(), **overrides[main])
    truth, res = ppp_ins_study.scenario(seed, duration_s=duration, outage_at_s=outage_at, products=products,
                                        grade=grade, options=opts)
    t = res.t_s - res.t_s[0]
    end = outage_at + OUTAGE_S
    during = (t >= outage_at) & (t < end)
    after = t >= end
    err_f = np.linalg.norm(res.pos_float_ecef_m - truth, axis=1)
    err_x = np.linalg.norm(res.pos_fixed_ecef_m - truth, axis=1)
    sig = np.sqrt(np.trace(res.cov_pos_enu_m2, axis1=1, axis2=2))
    wl = np.flatnonzero(after & (res.n_wl >= opts.min_fixed))
    nl = np.flatnonzero(after & np.isfinite(err_x))
    gap = np.flatnonzero(during)
    doc = {} if not with_budget else {"budget": ppp_ins_study.outage_budget(res, grade, duration, gap[0], gap[-1])}
    return doc | {"seed": seed, "grade": grade, "main": main,
            "max_err_m": float(err_f[during].max()), "sigma_end_m": float(sig[during][-1]),
            "wl_s": float(t[wl[0]] - end) if wl.size else np.nan,
            "refix_s": float(t[nl[0]] - end) if nl.size else np.nan,
            "wrong": int(np.sum(err_x[nl] > 0.05)), "wl_checked": res.n_wl_checked,
            "wl_mismatch": res.n_wl_mismatch,
            "wrong_run": int(np.sum(err_x[np.isfinite(err_x)] > 0.05)),
            "first_fix_s": float(t[np.argmax(np.isfinite(err_x))]) if np.isfinite(err_x).any() else np.nan}


def arw_drift_m(grade, t_s):
    q = np.radians(ppp_ins_study.GRADES[grade]["gyro_arw_deg_per_rt_h"]) / 60.0
    return G0_MPS2 * q * t_s**2.5 / np.sqrt(20.0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--grades", nargs="+", default=["fog", "navigation"], choices=sorted(ppp_ins_study.GRADES))
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--set", nargs="*", default=[], metavar="OPTION=VALUE",
                    help="PppInsOptions fields changed in the runs (e.g. wl_min_epochs=3)")
    ap.add_argument("--baseline", nargs="*", default=["wl_inertial=False"], metavar="OPTION=VALUE",
                    help="PppInsOptions fields changed in the baseline runs")
    ap.add_argument("--budget", action="store_true", help="print the error budget of the first seed's outage")
    a = ap.parse_args()
    fields = {f.name: f.type for f in dataclasses.fields(ppp_ins.PppInsOptions)}

    def parse(items):
        return {k: (v == "True") if fields[k] is bool else fields[k](v) for k, v in (kv.split("=", 1) for kv in items)}

    overrides = {True: parse(a.set), False: parse(a.baseline)}
    outage_at = 2.0 * a.duration / 3.0
    cases = [(s, g, m, a.duration, outage_at, overrides, a.budget and m and s == 0) for g in a.grades
             for m in (True, False) for s in range(a.seeds)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.jobs) as pool:
        rows = list(pool.map(one, cases))
    for r in rows:
        b = r.pop("budget", None)
        if b is not None:
            print(f"error budget, {r['grade']} seed {r['seed']}: 1-sigma drift over the outage E N U [m]")
            for k, v in b.items():
                print(f"  {k:24s}" + " ".join(f"{x:7.3f}" for x in v))
        print(" ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))
    print(f"{a.seeds} seeds, {a.duration:g} s runs, {OUTAGE_S:g} s outage at {outage_at:g} s, "
          f"{time.perf_counter() - t0:.0f} s")
    for g in a.grades:
        print(f"{g}: gyro ARW alone drifts {arw_drift_m(g, OUTAGE_S):.3f} m per horizontal axis (1 sigma) "
              f"in {OUTAGE_S:g} s")
        for m in (True, False):
            sel = [r for r in rows if r["grade"] == g and r["main"] == m]
            name = f"options {overrides[True] or '(defaults)'}" if m else f"baseline {overrides[False]}"
            parts = []
            for k in ("max_err_m", "sigma_end_m", "wl_s", "refix_s"):
                v = np.array([r[k] for r in sel])
                ok = np.isfinite(v)
                parts.append(f"{k} median {np.median(v[ok]):.2f} worst {v[ok].max():.2f}"
                             + ("" if ok.all() else f" (none in {np.sum(~ok)} runs)") if ok.any() else f"{k} -")
            tot = {k: sum(r[k] for r in sel) for k in ("wrong", "wrong_run", "wl_mismatch", "wl_checked")}
            print(f"  {name}: " + "; ".join(parts) + f"; wrong fixes {tot['wrong']} epochs after the outage, "
                  f"{tot['wrong_run']} in the runs; inertial wide-lanes contradicted by the Melbourne-Wuebbena "
                  f"rule {tot['wl_mismatch']} of {tot['wl_checked']} satellite-epochs checked; first fix median "
                  f"{np.nanmedian([r['first_fix_s'] for r in sel]):.0f} s")


if __name__ == "__main__":
    main()
