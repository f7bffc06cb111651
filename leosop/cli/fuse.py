"""``leosop fuse``: a real IMU log fused with GNSS fixes and LEO Doppler (DESIGN 4.1, 4.5), simulated outages scored.

JSON (all present): ``n_epochs``, ``duration_s``, ``aids`` (used per kind),
``outages`` (``start_s``, ``duration_s``, ``max_horiz_err_m``,
``end_horiz_err_m``, ``n_ref``, ``n_inside_3sigma``), ``runtime_s``; and
``aids_rejected``, ``reference`` (``"Q=1"`` or ``"all withheld"``), ``mean_max_horiz_err_m``,
``worst_max_horiz_err_m``, ``inside_3sigma_fraction``, ``yaw_aligned_s``, ``imu``, ``gnss``, and with
``--leo``/``--leo-sim`` ``leo`` (``source``, ``n_rows``, ``n_sats``, ``coupling``, per receiver clock the final
``offset_hz``, ``drift_hz_per_s``, ``offset_sigma_hz``); with ``--leo-base`` ``leo`` also has ``base``
(``source``, ``n_rows``, ``n_sats``, ``site``: lat, lon [deg], alt [m]) and ``carrier`` (the rover's and the
base's tables both have ``phase_cycles``), its ``clocks`` the rover-minus-base offset ``rover-base``.
``--out``: ``solution.pos`` (RTKLIB, the antenna at every INS update: half the
IMU rate), ``solution.csv``, ``solution.geojson`` (the track at 10 Hz at most,
its dead-reckoning stretches, the withheld fixes), ``fuse.json``, ``track.png``, ``outage_errors.png``
(with outages), ``biases.png``, and with ``--leo-sim`` ``leo_measurements.csv`` (DESIGN 4.3, with the
satellite states: ``--leo`` reads it back); all or none.
"""

import sys
import time
from pathlib import Path

import numpy as np

from .. import frames
from ..apps import fuse_leo
from ..apps.export import Layer, to_geojson
from ..constellations import REGISTRY
from ..errors import InputError
from ..fileio import atomic_outputs, check_input_file, write_csv, write_json
from ..fusion import real
from ..fusion.aids_leo import LeoOptions
from ..gnss import rtklib_pos
from ..ins import flight_mat, imu_io
from ..positioning.measurements import write_measurements
from ..progress import progress
from ..rotations import dcm_to_euler, heading_from_yaw, quat_to_dcm
from . import add_command
from .options import parse_site, parse_span

IMU_FORMATS = ("rtklib-csv", "rtklib-sf-csv", "csv", "psins", "flight-mat")
#: The GeoJSON track keeps at most this many epochs per second (the INS updates are at half the IMU rate).
GEOJSON_RATE_HZ = 10.0
#: Prior sigma of the accelerometer scale factors with --gyro-error-sigma (a MEMS part's +-1-3 %).
ACCEL_SCALE_SIGMA = 0.01


