"""Benchmark: ``leosop fuse``'s filter beside rtklibexplorer/GNSS_IMU on the real drive and walk, same outages.

For each log (``../shared/data/gnss-ins/rtklibexplorer_drive_0708`` and
``_walk_0827``) and each outage length (GNSS_IMU's default 15 s, and 30 s),
the outages follow GNSS_IMU's schedule (first at its ``start_coast`` after
the first GNSS epoch, one every three outage lengths, none after
``end_coast`` before the end). Both filters run forward; the peer runs from
a temporary copy of ``../shared/anchors/gnss_imu`` with velocity matching off
(a backward smoothing, not a forward filter) and plots off, on its own
converted IMU file (its ``convert_imu_file.py`` makes the drive's). Both
are scored alike: the horizontal error of the output track, interpolated to
the withheld Q = 1 epochs, maximum per outage.

Our filter reads the raw IMU CSV with its ``.tag``, the mounting, lever arm
and IMU time offset of the peer's configuration files, the ``consumer``
grade, ``--nhc --zupt`` on the drive and ``--zupt --walking-speed`` on the walk.

Usage: ``python tools/bench_fuse.py [--data DIR] [--anchor DIR] [--logs drive walk] [--leo-sim] [--json]``.
Goals (issue 21): mean <= 0.5 x the peer's, worst no worse, >= 95 % of the
withheld-fix errors inside our 3 sigma, run time <= 0.1 x the log.

``--leo-sim``: instead of the peer, our filter GNSS-only beside our filter
with LEO Doppler simulated along the RTK path (``leosop fuse --leo-sim``,
seed 0, bundled Starlink-like sky, tight), same outages; goal: the LEO
run's outage errors <= 0.5 x the GNSS-only run's, >= 95 % inside 3 sigma.
``--leo-exact`` (with ``--leo-sim``): the simulated rows' Doppler replaced by
the exact one of the reference track (no noise, offsets or orbit errors;
sigmas kept), to tell the measurement errors from the rest. ``--leo-window S``
(with ``--leo-sim``): the LEO aids model each Doppler as the mean velocity
over an integration of S seconds (``LeoOptions.window_s``; default the
simulation's own, ``fuse_leo.SIM_WINDOW_S`` = 1 s, as ``leosop fuse
--leo-sim``); 0: the velocity at its time.
"""

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from leosop import frames
from leosop.constants import C_MPS
from leosop.apps import fuse_leo
from leosop.fusion import real
from leosop.fusion.aids_leo import LeoOptions
from leosop.gnss.rtklib_pos import read_pos
from leosop.ins import imu_io

ROOT = Path(__file__).resolve().parents[2]
#: Per log: folder, peer config, peer file stem, our IMU file, mounting (R, P, Y deg), lever arm (F, R, D m),
#: IMU time offset [s], our aids, the peer's start_coast and end_coast [s].
LOGS = {
    "drive": ("rtklibexplorer_drive_0708", "drive_config", "1934_sf", "imu_1934.csv", (180.0, -6.79, 185.35),
              (0.0, -0.05, 0.0), -0.125, {"nhc": True, "zupt": True}, 40.0, 30.0),
    "walk": ("rtklibexplorer_walk_0827", "walk_config", "1730_sf", "imu_1730.csv", (180.0, 0.0, -90.0),
             (0.0, -0.05, 0.0), 0.0, {"zupt": True, "walking_speed": True}, 25.0, 45.0),
}
OUTAGE_LENGTHS_S = (15.0, 30.0)


def schedule(duration_s, start_s, end_s, length_s):
    """GNSS_IMU's outages: ``length_s`` long from ``start_s``, one every ``3 length_s``.

    The schedule is cut at ``duration_s - end_s``.
    """
    last = duration_s - end_s
    return tuple((s, min(length_s, last - s)) for s in np.arange(start_s, last, 3 * length_s))


def _horiz_errors(t_s, lat_deg, lon_deg, alt_m, sol, t0, outages):
    """Max horizontal error per outage of a track against the withheld Q = 1 epochs."""
    pos = frames.geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), alt_m)
    tg = sol.t_gpst_s - t0
    out = []
    for s, d in outages:
        k = np.flatnonzero((tg >= s) & (tg < s + d) & (sol.q == 1))
        if k.size == 0:
            continue
        est = np.stack([np.interp(tg[k], t_s, pos[:, c]) for c in range(3)], axis=-1)
        lat, lon = np.radians(sol.lat_deg[k]), np.radians(sol.lon_deg[k])
        e = frames.ecef_to_enu(est - frames.geodetic_to_ecef(lat, lon, sol.alt_m[k]), lat, lon)
        out.append(float(np.hypot(e[:, 0], e[:, 1]).max()))
    return out


