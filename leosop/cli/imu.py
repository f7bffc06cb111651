"""``leosop imu allan``: Allan deviation of a static IMU log, its noise terms, and a spec for ``fuse --imu-spec``.

JSON: ``source``, ``format``, ``rate_hz``, ``segment_s`` (start, duration), ``gyro`` and ``accel`` (per
axis R, F, U: ``tau_s``, ``adev``, ``white_density``, ``bias_instability``, ``tau_min_s``, ``floor_reached``
(False: the least deviation is at the longest averaging time, the bias instability an upper bound); gyro in deg/h
and deg/sqrt(h), accelerometer in ug and ug/sqrt(Hz)), ``imu_spec`` (the fields of
:class:`leosop.fusion.imu_noise.ImuSpec`). ``--out``: ``imu_spec.json`` (accepted by ``leosop fuse --imu-spec``),
``allan.json`` (this document) and ``allan.png`` (log-log, the read-off slopes marked); all or none.
"""

import dataclasses
import math
import sys
from pathlib import Path

from ..earth import normal_gravity_mps2
from ..errors import InputError
from ..fileio import atomic_outputs, write_json
from ..fusion.imu_noise import ImuSpec
from ..ins import allan, imu_io
from . import add_action, add_command
from .fuse import IMU_FORMATS, read_imu
from .options import parse_span

#: rad/s -> deg/h, and rad/sqrt(s) -> deg/sqrt(h).
_DEG_PER_H = math.degrees(1.0) * 3600.0
_DEG_PER_RT_H = math.degrees(1.0) * 60.0


def register(subparsers):
    p = add_command(subparsers, "imu", sys.modules[__name__], help="characterise an IMU log", out=False)
    sub = p.add_subparsers(dest="imu_command", metavar="ACTION", required=True)
    a = add_action(sub, "allan", help="Allan deviation of a static log: random walks and bias instability")
    a.add_argument("file", metavar="FILE", help="IMU log, at rest")
    a.add_argument("--imu-format", choices=IMU_FORMATS, help="as leosop fuse --imu-format")
    a.add_argument("--imu-columns", metavar="MAP", help="as leosop fuse --imu-columns")
    a.add_argument("--segment-s", metavar="START_S,DURATION_S",
                   help="only this stretch, seconds after the log's first sample (a static segment)")
    a.add_argument("--out", metavar="DIR", help="directory for imu_spec.json, allan.json and allan.png")


def run(args):
    if args.imu_columns and args.imu_format != "csv":
        raise InputError("--imu-columns goes with --imu-format csv")
    log, _ = read_imu(args.file, args.imu_format, args.imu_columns, imu_io.mount_C_b_s(0.0, 0.0, 0.0))
    start, duration = ((0.0, float(log.t_s[-1] - log.t_s[0])) if args.segment_s is None
                       else parse_span(args.segment_s, "--segment-s"))
    t = log.t_s - log.t_s[0]
    sel = (t >= start) & (t <= start + duration)
    if sel.sum() < 1000:
        raise InputError(f"{args.file}: {int(sel.sum())} samples in the segment, the Allan deviation needs >= 1000")
    rate = log.rate_hz
    gyro = allan.allan(log.gyro_rad_per_s[sel], rate)
    accel = allan.allan(log.accel_mps2[sel], rate)
    spec = ImuSpec.from_allan(gyro, accel)
    ug = 1e6 / normal_gravity_mps2(0.0, 0.0)
    doc = {"source": str(args.file), "format": log.metadata.get("format"), "rate_hz": rate,
           "segment_s": [start, float(t[sel][-1] - t[sel][0])],
           "gyro": _terms(gyro, _DEG_PER_H, _DEG_PER_RT_H, "deg_per_h", "deg_per_rt_h"),
           "accel": _terms(accel, ug, ug, "ug", "ug_per_rt_hz"),
           "imu_spec": dataclasses.asdict(spec)}
    if args.out:
        from ..plots import imu as plots

        with atomic_outputs(args.out) as stage:
            write_json(stage / "imu_spec.json", doc["imu_spec"])
            write_json(stage / "allan.json", doc)
            plots.allan(stage / "allan.png", gyro, accel, _DEG_PER_H, ug, Path(args.file).name)
    return doc


def _terms(res, scale, white_scale, unit, white_unit):
    return {"tau_s": res.tau_s.tolist(), f"adev_{unit}": (res.adev * scale).tolist(),
            f"white_density_{white_unit}": (res.white_density * white_scale).tolist(),
            f"bias_instability_{unit}": (res.bias_instability * scale).tolist(), "tau_min_s": res.tau_min_s.tolist(),
            "floor_reached": res.floor_reached.tolist()}


def summary(doc):
    g, a = doc["gyro"], doc["accel"]

    def fmt(v):
        return " / ".join(f"{x:.3g}" for x in v)

    def bound(d, key):
        return " / ".join(f"{'' if r else '<= '}{x:.3g}" for x, r in zip(d[key], d["floor_reached"]))

    return "\n".join([
        f"{doc['source']}: {doc['segment_s'][1]:.0f} s at {doc['rate_hz']:.0f} Hz (axes R / F / U)",
        (f"  gyro: ARW {fmt(g['white_density_deg_per_rt_h'])} deg/sqrt(h), bias instability "
        f"{bound(g, 'bias_instability_deg_per_h')} deg/h at {fmt(g['tau_min_s'])} s"),
        (f"  accel: VRW {fmt(a['white_density_ug_per_rt_hz'])} ug/sqrt(Hz), bias instability "
        f"{bound(a, 'bias_instability_ug')} ug at {fmt(a['tau_min_s'])} s"),
        "  (<= : no floor within the log, the least deviation is at its longest averaging time)"])