def register(subparsers):
    p = add_command(subparsers, "fuse", sys.modules[__name__],
                    help="fuse a real IMU log with GNSS fixes (RTKLIB .pos) and LEO Doppler; score simulated outages")
    p.add_argument("--imu", required=True, metavar="FILE", help="IMU log")
    p.add_argument("--imu-format", choices=IMU_FORMATS,
                   help="rtklib-csv (raw CSV with FILE.tag), rtklib-sf-csv (its converted _sf.csv), csv with "
                        "--imu-columns, psins (PSINS .imu text; no absolute time, so --gnss cannot meet it), or "
                        "flight-mat (the Gebre-Egziabher flight_data.mat, whose GPS is the aid without --gnss) "
                        "(default: rtklib-csv when FILE.tag exists, else rtklib-sf-csv)")
    p.add_argument("--imu-columns", metavar="MAP",
                   help="for --imu-format csv: NAME=COLUMN,... (0-based), names with units, e.g. "
                        "t_gpst_s=0,ax_g=1,ay_g=2,az_g=3,gx_deg_per_s=4,gy_deg_per_s=5,gz_deg_per_s=6")
    p.add_argument("--gnss", metavar="FILE.pos", help="RTKLIB solution file (GPST, lat/lon form)")
    p.add_argument("--leo", metavar="MEAS.csv",
                   help="LEO Doppler aids (DESIGN 4.3, e.g. leosop replay's measurements.csv); a table with t_s only "
                        "is on the clock of --outage")
    p.add_argument("--leo-sim", action="store_true",
                   help="LEO Doppler simulated along the Q=1 epochs of --gnss (simulate's measurement level), "
                        "continuing through the outages")
    p.add_argument("--leo-base", metavar="BASE.csv",
                   help="a base station's table of the same satellites (DESIGN 4.3, e.g. replay --base's "
                        "base_measurements.csv; with --base-site): --leo's rows less the base's corrections as "
                        "differential aids, and with phase_cycles in both tables the differential carrier aid")
    p.add_argument("--base-site", metavar="LAT_DEG,LON_DEG,ALT_M", help="the base's known position (with --leo-base)")
    p.add_argument("--tle", metavar="FILE",
                   help="element sets: the satellite states of a --leo table without state columns, or the sky of "
                        "--leo-sim (default the bundled one)")
    p.add_argument("--constellation", nargs="+", metavar="NAME", choices=tuple(REGISTRY),
                   help="transmitting families of --leo-sim (default starlink)")
    p.add_argument("--leo-window-s", type=float, metavar="S",
                   help="model each LEO Doppler as the antenna's mean velocity over an integration of S seconds "
                        "centred on its time (0: the velocity at its time); default 0 for --leo, and for --leo-sim "
                        f"its rows' own integration, {fuse_leo.SIM_WINDOW_S:g} s")
    p.add_argument("--coupling", choices=("loose", "tight"), default="tight",
                   help="LEO coupling: tight (each Doppler an aid, default); loose is not yet supported")
    p.add_argument("--outage", action="append", default=[], metavar="START_S,DURATION_S",
                   help="withhold the GNSS aids from START_S for DURATION_S (seconds after the first GNSS epoch); "
                        "repeatable")
    p.add_argument("--zupt", action="store_true", help="zero-velocity and zero-rate updates when the IMU is at rest")
    p.add_argument("--nhc", action="store_true", help="non-holonomic constraint (a wheeled vehicle)")
    p.add_argument("--walking-speed", action="store_true",
                   help="a pedestrian keeps the pace of the last 5 s of GNSS where GNSS is missing (hand-held IMU)")
    p.add_argument("--course-yaw", metavar="MIN_SPEED_MPS,SIGMA_DEG",
                   help="yaw from the course over ground at the first GNSS speed of at least MIN_SPEED_MPS, its sigma "
                        "the course's (velocity sigma / speed) and SIGMA_DEG (sideslip, crab) in quadrature, never "
                        "the yaw bank: e.g. 5,10 for an aircraft handled on the ground before launch (default: 1 m/s "
                        "and no sideslip with --nhc, else a bank of yaws at rest)")
    p.add_argument("--gyro-error-sigma", metavar="SCALE,CROSS",
                   help="gyro scale-factor (3) and cross-axis (6) errors as filter states with these prior sigmas "
                        "(fractions, e.g. 0.03,0.03 for a MEMS gyro rated +-3 %% scale, +-2 %% cross-axis; the "
                        "accelerometer scale factors get 0.01); for sustained turns (aircraft)")
    p.add_argument("--mount-rpy-deg", default="0,0,0", metavar="R,P,Y",
                   help="IMU mounting in the forward-right-down vehicle body, as GNSS_IMU's imu_misalign "
                        "(default 0,0,0: the IMU axes are forward-right-down)")
    p.add_argument("--lever-arm-m", default="0,0,0", metavar="F,R,D",
                   help="GNSS antenna minus IMU in the body frame, forward-right-down [m]")
    p.add_argument("--imu-time-offset-s", type=float, default=0.0, metavar="T",
                   help="added to the IMU time tags (the prior of the estimated offset)")
    p.add_argument("--imu-time-offset-sigma-s", type=float, default=0.1, metavar="S",
                   help="prior sigma of the IMU time offset, estimated by the filter (default 0.1; 0: take T as known)")
    p.add_argument("--imu-spec", default="consumer", metavar="FILE|GRADE",
                   help=f"IMU noise: a grade ({', '.join(real.GRADES)}; default consumer) or a JSON file with "
                        "the fields of leosop.fusion.imu_noise.ImuSpec")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated LEO aids (--leo-sim)")


