"""Ambiguity-fixed PPP of ESBC00DNK (2020-06-25, 24 h) against the station's ITRF2014 coordinate: the issue-22 goals.

Same files as ``tools/bench_ppp.py`` (GRG orbits and integer-recovery clocks, the day's ANTEX subset, which
leaves G04 / G18 out of ambiguity fixing: IGS20 offsets against the clocks' igs14). Reference: the header
ETRF2000 coordinate mapped to ITRF2014 (``leosop.gnss.etrf``; PROVENANCE.md gives the same numbers).

Printed:
- static: the fixed final 3-D error (goal 1 cm), and at 1, 3, 6, 12, 24 h with the float error in units of
  its sigma per axis (the float static sigma was once 28x too small at 6 h); the share of epoch-axis errors
  within 3 sigma, fixed after the first fix and float after 2 h (>= 95 %);
- kinematic: time to first fix (goal <= 15 min), share of epochs fixed after it (>= 90 %), 3-D RMS after it
  (<= 3 cm), wrong fixes (fixed epochs more than 5 cm from the reference, and fixed epochs whose position
  jumps by more than 5 cm from the previous fixed epoch), the share of epoch-axis errors within 3 sigma
  (>= 95 %) for the fixed epochs and for the float solution after 2 h; the troposphere gradients;
- where the kinematic error comes from: the RMS per component after the first fix by 3-h block of the day
  (GPST) and by the number of satellites used;
- re-convergence: the kinematic run with the data cut for 5 min (10 epochs) at each of ``--cuts`` hours,
  the time from the first epoch after the cut to the first fixed one (goal <= 2 min), the jump across the cut
  and the largest difference from the uncut run at the epochs fixed in both in the hour after (a wrong
  integer would show there as centimetres);
- run times (goal <= 30 s for the day on one core).

With ``--up-budget`` it prints instead the static fixed final error with each candidate source of the shared
up bias changed (elevation mask, receiver antenna variations set to zero, GPS alone, phase wind-up off, a
hydrostatic delay 10 hPa heavier), and the factor on the receiver's ionosphere-free variations that would
cancel the up error at each mask (docs/ppp.md, "Ambiguity resolution"): about 4 min on one core.

``--ppp NAME=VALUE`` changes a ``PppOptions`` field (e.g. ``--ppp gradients=0`` for the filter without
troposphere gradients), ``--option NAME=VALUE`` an ``ArOptions`` field.

Run: ``OPENBLAS_NUM_THREADS=1 python tools/bench_ppp_ar.py [--hours 24] [--cuts 6 12 18] [--up-budget]``
"""

import argparse
import copy
import dataclasses
import os
import time
from pathlib import Path
from unittest import mock

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.frames import C_e_n, ecef_to_geodetic  # noqa: E402
from leosop.gnss import models  # noqa: E402
from leosop.gnss.antex import check_antex, read_antex  # noqa: E402
from leosop.gnss.ar import ArOptions  # noqa: E402
from leosop.gnss.etrf import decimal_year, etrf2000_to_itrf2014  # noqa: E402
from leosop.gnss.ppp import PppOptions, run_ppp  # noqa: E402
from leosop.gnss.products import read_clk, read_sp3  # noqa: E402
from leosop.gnss.rinex import read_obs  # noqa: E402