def _exact(meas, sol):
    """``meas`` with the Doppler of :func:`fuse_leo.reference_track` at its rows, no errors."""
    t_s, pos, vel, _ = fuse_leo.reference_track(sol)
    k = np.searchsorted(t_s, meas.t_s)
    rate = frames.range_rate(meas.pos_sv_ecef_m, meas.vel_sv_ecef_mps, pos[k], vel[k])
    return dataclasses.replace(meas, doppler_hz=-rate * meas.carrier_hz / C_MPS)


def ours(data, name, length_s, leo_sim=False, leo_exact=False, leo_window_s=None):
    folder, _, _, imu, mount, (f, r, d), offset, aids, start, end = LOGS[name]
    sol = read_pos(data / folder / f"gnss_{LOGS[name][2]}.pos")
    log = imu_io.read_rtklib_csv(data / folder / imu, C_b_s=imu_io.mount_C_b_s(*mount))
    outages = schedule(sol.t_gpst_s[-1] - sol.t_gpst_s[0], start, end, length_s)
    opts = real.FuseOptions(spec=real.GRADES["consumer"], outages=outages, lever_arm_b_m=(r, f, -d), **aids)
    t = time.perf_counter()
    extra = ()
    if leo_sim:
        meas = fuse_leo.simulate(sol, seed=0)
        extra = fuse_leo.to_aids(_exact(meas, sol) if leo_exact else meas, sol, opts.lever_arm_b_m,
                                  LeoOptions(window_s=leo_window_s or None))[0]
    run = real.fuse(log, sol, opts, imu_time_offset_s=offset, extra_aids=extra)
    errs, _ = real.outage_errors(run, sol, opts)
    runtime = time.perf_counter() - t
    scored = [o for o in errs if o["n_ref"]]
    inside = sum(o["n_inside_3sigma"] for o in scored) / sum(o["n_ref"] for o in scored)
    return {"max_horiz_err_m": [o["max_horiz_err_m"] for o in scored], "inside_3sigma": inside,
            "runtime_s": runtime, "log_s": float(run.result.t_s[-1] - run.result.t_s[0])}, outages


def _read_peer_pos(path):
    """The peer's output: RTKLIB rows with 3 extra attitude columns; GPST date and time -> Unix-style seconds."""
    rows = [ln.split() for ln in Path(path).read_text().splitlines() if ln.strip() and not ln.startswith("%")]
    stamps = np.array([np.datetime64(r[0].replace("/", "-") + "T" + r[1], "ns") for r in rows])
    t = (stamps - np.datetime64("1970-01-01T00:00:00", "ns")) / np.timedelta64(1, "s")
    v = np.array([[float(x) for x in r[2:5]] for r in rows])
    return t, v[:, 0], v[:, 1], v[:, 2]


def peer(data, anchor, name, length_s, outages):
    folder, cfg, stem, imu, *_ = LOGS[name]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src, dat = tmp / "src", tmp / "data"
        shutil.copytree(anchor / "src", src)
        shutil.copytree(data / folder, dat)
        for p in (src / "drive_config.py", src / "walk_config.py"):
            p.chmod(0o644)
            p.write_text(p.read_text() + f"\nvel_match = False\ncoast_len = {length_s}\nplot_results = False\n"
                         "plot_bias_data = False\n")
        env = dict(os.environ, MPLBACKEND="Agg")
        if not (dat / f"imu_{stem}.csv").exists():
            conv = (src / "convert_imu_file.py")
            conv.chmod(0o644)
            text = conv.read_text().replace(r"filepath = r'..\data\drive_0708\imu_1934.csv'",
                                            f"filepath = {str(dat / imu)!r}")
            conv.write_text(text)
            subprocess.run([sys.executable, str(conv)], cwd=src, env=env, check=True, capture_output=True)
        main = src / "GNSS_IMU.py"
        main.chmod(0o644)
        text = main.read_text()
        text = text.replace("import drive_config as cfg\ndataDir = r'..\\data\\drive_0708'\nfileIn = '1934_sf'",
                            f"import {cfg} as cfg\ndataDir = {str(dat)!r}\nfileIn = {stem!r}")
        main.write_text(text)
        t = time.perf_counter()
        subprocess.run([sys.executable, str(main)], cwd=src, env=env, check=True, stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE)
        runtime = time.perf_counter() - t
        sol = read_pos(dat / f"gnss_{stem}.pos")
        t_s, lat, lon, alt = _read_peer_pos(dat / f"gnss_imu_{stem}.pos")
    t0 = sol.t_gpst_s[0]
    return {"max_horiz_err_m": _horiz_errors(t_s - t0, lat, lon, alt, sol, t0, outages), "runtime_s": runtime}