def _triple(text, option):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not all(np.isfinite(values)):
        raise InputError(f"{option} {text!r}: expected three numbers A,B,C")
    return values


def _offset_sigma(sigma_s):
    if not (np.isfinite(sigma_s) and sigma_s >= 0):
        raise InputError(f"--imu-time-offset-sigma-s {sigma_s!r}: must be a number >= 0")
    return sigma_s or None


def _course_yaw(text):
    if text is None:
        return None
    try:
        speed, sigma = (float(x) for x in text.split(","))
    except ValueError:
        raise InputError(f"--course-yaw {text!r}: expected MIN_SPEED_MPS,SIGMA_DEG") from None
    if not (np.isfinite(speed) and np.isfinite(sigma) and speed > 0 and 0 < sigma <= 180):
        raise InputError(f"--course-yaw {text!r}: MIN_SPEED_MPS must be > 0 and SIGMA_DEG in (0, 180]")
    return speed, sigma


def _gyro_error_sigma(text):
    """``(scale_sigma, gyro_cross_sigma)`` of :class:`leosop.fusion.real.FuseOptions` from ``SCALE,CROSS``."""
    if text is None:
        return None, None
    try:
        scale, cross = (float(x) for x in text.split(","))
    except ValueError:
        raise InputError(f"--gyro-error-sigma {text!r}: expected SCALE,CROSS") from None
    if not (np.isfinite(scale) and np.isfinite(cross) and 0 < scale < 1 and 0 < cross < 1):
        raise InputError(f"--gyro-error-sigma {text!r}: SCALE and CROSS must be fractions in (0, 1)")
    return (scale, ACCEL_SCALE_SIGMA), cross


def _columns(text):
    if not text:
        raise InputError("--imu-format csv needs --imu-columns NAME=COLUMN,...")
    cols = {}
    for item in text.split(","):
        name, _, index = item.partition("=")
        if not index.strip().isdigit():
            raise InputError(f"--imu-columns {item!r}: expected NAME=COLUMN with a column index >= 0")
        cols[name.strip()] = int(index)
    return cols


def read_imu(path, fmt, columns, C_b_s):
    """The IMU log of ``--imu`` in ``--imu-format`` (shared with ``leosop imu``); the flight's GPS too, else None."""
    path = Path(path)
    check_input_file(path, "IMU log (--imu)")
    fmt = fmt or ("rtklib-csv" if Path(f"{path}.tag").exists() else "rtklib-sf-csv")
    if fmt == "flight-mat":
        log, gps, _ = flight_mat.read_flight_mat(path, C_b_s=C_b_s)
        return log, gps
    if fmt == "psins":
        return imu_io.read_psins(path), None
    return _read_text_imu(path, fmt, columns, C_b_s), None


def _read_text_imu(path, fmt, columns, C_b_s):
    if fmt == "rtklib-csv":
        return imu_io.read_rtklib_csv(path, C_b_s=C_b_s)
    if fmt == "rtklib-sf-csv":
        return imu_io.read_rtklib_sf_csv(path, C_b_s=C_b_s)
    return imu_io.read_csv_columns(path, _columns(columns), C_b_s=C_b_s)