DAY = Path(__file__).resolve().parents[2] / "shared" / "data" / "rinex" / "esbc_2020-177"
OBS = DAY / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"
SP3 = DAY / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz"
CLK = DAY / "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz"
ATX = DAY / "esbc_2020-177.atx"
CODES = {"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]}
WRONG_FIX_M = 0.05
CUT_EPOCHS = 10  # 5 min of 30 s epochs


def select(obs, keep):
    """The observation file restricted to the epochs ``keep`` (bool or index array)."""
    return dataclasses.replace(obs, time_gps=obs.time_gps[keep], obs={k: v[keep] for k, v in obs.obs.items()},
                               lli={k: v[keep] for k, v in obs.lli.items()})


def options(cls, pairs):
    """``cls`` with the fields of ``NAME=VALUE`` strings (booleans as 0/1)."""
    kw = {}
    for k, v in (p.split("=") for p in pairs):
        t = type(getattr(cls(), k))
        kw[k] = bool(int(v)) if t is bool else t(v)
    return cls(**kw)


def breakdown(t_s, enu_m, after, n_used):
    """RMS [cm] per ENU component after the first fix, by 3-h block and by satellites used."""
    hour = t_s / 3600.0
    groups = [(f"{h:2d}-{h + 3:2d} h", after & (hour >= h) & (hour < h + 3)) for h in range(0, 24, 3)]
    groups += [(f"{lo:2d}-{hi:2d} sats", after & (n_used >= lo) & (n_used <= hi))
               for lo, hi in ((5, 9), (10, 12), (13, 15), (16, 18), (19, 40))]
    for label, m in groups:
        if m.sum() >= 10:
            rms = 100 * np.sqrt(np.mean(enu_m[m] ** 2, axis=0))
            print(f"           {label}: {int(m.sum()):4d} epochs, RMS ENU {np.round(rms, 2).tolist()} cm, 3-D "
                  f"{np.linalg.norm(rms):.2f}, mean up {100 * enu_m[m, 2].mean():+.2f} cm")


def within_3_sigma(label, fixed, flt):
    """Print the share of epoch-axis errors within 3 sigma; ``fixed``, ``flt``: (enu (n, 3), sigma (n, 3), mask)."""
    parts = []
    for name, (enu_m, sigma_m, sel) in (("fixed", fixed), ("float after 2 h", flt)):
        inside = np.abs(enu_m[sel]) <= 3.0 * sigma_m[sel]
        parts.append(f"{name} {100 * inside.mean():.1f} % (ENU {np.round(100 * inside.mean(axis=0), 1).tolist()}, "
                     f"{int(sel.sum())} epochs)")
    print(f"{'':11s}{label} within 3 sigma: {'; '.join(parts)}")


def up_budget(obs, orb, clk, atx, aro, no_ar, ref, C, ppo):
    """Static fixed final ENU error [cm] with each candidate source of the up bias changed, one run each."""
    no_pcv = copy.deepcopy(atx)
    rx = no_pcv.receiver(obs.antenna_type)
    rx.pcv_m = {k: np.zeros_like(v) for k, v in rx.pcv_m.items()}
    zhd = models.saastamoinen_zhd_m
    # The hydrostatic delay is linear in the pressure: 10 hPa more adds the delay of 10 hPa.
    heavier = {"saastamoinen_zhd_m": lambda lat, alt, p=None: zhd(lat, alt, p) + zhd(lat, alt, 10.0)}
    no_windup = {"windup_cycles": lambda RS, *args: np.zeros(RS.shape[:2])}
    cases = [(f"mask {m} deg", {"mask_deg": m}, atx, {}) for m in (10.0, 15.0, 20.0)]
    cases += [(f"mask {m} deg, receiver PCV zero", {"mask_deg": m}, no_pcv, {}) for m in (10.0, 15.0, 20.0)]
    cases += [("GPS alone", {"systems": "G"}, atx, {}), ("phase wind-up off", {}, atx, no_windup),
              ("hydrostatic delay of 10 hPa more", {}, atx, heavier)]
    up = {}
    for label, kw, antex, patches in cases:
        with mock.patch.dict(vars(models), patches):
            res = run_ppp(obs, orb, clk, dataclasses.replace(ppo, static=True, **kw), antex, ar=aro, no_ar=no_ar)
        k = np.flatnonzero(np.isfinite(res.pos_ecef_m).all(axis=1))[-1]
        enu = 100 * C.T @ (res.pos_ecef_m[k] - ref)
        up[label] = enu[2]
        print(f"{label:36s} final ({'fixed' if res.fixed[k] else 'float'}) ENU {np.round(enu, 2).tolist()} cm, "
              f"3-D {np.linalg.norm(enu):.2f} cm", flush=True)
    for m in (10.0, 15.0, 20.0):
        base, zero = up[f"mask {m} deg"], up[f"mask {m} deg, receiver PCV zero"]
        print(f"mask {m:g} deg: the receiver PCV moves the up by {base - zero:+.2f} cm; {zero / (zero - base):.2f} "
              "times it would cancel the up error")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--cuts", type=float, nargs="*", default=[6.0, 12.0, 18.0], help="hours of the 5-min data cuts")
    ap.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                    help="an ArOptions field (repeatable)")
    ap.add_argument("--ppp", action="append", default=[], metavar="NAME=VALUE",
                    help="a PppOptions field (repeatable; booleans 0/1)")
    ap.add_argument("--up-budget", action="store_true", help="the static up error's candidate sources instead")
    a = ap.parse_args()
    aro, ppo = options(ArOptions, a.option), options(PppOptions, a.ppp)
    t0 = time.perf_counter()
    obs = read_obs(OBS, codes=CODES)
    orb, clk, atx = read_sp3(SP3), read_clk(CLK), read_antex(ATX)
    t_read = time.perf_counter() - t0
    obs = select(obs, slice(0, int(round(a.hours * 120))))
    notes, no_ar = check_antex(atx, obs.antenna_type, obs.sv, obs.time_gps[0].astype("datetime64[D]"),
                               clk.pcvs_applied)
    ref = etrf2000_to_itrf2014(obs.approx_pos_ecef_m, decimal_year(obs.time_gps[len(obs.time_gps) // 2]))
    C = C_e_n(*ecef_to_geodetic(ref)[:2])
    print(f"read {t_read:.1f} s; reference ITRF2014 {np.round(ref, 4).tolist()}; not fixed: {', '.join(no_ar)}")
    if a.up_budget:
        up_budget(obs, orb, clk, atx, aro, no_ar, ref, C, ppo)
        return

    def run(o, static):
        t = time.perf_counter()
        res = run_ppp(o, orb, clk, dataclasses.replace(ppo, static=static), atx, ar=aro, no_ar=no_ar)
        t_s = (res.time_gps - res.time_gps[0]).astype("timedelta64[s]").astype(float)
        return res, t_s, time.perf_counter() - t

    res, t_s, dt = run(obs, True)
    ok = np.isfinite(res.pos_ecef_m).all(axis=1)
    e = res.pos_ecef_m - ref
    k = np.flatnonzero(ok)[-1]
    print(f"static: final ({'fixed' if res.fixed[k] else 'float'}) 3-D error {100 * np.linalg.norm(e[k]):.2f} cm, "
          f"ENU {np.round(100 * C.T @ e[k], 2).tolist()} cm, sigma {np.round(100 * res.sigma_enu_m[k], 2).tolist()}"
          f" cm; float {100 * np.linalg.norm(res.pos_float_ecef_m[k] - ref):.2f} cm; run {dt:.1f} s")
    if np.isfinite(res.grad_ne_m[k]).all():
        print(f"        troposphere gradients N / E at the end {np.round(1000 * res.grad_ne_m[k], 2).tolist()} mm")
    e_flt = (res.pos_float_ecef_m - ref) @ C
    for h in (1, 3, 6, 12, 24):
        i = np.flatnonzero(ok & (t_s < 3600 * h))
        if i.size and t_s[i[-1]] >= 3600 * h - 1800:  # the day's last epoch is at 23.8 h
            i = i[-1]
            print(f"        at {t_s[i] / 3600:4.1f} h: 3-D {100 * np.linalg.norm(e[i]):.2f} cm "
                  f"({'fixed' if res.fixed[i] else 'float'}), ENU {np.round(100 * C.T @ e[i], 2).tolist()} cm; "
                  f"float ENU {np.round(100 * e_flt[i], 2).tolist()} cm = "
                  f"{np.round(e_flt[i] / res.sigma_float_enu_m[i], 2).tolist()} sigma")
    within_3_sigma("static", (e @ C, res.sigma_enu_m, ok & res.fixed & (t_s >= t_s[np.argmax(res.fixed)])),
                   (e_flt, res.sigma_float_enu_m, ok & (t_s >= 7200.0)))

    res, t_s, dt = run(obs, False)
    ok = np.isfinite(res.pos_ecef_m).all(axis=1)
    enu = (res.pos_ecef_m - ref) @ C
    first = np.flatnonzero(res.fixed)[0]
    after = ok & (t_s >= t_s[first])
    fx = after & res.fixed
    e3 = np.linalg.norm(enu, axis=1)
    jumps = np.linalg.norm(np.diff(res.pos_ecef_m[fx], axis=0), axis=1)
    print(f"kinematic: first fix after {t_s[first] / 60:.1f} min; fixed {100 * res.fixed[after].mean():.1f} % of "
          f"the epochs after it; 3-D RMS after it {100 * np.sqrt(np.mean(e3[after] ** 2)):.2f} cm (ENU "
          f"{np.round(100 * np.sqrt(np.mean(enu[after] ** 2, axis=0)), 2).tolist()}, mean "
          f"{np.round(100 * enu[after].mean(axis=0), 2).tolist()} cm); run {dt:.1f} s")
    print(f"           fixed epochs more than 5 cm off: {int(np.sum(e3[fx] > WRONG_FIX_M))} of {int(fx.sum())} "
          f"(largest {100 * e3[fx].max():.1f} cm); jumps > 5 cm between fixed epochs: "
          f"{int(np.sum(jumps > WRONG_FIX_M))} (largest {100 * jumps.max():.1f} cm)")
    within_3_sigma("kinematic", (enu, res.sigma_enu_m, fx),
                   ((res.pos_float_ecef_m - ref) @ C, res.sigma_float_enu_m, ok & (t_s >= 7200.0)))
    print(f"           median fixed sigma ENU {np.round(100 * np.median(res.sigma_enu_m[fx], axis=0), 2).tolist()} cm")
    kin = res
    g = 1000 * res.grad_ne_m[ok]
    if np.isfinite(g).all():
        print(f"           troposphere gradients N / E: mean {np.round(g.mean(axis=0), 2).tolist()} mm, "
              f"std {np.round(g.std(axis=0), 2).tolist()} mm")
    breakdown(t_s, enu, after, res.n_used)

    for h in a.cuts:
        c0 = int(round(h * 120))
        if c0 + CUT_EPOCHS >= len(obs.time_gps):
            continue
        keep = np.ones(len(obs.time_gps), bool)
        keep[c0:c0 + CUT_EPOCHS] = False
        res, t_s, _ = run(select(obs, keep), False)
        was_fixed = bool(res.fixed[c0 - 1])
        after = np.flatnonzero(res.fixed[c0:])
        e3 = np.linalg.norm(res.pos_ecef_m[c0:] - ref, axis=1)
        gap_s = t_s[c0] - t_s[c0 - 1]
        # A wrong integer after the cut would move the fixed position away from the uncut run's at the same
        # epochs (a narrow-lane cycle is 10.7 cm of range); the jump across the cut is the wrong-fix test.
        hour = after[after < 120]
        both = kin.fixed[keep][c0:][hour]
        d_uncut = np.linalg.norm(res.pos_ecef_m[c0:][hour[both]] - kin.pos_ecef_m[keep][c0:][hour[both]], axis=1)
        jump = np.linalg.norm(res.pos_ecef_m[c0 + after[0]] - res.pos_ecef_m[c0 - 1]) if after.size else np.nan
        print(f"cut at {h:g} h ({gap_s:.0f} s between epochs; fixed before: {was_fixed}): fixed again "
              + (f"{t_s[c0 + after[0]] - t_s[c0]:.0f} s after the first epoch back, 3-D error then "
                 f"{100 * e3[after[0]]:.1f} cm, jump across the cut {100 * jump:.1f} cm, largest fixed error in the "
                 f"next hour {100 * np.nanmax(e3[hour]):.1f} cm, largest difference from the uncut run there "
                 f"{100 * d_uncut.max():.2f} cm ({both.sum()} epochs fixed in both)" if after.size else "never"))


if __name__ == "__main__":
    main()
