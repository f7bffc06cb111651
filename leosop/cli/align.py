"""``leosop align``: static coarse alignment of a real IMU log ([Qu 2024] and Wahba).

Prints ``{"pitch_deg", "roll_deg", "heading_deg", "method"}`` (heading
clockwise from true North in [0, 360), pitch nose up, roll right wing down;
``method`` is the one that ran, ``method_requested`` what was asked, e.g.
``auto``) plus the span used and the motion indicator; ``--window-s W`` adds the
alignment of each successive W-second window (stability check).
"""

import sys
import warnings
from pathlib import Path

import numpy as np

from ..constants import G0_MPS2
from ..errors import InputError
from ..fileio import atomic_outputs, write_csv, write_json
from ..ins import imu_io
from ..ins.alignment import (AUTO_INERTIAL_MIN_S, INCREMENT_METHODS, MotionWarning, align_increments,
                             motion_std_mps2, resolve_method)
from ..rotations import heading_from_yaw
from . import add_command


def register(subparsers):
    p = add_command(subparsers, "align", sys.modules[__name__],
                    help="coarse alignment (pitch, roll, heading) of a static IMU log")
    p.add_argument("--imu", required=True, metavar="FILE", help="IMU log (PSINS .imu text or rtklibexplorer CSV)")
    p.add_argument("--format", choices=("psins", "csv"),
                   help="psins, or csv: rtklibexplorer raw CSV when FILE.tag exists beside it, else its converted "
                        "_sf.csv (default: from the extension)")
    p.add_argument("--lat-deg", type=float, help="latitude [deg] (default: the file's header, PSINS only)")
    p.add_argument("--seconds", type=float, help="use the first S seconds (default: the whole log)")
    p.add_argument("--method", choices=INCREMENT_METHODS, default="auto",
                   help="[Qu 2024] algorithm 1 or 2, the optimal Wahba solution, the inertial-frame alignment "
                        "(robust to rocking; attitude at the end of the span), or auto (default): inertial on "
                        f"spans of {AUTO_INERTIAL_MIN_S:g} s or more, else wahba; the output names the method "
                        "that ran")
    p.add_argument("--window-s", type=float, help="also align every successive window of this length")


def _read(path, fmt):
    path = Path(path)
    if fmt is None:
        fmt = {".imu": "psins", ".csv": "csv"}.get(path.suffix.lower())
        if fmt is None:
            raise InputError(f"--imu {path}: cannot tell the format from the extension; give --format psins|csv")
    if fmt == "psins":
        return imu_io.read_psins(path)
    if Path(f"{path}.tag").exists():
        return imu_io.read_rtklib_csv(path)
    return imu_io.read_rtklib_sf_csv(path)


def _angles_deg(pitch, roll, yaw):
    return {"pitch_deg": float(np.degrees(pitch)), "roll_deg": float(np.degrees(roll)),
            "heading_deg": float(np.degrees(heading_from_yaw(yaw)))}


#: Mean specific force of a static log, as a fraction of g: outside it the log
#: does not hold gravity (all zero, wrong units) and no attitude follows.
_GRAVITY_RANGE = (0.5, 1.5)


def _check_static(path, dtheta, dvel, span_s):
    """Refuse logs without gravity in the accelerometers or without any gyro signal."""
    f_mps2 = float(np.linalg.norm(dvel, axis=1).sum()) / span_s
    if not _GRAVITY_RANGE[0] * G0_MPS2 <= f_mps2 <= _GRAVITY_RANGE[1] * G0_MPS2:
        raise InputError(f"{path}: mean specific force {f_mps2:.4g} m/s^2 is not gravity ({G0_MPS2:.2f} m/s^2): "
                         "not a static log with accelerometers in m/s^2 or g")
    if not np.any(dtheta):
        raise InputError(f"{path}: the gyro increments are all zero (no Earth rate): the heading is undefined")


def run(args):
    log = _read(args.imu, args.format)
    lat_deg = args.lat_deg if args.lat_deg is not None else log.metadata.get("lat_deg")
    if lat_deg is None:
        raise InputError(f"--lat-deg is required: {args.imu} states no latitude")
    if not np.isfinite(lat_deg) or abs(lat_deg) > 90.0:
        raise InputError(f"--lat-deg {lat_deg:g}: latitude must be within [-90, 90]")
    dt = float(np.median(log.dt_s))
    n = log.dt_s.size
    if args.seconds is not None:
        if not (np.isfinite(args.seconds) and args.seconds > 0):
            raise InputError(f"--seconds {args.seconds:g}: must be a positive number")
        if args.seconds > n * dt + dt:
            raise InputError(f"--seconds {args.seconds:g}: the log {args.imu} holds only {n * dt:.1f} s")
        n = min(n, int(round(args.seconds / dt)))
    if n * dt < 1.0:
        raise InputError(f"{args.imu}: at least 1 s of data is needed for an alignment, got {n * dt:.3f} s")
    lat = np.radians(lat_deg)
    dtheta, dvel = log.dtheta_b_rad[:n], log.dvel_b_mps[:n]
    _check_static(args.imu, dtheta, dvel, n * dt)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MotionWarning)
        method = resolve_method(args.method, n * dt)
        pitch, roll, yaw = align_increments(dtheta, dvel, dt, lat, method=method)
    for w in caught:
        print(f"leosop align: warning: {args.imu}: {w.message}", file=sys.stderr)
    doc = {**_angles_deg(pitch, roll, yaw), "method": method, "method_requested": args.method,
           "lat_deg": float(lat_deg), "duration_s": float(n * dt), "motion_std_mps2": motion_std_mps2(dvel, dt)}
    if args.window_s is not None:
        if not 1.0 <= args.window_s <= n * dt:
            raise InputError(f"--window-s {args.window_s:g}: must be between 1 s and the {n * dt:.1f} s aligned")
        m = int(round(args.window_s / dt))
        doc["window_method"] = window_method = resolve_method(args.method, m * dt)
        windows = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MotionWarning)  # reported once for the whole span above
            for k in range(n // m):
                sl = slice(k * m, (k + 1) * m)
                windows.append({"t0_s": float(k * m * dt),
                                **_angles_deg(*align_increments(dtheta[sl], dvel[sl], dt, lat, method=window_method))})
        doc["windows"] = windows
    if args.out:
        with atomic_outputs(args.out) as out:
            write_json(out / "align.json", doc)
            if "windows" in doc:
                write_csv(out / "align_windows.csv", ["t0_s", "pitch_deg", "roll_deg", "heading_deg"],
                          [[w["t0_s"], w["pitch_deg"], w["roll_deg"], w["heading_deg"]] for w in doc["windows"]])
    return doc


def summary(doc):
    chosen = " (auto)" if doc["method_requested"] == "auto" else ""
    lines = [f"method {doc['method']}{chosen}: pitch {doc['pitch_deg']:.4f} deg, roll {doc['roll_deg']:.4f} deg, "
             f"heading {doc['heading_deg']:.3f} deg over {doc['duration_s']:.0f} s"]
    if "windows" in doc:
        lines.append(f"windows (method {doc['window_method']}):")
    for w in doc.get("windows", []):
        lines.append(f"  t0 {w['t0_s']:7.1f} s: pitch {w['pitch_deg']:.4f} roll {w['roll_deg']:.4f} "
                     f"heading {w['heading_deg']:.3f}")
    return "\n".join(lines)