def run(args):
    if args.leo and args.leo_sim:
        raise InputError("--leo and --leo-sim exclude each other")
    if args.tle and not (args.leo or args.leo_sim):
        raise InputError("--tle goes with --leo or --leo-sim")
    if args.constellation and not args.leo_sim:
        raise InputError("--constellation goes with --leo-sim")
    if (args.leo_base is None) != (args.base_site is None):
        raise InputError("--leo-base needs --base-site, the base's known position" if args.leo_base else
                         "--base-site goes with --leo-base, the base's measurement table")
    if args.leo_base and not args.leo:
        raise InputError("--leo-base goes with --leo, the rover's measurement table")
    if args.leo_base and args.leo_window_s:
        raise InputError("--leo-window-s does not go with --leo-base (the differential aids take each Doppler at its "
                         "time)")
    if args.leo_window_s is not None and not (args.leo or args.leo_sim):
        raise InputError("--leo-window-s goes with --leo or --leo-sim")
    if args.leo_window_s is not None and not args.leo_window_s >= 0.0:
        raise InputError(f"--leo-window-s {args.leo_window_s}: expected an integration time >= 0 [s]")
    if args.coupling == "loose" and (args.leo or args.leo_sim):
        raise InputError("--coupling loose (LEO snapshot fixes as aids) is not yet supported; use tight")
    if not args.gnss and args.imu_format != "flight-mat":
        raise InputError("--gnss FILE.pos is required (the only aid source so far; flight-mat carries its GPS)")
    if args.imu_columns and args.imu_format != "csv":
        raise InputError("--imu-columns goes with --imu-format csv")
    if args.leo_base:
        site = parse_site(args.base_site, "--base-site")
        check_input_file(Path(args.leo_base), "base measurement file (--leo-base)")
    mount = _triple(args.mount_rpy_deg, "--mount-rpy-deg")
    f, r, d = _triple(args.lever_arm_m, "--lever-arm-m")
    outages = tuple(parse_span(t, "--outage") for t in args.outage)
    scale_sigma, cross_sigma = _gyro_error_sigma(args.gyro_error_sigma)
    options = real.FuseOptions(spec=real.imu_spec(args.imu_spec), outages=outages,
                               lever_arm_b_m=(r, f, -d), zupt=args.zupt, nhc=args.nhc,
                               walking_speed=args.walking_speed,
                               time_offset_sigma_s=_offset_sigma(args.imu_time_offset_sigma_s),
                               course_yaw=_course_yaw(args.course_yaw), scale_sigma=scale_sigma,
                               gyro_cross_sigma=cross_sigma)
    if args.gnss:
        check_input_file(Path(args.gnss), "GNSS solution file (--gnss)")
    sol = rtklib_pos.read_pos(args.gnss) if args.gnss else None
    log, gps = read_imu(args.imu, args.imu_format, args.imu_columns, imu_io.mount_C_b_s(*mount))
    sol = sol or gps
    t_start = time.perf_counter()
    leo = base = None
    if args.leo:
        leo = fuse_leo.read(args.leo, sol, tle=args.tle)
    elif args.leo_sim:
        try:
            leo = fuse_leo.simulate(sol, tle=args.tle, constellations=tuple(args.constellation or ("starlink",)),
                                     seed=args.seed)
        except InputError as exc:  # the library's message does not know its aids are --leo-sim's
            raise InputError(f"--leo-sim: {exc}", param=exc.params) from exc
    window_s = args.leo_window_s
    if window_s is None:  # --leo-sim's rows are means over its chord; a table's are taken as instantaneous
        window_s = fuse_leo.SIM_WINDOW_S if args.leo_sim else 0.0
    if args.leo_base:
        site_ecef_m = frames.geodetic_to_ecef(np.radians(site[0]), np.radians(site[1]), site[2])
        base = fuse_leo.read(args.leo_base, sol, tle=args.tle, site_ecef_m=site_ecef_m)
        leo_aids = fuse_leo.to_differential_aids(leo, base, sol, site_ecef_m, options.lever_arm_b_m)
    else:
        leo_aids = [] if leo is None else fuse_leo.to_aids(leo, sol, options.lever_arm_b_m,
                                                            LeoOptions(window_s=window_s or None))[0]
    fused = real.fuse(log, sol, options, imu_time_offset_s=args.imu_time_offset_s, extra_aids=leo_aids,
                      progress=lambda it: progress(it, desc="fuse", unit="update"))
    outages, reference = real.outage_errors(fused, sol, options)
    runtime = time.perf_counter() - t_start
    doc = _document(fused, sol, log, outages, reference, runtime, args)
    if leo is not None:
        doc["leo"] = _leo_summary(leo, fused.result, args)
    if base is not None:
        doc["leo"]["base"] = {"source": base.source, "n_rows": len(base), "n_sats": int(np.unique(base.sat_id).size),
                              "site": list(site)}
        doc["leo"]["carrier"] = leo.phase_cycles is not None and base.phase_cycles is not None
    if args.out:
        _write(args.out, fused, sol, outages, doc, leo if args.leo_sim else None)
    return doc


