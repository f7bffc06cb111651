"""24 h float PPP of ESBC00DNK (2020-06-25), static and kinematic, against the station's published coordinate.

Reference: the RINEX header position is the station's ETRF2000 (ETRS89) coordinate (SDFE); mapped to
ITRF2014 at the observation epoch ([Altamimi 2018], leosop.gnss.etrf) it is the frame of the GRG orbits
and clocks. Prints the static 3-D error (and ENU), the kinematic RMS after a convergence time, the
read and run times. Baseline in the same run: the header position taken as if it were ITRF (the 0.76 m
frame offset of the first measurement).

Also printed: the share of kinematic epoch-axis errors within 3 sigma after the convergence time, and the
static error against its sigma at 1, 3, 6, 12 and 24 h. ``--atx`` applies the day's ANTEX file.

Run: ``OPENBLAS_NUM_THREADS=1 python tools/bench_ppp.py [--converge-min 60] [--hours 24] [--atx]``
"""

import argparse
import dataclasses
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.frames import C_e_n, ecef_to_geodetic  # noqa: E402
from leosop.gnss.antex import read_antex  # noqa: E402
from leosop.gnss.etrf import decimal_year, etrf2000_to_itrf2014  # noqa: E402
from leosop.gnss.ppp import PppOptions, run_ppp  # noqa: E402
from leosop.gnss.products import read_clk, read_sp3  # noqa: E402
from leosop.gnss.rinex import read_obs  # noqa: E402

DAY = Path(__file__).resolve().parents[2] / "shared" / "data" / "rinex" / "esbc_2020-177"
OBS = DAY / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"
SP3 = DAY / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz"
CLK = DAY / "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz"
CODES = {"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--converge-min", type=float, default=60.0)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--systems", default="GE")
    ap.add_argument("--atx", action="store_true", help="apply the day's ANTEX (esbc_2020-177.atx)")
    ap.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                    help="a PppOptions field set to a float (repeatable)")
    a = ap.parse_args()
    antex = read_antex(DAY / "esbc_2020-177.atx") if a.atx else None
    overrides = {k: float(v) for k, v in (o.split("=") for o in a.option)}
    t0 = time.perf_counter()
    obs = read_obs(OBS, codes=CODES)
    orb, clk = read_sp3(SP3), read_clk(CLK)
    t_read = time.perf_counter() - t0
    n = int(round(a.hours * 120))
    obs = dataclasses.replace(obs, time_gps=obs.time_gps[:n], obs={k: v[:n] for k, v in obs.obs.items()},
                              lli={k: v[:n] for k, v in obs.lli.items()})
    ref = etrf2000_to_itrf2014(obs.approx_pos_ecef_m, decimal_year(obs.time_gps[len(obs.time_gps) // 2]))
    lat, lon, _ = ecef_to_geodetic(ref)
    C = C_e_n(lat, lon)
    print(f"read (obs+sp3+clk): {t_read:.1f} s; reference ITRF2014 = {np.round(ref, 4).tolist()}")
    for static in (True, False):
        t = time.perf_counter()
        res = run_ppp(obs, orb, clk, PppOptions(static=static, systems=a.systems, **overrides), antex=antex)
        dt = time.perf_counter() - t
        err = res.pos_ecef_m - ref
        ok = np.isfinite(err).all(axis=1)
        tsec = (res.time_gps - res.time_gps[0]).astype("timedelta64[s]").astype(float)
        if static:
            e = err[ok][-1]
            base = np.linalg.norm(res.pos_ecef_m[ok][-1] - obs.approx_pos_ecef_m)
            print(f"static  {a.systems}: final 3-D error {100 * np.linalg.norm(e):.1f} cm, ENU "
                  f"{np.round(100 * C.T @ e, 1).tolist()} cm (baseline, header as if ITRF: {100 * base:.1f} cm); "
                  f"run {dt:.1f} s, slips {res.n_slips}, outliers {res.n_outliers}")
            below = np.flatnonzero(ok & (np.linalg.norm(err, axis=1) < 0.05))
            conv = [k for k in below if np.all(np.linalg.norm(err[k:][ok[k:]], axis=1) < 0.05)]
            print(f"        stays below 5 cm from {tsec[conv[0]] / 3600:.2f} h" if conv else "        never < 5 cm")
            for h in (1, 3, 6, 12, 24):
                k = np.flatnonzero(ok & (tsec < 3600 * h))
                if len(k) and tsec[k[-1]] >= 3600 * h - 1200:
                    e_enu, s_enu = C.T @ err[k[-1]], res.sigma_enu_m[k[-1]]
                    print(f"        at {h:2d} h: ENU error {np.round(100 * e_enu, 1).tolist()} cm, "
                          f"sigma {np.round(100 * s_enu, 2).tolist()} cm, "
                          f"|error|/sigma {np.round(np.abs(e_enu) / s_enu, 1).tolist()}")
        else:
            sel = ok & (tsec >= 60 * a.converge_min)
            enu = err[sel] @ C
            rms3 = np.sqrt(np.mean(np.sum(err[sel] ** 2, axis=1)))
            print(f"kinematic {a.systems}: RMS after {a.converge_min:g} min: 3-D {100 * rms3:.1f} cm, ENU "
                  f"{np.round(100 * np.sqrt(np.mean(enu**2, axis=0)), 1).tolist()} cm, mean ENU "
                  f"{np.round(100 * enu.mean(axis=0), 1).tolist()} cm; 95% 3-D "
                  f"{100 * np.percentile(np.linalg.norm(err[sel], axis=1), 95):.1f} cm; run {dt:.1f} s")
            ratio = np.abs(enu) / res.sigma_enu_m[sel]
            print(f"          epoch-axis errors within 3 sigma after {a.converge_min:g} min: "
                  f"{100 * np.mean(ratio <= 3):.1f} % (E/N/U {np.round(100 * np.mean(ratio <= 3, axis=0), 1).tolist()}"
                  f" %), within 1 sigma {100 * np.mean(ratio <= 1):.1f} %, median sigma ENU "
                  f"{np.round(100 * np.median(res.sigma_enu_m[sel], axis=0), 2).tolist()} cm")


if __name__ == "__main__":
    main()
