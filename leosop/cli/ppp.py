"""``leosop ppp OBS --nav NAV --sp3 SP3 --clk CLK``: precise point positioning, float or ambiguity-fixed.

Dual-frequency ionosphere-free code and phase of GPS and Galileo with precise
orbits (SP3) and clocks (RINEX clock), float ambiguities, estimated zenith
wet delay (leosop.gnss.ppp). Without ``--static`` the position is re-estimated
every epoch (kinematic); with ``--static`` it is one constant, and the JSON
``summary`` gives the final position. ``--ar`` fixes the ambiguities with
integer-recovery clocks (CNES/GRG: wide-lane biases in the clock header) and
the satellite antenna offsets they were made with (``--antex``): wide-lane,
then narrow-lane by LAMBDA (leosop.gnss.ar). ``--imu`` (tight PPP/INS) runs on
the simulated vehicle test (``leosop reproduce ppp-ins``); on real files it
stops: no IMU log recorded with the observations can be read yet.
"""

import sys
import time
import warnings

import numpy as np

from ..errors import InputError
from ..fileio import atomic_outputs, write_csv, write_json
from ..frames import C_e_n, ecef_to_geodetic
from ..gnss.antex import check_antex, read_antex
from ..gnss.ar import ArOptions
from ..gnss.etrf import decimal_year, etrf2000_to_itrf2014, itrf2014_to_etrf2000
from ..gnss.ppp import PppOptions, gps_to_utc, run_ppp
from ..gnss.products import read_clk, read_sp3, uncovered_note
from ..gnss.rinex import check_nav, read_obs
from ..plots.ppp import ppp_figure
from ..timebase import format_utc
from . import add_command

_DESCRIPTION = __doc__.split("\n\n")[1].replace("\n", " ")


def register(subparsers):
    p = add_command(subparsers, "ppp", sys.modules[__name__], description=_DESCRIPTION,
                    help="PPP, float or ambiguity-fixed, from RINEX 3 observations, SP3 and CLK")
    p.add_argument("obs", metavar="OBS", help="RINEX 3 observation file (plain, .gz or Hatanaka .crx[.gz])")
    p.add_argument("--nav", metavar="NAV", required=True, help="RINEX 3 navigation file of the same day (checked)")
    p.add_argument("--sp3", metavar="SP3", required=True, help="precise orbits, SP3-c/d")
    p.add_argument("--clk", metavar="CLK", required=True, help="precise satellite clocks, RINEX clock")
    p.add_argument("--antex", metavar="ATX", help="ANTEX antenna calibrations (receiver offset and variations, "
                   "satellite offsets); without it the height is that of the receiver antenna's phase centre and "
                   "the sigmas carry a larger floor")
    p.add_argument("--static", action="store_true", help="receiver at rest: one position for the whole file")
    p.add_argument("--systems", default="GE", help="GNSS letters to use (default %(default)s)")
    p.add_argument("--mask-deg", type=float, metavar="D",
                   help=f"elevation mask (default {PppOptions.mask_deg:g} with the receiver antenna's calibration "
                   f"from --antex, {PppOptions.mask_no_antex_deg:g} without)")
    p.add_argument("--ar", action="store_true", help="ambiguity resolution: wide-lane, then narrow-lane by LAMBDA "
                   "(needs integer-recovery clocks with wide-lane biases, e.g. CNES/GRG, and --antex)")
    p.add_argument("--imu", metavar="FILE", help="IMU log for tight PPP/INS (see 'leosop reproduce ppp-ins')")
    return p