def _leo_summary(leo, res, args):
    clocks = {k.partition(":")[2]: {"offset_hz": float(x[0]), "drift_hz_per_s": float(x[1]),
                                    "offset_sigma_hz": float(sd[0])}
              for k, (x, sd) in res.states.items() if k.startswith("leo_clock:")}
    if "diff_clock" in res.states:
        x, sd = res.states["diff_clock"]
        clocks["rover-base"] = {"offset_hz": float(x[0]), "drift_hz_per_s": float(x[1]),
                                "offset_sigma_hz": float(sd[0])}
    return {"source": leo.source, "n_rows": len(leo), "n_sats": int(np.unique(leo.sat_id).size),
            "coupling": args.coupling, "clocks": clocks}


def _document(fused, sol, log, outages, reference, runtime, args):
    res = fused.result
    scored = [o for o in outages if o["n_ref"]]
    n_ref = sum(o["n_ref"] for o in scored)
    maxima = [o["max_horiz_err_m"] for o in scored]
    keys = ("start_s", "duration_s", "max_horiz_err_m", "end_horiz_err_m", "n_ref", "n_inside_3sigma")
    return {
        "n_epochs": int(res.t_s.size), "duration_s": float(res.t_s[-1] - res.t_s[0]),
        "aids": {k: int(v[0]) for k, v in res.aids.items()},
        "aids_rejected": {k: int(v[1]) for k, v in res.aids.items()},
        "outages": [{k: o[k] for k in keys} for o in outages],
        "reference": reference,
        "mean_max_horiz_err_m": float(np.mean(maxima)) if maxima else None,
        "worst_max_horiz_err_m": float(np.max(maxima)) if maxima else None,
        "inside_3sigma_fraction": sum(o["n_inside_3sigma"] for o in scored) / n_ref if n_ref else None,
        "yaw_aligned_s": res.yaw_aligned_s,
        "imu": {"source": log.source, "format": log.metadata["format"], "rate_hz": log.rate_hz,
                "n_samples": int(log.t_s.size), "time_offset_s": args.imu_time_offset_s,
                "time_offset_estimated_s": args.imu_time_offset_s - float(res.time_offset_s[-1]),
                "time_offset_sigma_s": float(res.sigma[-1, -1]) if args.imu_time_offset_sigma_s else None},
        "gnss": {"source": sol.source, "n_epochs": int(sol.t_gpst_s.size), "n_fix": int((sol.q == 1).sum()),
                 "n_withheld": int(fused.withheld.sum())},
        "runtime_s": runtime,
    }


def _solution(fused):
    res = fused.result
    return rtklib_pos.PosSolution(fused.t0_gpst_s + res.t_s, fused.lat_deg, fused.lon_deg, fused.alt_m, fused.q,
                                  np.zeros(res.t_s.size, dtype=int), res.cov_pos_enu_m2, res.vel_enu_mps,
                                  res.cov_vel_enu_m2ps2, "leosop fuse")