def table(args, run, sides, more, ratio, tail):
    """One row per log and outage length comparing two scored runs; printed line by line, or JSON at the end.

    Parameters
    ----------
    args : argparse.Namespace
        ``logs`` and ``json`` of the command line.
    run : callable
        ``run(name, length_s) -> (a, b)``: the two runs' scores (dicts of :func:`ours` or :func:`peer`).
    sides : tuple of (str, str)
        Column prefix and printed name of ``a`` and of ``b``: each gets ``{prefix}_mean_m`` and
        ``{prefix}_worst_m`` of its per-outage maxima.
    more : callable
        ``more(a, b) -> dict``: the table's further columns, after the means and worsts.
    ratio : tuple of str
        Prefixes of the numerator and denominator of ``mean_ratio``.
    tail : callable
        ``tail(row) -> str``: the printed line after ``ratio``, from its value on.
    """
    (key_a, name_a), (key_b, name_b) = sides
    rows = []
    for name in args.logs:
        for length in OUTAGE_LENGTHS_S:
            a, b = run(name, length)
            row = {"log": name, "outage_s": length, "n_outages": len(a["max_horiz_err_m"])}
            for key, res in ((key_a, a), (key_b, b)):
                row[f"{key}_mean_m"] = float(np.mean(res["max_horiz_err_m"]))
                row[f"{key}_worst_m"] = max(res["max_horiz_err_m"])
            row.update(more(a, b))
            row["mean_ratio"] = row[f"{ratio[0]}_mean_m"] / row[f"{ratio[1]}_mean_m"]
            rows.append(row)
            if not args.json:
                print(f"{name:5s} {length:4.0f} s x{row['n_outages']:2d}: "
                      f"{name_a} mean {row[f'{key_a}_mean_m']:6.2f} m worst {row[f'{key_a}_worst_m']:6.2f} m | "
                      f"{name_b} mean {row[f'{key_b}_mean_m']:6.2f} m worst {row[f'{key_b}_worst_m']:6.2f} m | "
                      f"ratio {tail(row)}", flush=True)
    if args.json:
        print(json.dumps(rows, indent=2))


def _peer_columns(a, b):
    """The peer table's columns beyond the means and worsts: ``a`` ours, ``b`` the peer's."""
    return {"inside_3sigma": a["inside_3sigma"], "ours_runtime_s": a["runtime_s"], "peer_runtime_s": b["runtime_s"],
            "log_s": a["log_s"], "ours_max_m": a["max_horiz_err_m"], "peer_max_m": b["max_horiz_err_m"]}


def _peer_tail(row):
    """The peer table's printed line after ``ratio``."""
    return (f"{row['mean_ratio']:.2f} | inside 3 sigma {100 * row['inside_3sigma']:.0f} % | run "
            f"{row['ours_runtime_s']:.1f} s ({row['ours_runtime_s'] / row['log_s']:.3f} x log), "
            f"peer {row['peer_runtime_s']:.1f} s")


def _leo_columns(a, b):
    """The ``--leo-sim`` table's columns beyond the means and worsts: ``a`` GNSS-only, ``b`` with LEO."""
    return {"gnss_inside_3sigma": a["inside_3sigma"], "leo_inside_3sigma": b["inside_3sigma"],
            "leo_runtime_s": b["runtime_s"], "log_s": b["log_s"], "leo_max_m": b["max_horiz_err_m"]}


def _leo_tail(row):
    """The ``--leo-sim`` table's printed line after ``ratio``."""
    return (f"{row['mean_ratio']:.3f} | inside 3 sigma {100 * row['gnss_inside_3sigma']:.0f} % / "
            f"{100 * row['leo_inside_3sigma']:.0f} % | LEO run {row['leo_runtime_s']:.1f} s "
            f"({row['leo_runtime_s'] / row['log_s']:.3f} x log)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT / "shared" / "data" / "gnss-ins")
    ap.add_argument("--anchor", type=Path, default=ROOT / "shared" / "anchors" / "gnss_imu")
    ap.add_argument("--logs", nargs="+", choices=tuple(LOGS), default=tuple(LOGS))
    ap.add_argument("--leo-sim", action="store_true", help="GNSS-only against GNSS + simulated LEO Doppler")
    ap.add_argument("--leo-exact", action="store_true", help="with --leo-sim: the exact Doppler, no errors")
    ap.add_argument("--leo-window", type=float, metavar="S", default=fuse_leo.SIM_WINDOW_S,
                    help="with --leo-sim: the Doppler as an S s mean (default %(default)s; 0: instantaneous)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.leo_sim:
        def run(name, length):
            return (ours(args.data, name, length)[0],
                    ours(args.data, name, length, leo_sim=True, leo_exact=args.leo_exact,
                         leo_window_s=args.leo_window)[0])

        table(args, run, (("gnss", "GNSS-only"), ("leo", "+LEO sim")), _leo_columns, ("leo", "gnss"), _leo_tail)
    else:
        def run(name, length):
            a, outages = ours(args.data, name, length)
            return a, peer(args.data, args.anchor, name, length, outages)

        table(args, run, (("ours", "ours"), ("peer", "peer")), _peer_columns, ("ours", "peer"), _peer_tail)


if __name__ == "__main__":
    main()