def run(args):
    if args.ar and not args.antex:
        raise InputError(f"--ar: narrow-lane fixing with the integer clocks of {args.clk} needs the satellite antenna "
                         "offsets they were computed with (its SYS / PCVS APPLIED): give them with --antex")
    if args.imu:
        raise InputError(f"--imu {args.imu}: no IMU log recorded with these observations can be read yet; the tight "
                         "PPP/INS filter runs on the simulated vehicle test: leosop reproduce ppp-ins")
    if not set(args.systems) <= {"G", "E"} or not args.systems:
        raise InputError(f"--systems {args.systems!r}: expected letters among G, E")
    if args.mask_deg is not None and not 0.0 <= args.mask_deg < 90.0:
        raise InputError(f"--mask-deg {args.mask_deg!r}: expected a value in [0, 90)")
    t0 = time.perf_counter()
    # The small files first: a bad product fails before the observation file is read.
    nav_day = check_nav(args.nav)
    antex = read_antex(args.antex) if args.antex else None
    orbits = read_sp3(args.sp3, systems=args.systems)
    clocks = read_clk(args.clk, systems=args.systems)
    if args.ar and not clocks.wl_bias_cyc:
        raise InputError(f"{args.clk}: no satellite wide-lane biases (header 'WL' COMMENT records): --ar needs "
                         "integer-recovery clocks such as the CNES/GRG products")
    obs = read_obs(args.obs, systems=args.systems,
                   codes={"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]})
    day = obs.time_gps[0].astype("datetime64[D]")
    if nav_day is not None and abs((nav_day - day).astype(int)) > 1:
        raise InputError(f"{args.nav}: navigation records start {nav_day}, the observations {day}")
    t_read = time.perf_counter() - t0
    print(f"leosop ppp: read {len(obs.time_gps)} epochs in {t_read:.1f} s", file=sys.stderr)
    notes, no_ar = [], {}
    if antex is not None:
        notes, no_ar = check_antex(antex, obs.antenna_type, obs.sv, day, clocks.pcvs_applied)
    notes += [n for n in (uncovered_note(p, obs.time_gps) for p in (orbits, clocks)) if n]
    mask = {} if args.mask_deg is None else {"mask_deg": args.mask_deg, "mask_no_antex_deg": args.mask_deg}
    res = run_ppp(obs, orbits, clocks, PppOptions(static=args.static, systems=args.systems, **mask), antex=antex,
                  ar=ArOptions() if args.ar else None, no_ar=no_ar, show_progress=True)
    if res.no_antenna:
        notes.append(f"{args.antex}: no block valid on {day} for {', '.join(res.no_antenna)}: left out of the "
                     "solution")
    for note in notes:
        warnings.warn(note, stacklevel=1)
    runtime = time.perf_counter() - t0
    times = format_utc(gps_to_utc(res.time_gps))
    lat, lon, alt = ecef_to_geodetic(res.pos_ecef_m)
    sols = []
    for k in np.flatnonzero(np.isfinite(res.pos_ecef_m).all(axis=1)):
        sols.append({"time_utc": times[k], "x_m": res.pos_ecef_m[k, 0], "y_m": res.pos_ecef_m[k, 1],
                     "z_m": res.pos_ecef_m[k, 2], "lat_deg": np.degrees(lat[k]), "lon_deg": np.degrees(lon[k]),
                     "alt_m": alt[k], "fixed": bool(res.fixed[k]), "sigma_enu_m": res.sigma_enu_m[k].tolist(),
                     "zwd_m": res.zwd_m[k], "n_sats": int(res.n_used[k]), "n_fixed": int(res.n_fixed[k])})
    if not sols:
        raise InputError(f"{args.obs}: no epoch with 5 usable satellites")
    summary = {"mode": "static" if args.static else "kinematic", "n_epochs": len(sols), "n_slips": res.n_slips,
               "n_outliers": res.n_outliers, "read_s": t_read, "runtime_s": runtime, "warnings": notes,
               "no_antenna": res.no_antenna}
    if args.ar:
        summary["ar"] = _ar_summary(res, times)
    hdr = obs.approx_pos_ecef_m
    year = decimal_year(obs.time_gps[len(obs.time_gps) // 2])
    C_hdr = C_e_n(*ecef_to_geodetic(hdr)[:2]) if np.any(hdr) else None
    if args.static:
        last = sols[-1]
        summary["position"] = {k: last[k] for k in ("time_utc", "x_m", "y_m", "z_m", "lat_deg", "lon_deg", "alt_m",
                                                      "sigma_enu_m", "fixed")}
        if np.any(hdr):
            pos = np.array([last["x_m"], last["y_m"], last["z_m"]])
            d_ecef = pos - hdr
            # European agencies write the ETRS89 (ETRF2000) coordinate there; ours is ITRF2014 (the products').
            d_etrf = itrf2014_to_etrf2000(pos, year) - hdr
            summary["minus_header_approx_m"] = d_ecef.tolist()  # ECEF X, Y, Z
            summary["minus_header_if_etrf2000_m"] = d_etrf.tolist()
            summary["minus_header_approx_enu_m"] = (d_ecef @ C_hdr).tolist()
            summary["minus_header_if_etrf2000_enu_m"] = (d_etrf @ C_hdr).tolist()
    elif np.any(hdr):
        summary["kinematic_rms"] = _kinematic_rms(res, etrf2000_to_itrf2014(hdr, year), C_hdr)
    doc = {"solutions": sols, "summary": summary}
    if args.out:
        with atomic_outputs(args.out) as stage:
            write_json(stage / "ppp.json", doc)
            ok = np.isfinite(res.pos_ecef_m).all(axis=1)
            ref_pos = res.pos_ecef_m[ok][-1]
            lat0, lon0, _ = ecef_to_geodetic(ref_pos)
            kind = "ambiguity-fixed" if args.ar else "float"
            ppp_figure(res.time_gps[ok], (res.pos_ecef_m[ok] - ref_pos) @ C_e_n(lat0, lon0), res.sigma_enu_m[ok],
                       res.n_used[ok], stage / "ppp.png", n_fixed=res.n_fixed[ok] if args.ar else None,
                       title=f"{obs.marker} {summary['mode']} {kind} PPP, offsets from the final position")
            write_csv(stage / "ppp.csv", ["time_utc", "x_m", "y_m", "z_m", "lat_deg", "lon_deg", "alt_m",
                                         "sigma_e_m", "sigma_n_m", "sigma_u_m", "zwd_m", "n_sats", "fixed", "n_fixed"],
                      [[s["time_utc"], s["x_m"], s["y_m"], s["z_m"], s["lat_deg"], s["lon_deg"], s["alt_m"],
                        *s["sigma_enu_m"], s["zwd_m"], s["n_sats"], int(s["fixed"]), s["n_fixed"]] for s in sols])
    return doc


def _ar_summary(res, times):
    """First fix, share of epochs fixed after it, satellites left out of fixing."""
    ok = np.isfinite(res.pos_ecef_m).all(axis=1)
    first = np.flatnonzero(res.fixed)
    doc = {"n_fixed_epochs": int(res.fixed.sum()), "first_fix_utc": None, "time_to_first_fix_s": None,
           "fixed_fraction_after_first_fix": None, "no_ar": res.no_ar}
    if first.size:
        k = first[0]
        doc["first_fix_utc"] = times[k]
        doc["time_to_first_fix_s"] = float((res.time_gps[k] - res.time_gps[ok][0]) / np.timedelta64(1, "s"))
        doc["fixed_fraction_after_first_fix"] = float(res.fixed[k:][ok[k:]].mean())
    return doc


def _kinematic_rms(res, ref_ecef_m, C_en):
    """RMS of the kinematic positions against a reference: all epochs and those after the first hour."""
    ok = np.isfinite(res.pos_ecef_m).all(axis=1)
    enu = (res.pos_ecef_m[ok] - ref_ecef_m) @ C_en
    t_s = (res.time_gps[ok] - res.time_gps[ok][0]).astype("timedelta64[ms]").astype(float) / 1e3
    doc = {"reference": "header APPROX POSITION taken as ETRF2000, mapped to ITRF2014"}
    for name, sel in (("all", np.ones(len(t_s), bool)), ("after_1h", t_s >= 3600.0)):
        if sel.any():
            doc[name] = {"n_epochs": int(sel.sum()), "rms_3d_m": float(np.sqrt(np.mean(np.sum(enu[sel] ** 2, 1)))),
                         "rms_enu_m": np.sqrt(np.mean(enu[sel] ** 2, axis=0)).tolist()}
    return doc


def _enu(v):
    return " ".join(f"{k} {x:+.4f}" for k, x in zip("ENU", v))


def summary(doc):
    s = doc["summary"]
    kind = "ambiguity-fixed" if "ar" in s else "float"
    lines = [(f"{s['mode']} {kind} PPP: {s['n_epochs']} epochs, {s['n_slips']} cycle slips, "
             f"{s['n_outliers']} outliers, read {s['read_s']:.1f} s, total {s['runtime_s']:.1f} s")]
    if "ar" in s:
        a = s["ar"]
        if a["first_fix_utc"] is None:
            lines.append("no epoch fixed")
        else:
            lines.append(f"first fix {a['first_fix_utc']} ({a['time_to_first_fix_s'] / 60:.1f} min), "
                         f"{100 * a['fixed_fraction_after_first_fix']:.1f} % of the epochs after it fixed")
    if "position" in s:
        p = s["position"]
        lines.append(f"position {p['lat_deg']:.9f} {p['lon_deg']:.9f} {p['alt_m']:.4f} m  "
                     f"ECEF {p['x_m']:.4f} {p['y_m']:.4f} {p['z_m']:.4f}")
        if "minus_header_approx_enu_m" in s:
            d = s["minus_header_approx_enu_m"]
            lines.append(f"minus header APPROX POSITION, ENU: {_enu(d)} m (|d| {np.linalg.norm(d):.3f} m)")
            e = s["minus_header_if_etrf2000_enu_m"]
            lines.append(f"  same in ETRF2000, if the header is an ETRS89 coordinate, ENU: {_enu(e)} m "
                         f"(|d| {np.linalg.norm(e):.3f} m)")
    if "kinematic_rms" in s:
        k = s["kinematic_rms"]
        for name, label in (("all", "all epochs"), ("after_1h", "after the first hour")):
            if name in k:
                r = k[name]
                lines.append(f"RMS against the {k['reference']}, {label} ({r['n_epochs']}): 3-D "
                             f"{r['rms_3d_m']:.3f} m, E {r['rms_enu_m'][0]:.3f} N {r['rms_enu_m'][1]:.3f} "
                             f"U {r['rms_enu_m'][2]:.3f} m")
    return "\n".join(lines)