def _geojson(fused, sol):
    """Layers: the fused antenna track (at most GEOJSON_RATE_HZ), its dead-reckoning stretches, the withheld fixes."""
    t = fused.result.t_s
    keep = np.r_[True, np.diff(np.floor(t * GEOJSON_RATE_HZ)) > 0]
    dr = np.where(fused.q[keep] == rtklib_pos.Q_DR, 1.0, np.nan)
    lat, lon, alt = fused.lat_deg[keep], fused.lon_deg[keep], fused.alt_m[keep]
    w = fused.withheld
    return to_geojson([
        Layer("fused", "track", lat, lon, alt, properties={"source": "leosop fuse"}),
        Layer("dead reckoning (GNSS withheld)", "track", lat * dr, lon * dr, alt * dr),
        Layer("withheld GNSS fixes (reference)", "points", sol.lat_deg[w], sol.lon_deg[w], sol.alt_m[w],
              point_properties=[{"q": int(q)} for q in sol.q[w]]),
    ])


def _write(out_dir, fused, sol, outages, doc, leo_sim):
    from ..plots import fuse as plots

    res = fused.result
    pitch, roll, yaw = dcm_to_euler(quat_to_dcm(res.q_n_b))
    sd = np.sqrt(np.diagonal(res.cov_pos_enu_m2, axis1=1, axis2=2))
    header = ["t_s", "lat_deg", "lon_deg", "alt_m", "vel_e_mps", "vel_n_mps", "vel_u_mps", "roll_deg", "pitch_deg",
              "heading_deg", "sigma_e_m", "sigma_n_m", "sigma_u_m", "gyro_bias_r_deg_per_s", "gyro_bias_f_deg_per_s",
              "gyro_bias_u_deg_per_s", "accel_bias_r_mps2", "accel_bias_f_mps2", "accel_bias_u_mps2", "q"]
    table = np.column_stack([res.t_s, fused.lat_deg, fused.lon_deg, fused.alt_m, res.vel_enu_mps,
                             np.degrees(roll), np.degrees(pitch), np.degrees(heading_from_yaw(yaw)), sd,
                             np.degrees(res.gyro_bias_rad_per_s), res.accel_bias_mps2, fused.q])
    fmt = ["%.3f", "%.9f", "%.9f", "%.4f"] + ["%.5f"] * 15 + ["%d"]
    rows = [[f % v for f, v in zip(fmt, row)] for row in table]
    title = Path(doc["imu"]["source"]).name
    with atomic_outputs(out_dir) as stage:
        rtklib_pos.write_pos(stage / "solution.pos", _solution(fused), comments=(
            "leosop fuse: the GNSS antenna from the INS at every INS update; Q 7 = dead reckoning",
            f"imu {doc['imu']['source']}, gnss {doc['gnss']['source']}"))
        write_csv(stage / "solution.csv", header, rows)
        write_json(stage / "solution.geojson", _geojson(fused, sol), compact=True)
        write_json(stage / "fuse.json", doc)
        plots.track(stage / "track.png", fused, sol, title)
        if any(o["n_ref"] for o in outages):
            plots.outage_errors(stage / "outage_errors.png", outages, title)
        plots.biases(stage / "biases.png", res)
        if leo_sim is not None:
            write_measurements(stage / "leo_measurements.csv", leo_sim)


def summary(doc):
    lines = [f"fused {doc['duration_s']:.1f} s ({doc['n_epochs']} epochs) in {doc['runtime_s']:.1f} s; aids used: "
             + ", ".join(f"{k} {v}" for k, v in doc["aids"].items())]
    for o in doc["outages"]:
        if o["n_ref"]:
            lines.append(f"  outage {o['start_s']:7.1f} s + {o['duration_s']:4.1f} s: "
                         f"max {o['max_horiz_err_m']:.2f} m, end {o['end_horiz_err_m']:.2f} m, "
                         f"{o['n_inside_3sigma']}/{o['n_ref']} inside 3 sigma")
        else:
            lines.append(f"  outage {o['start_s']:7.1f} s + {o['duration_s']:4.1f} s: no reference epoch")
    if doc["mean_max_horiz_err_m"] is not None:
        lines.append(f"mean of the maxima {doc['mean_max_horiz_err_m']:.2f} m, "
                     f"worst {doc['worst_max_horiz_err_m']:.2f} m, "
                     f"{100 * doc['inside_3sigma_fraction']:.1f} % inside 3 sigma (reference {doc['reference']})")
    return "\n".join(lines)
