"""``leosop export``: the toolkit's CSV outputs as GeoJSON, KML and NMEA.

Takes one CSV written by another command and tells its kind from the header:

- ``solution.csv`` (``leosop simulate --out``): the truth, INS-only and fused
  tracks and the LEO fixes; NMEA GGA + RMC of the fused solution, one pair
  per epoch.
- ``fixes.csv`` (``leosop position --out``, ``leosop replay --out``): one
  point per fix with its time, sigmas and status.
- ``passes.csv`` (``leosop visibility --out``): the ground track (sub-satellite
  points) of each pass from rise to set, propagated from ``--tle`` (the
  element sets the passes came from; default the bundled set).

Writes ``STEM.geojson``, ``STEM.kml`` and (solutions only) ``STEM.nmea`` into
``--out`` (default: the CSV's directory), all or none.
"""

import csv
import sys
from pathlib import Path

import numpy as np

from ..apps.export import Layer, nmea_gga, nmea_rmc, to_geojson, to_kml
from ..errors import InputError
from ..fileio import atomic_files, json_text
from ..frames import ecef_to_geodetic
from ..orbits import load_constellation
from ..orbits.propagate import state_ecef_pairs
from ..timebase import parse_utc
from . import add_command
from .options import positive

FORMATS = ("geojson", "kml", "nmea")
#: Columns that tell a CSV's kind, checked in this order.
KINDS = {
    "solution": ("time_utc", "fused_lat_deg", "fused_lon_deg", "fused_alt_m", "fused_ve_mps", "fused_vn_mps"),
    "fixes": ("time_utc", "lat_deg", "lon_deg", "alt_m", "status"),
    "passes": ("sat_id", "rise_utc", "set_utc", "max_elev_deg"),
}
#: Tracks of a solution file: column prefix and layer name.
SOLUTION_TRACKS = (("truth", "truth"), ("ins", "INS only"), ("fused", "Starlink/INS fused"))


def register(subparsers):
    p = add_command(subparsers, "export", sys.modules[__name__],
                    help="GeoJSON/KML of trajectories, fixes and passes; NMEA GGA/RMC of a fused solution",
                    description="Convert a solution.csv (simulate), fixes.csv (position, replay) or passes.csv "
                                "(visibility) into GeoJSON and KML for map viewers, and a solution into NMEA "
                                "GGA/RMC sentences; the kind is told by the CSV header. Writes STEM.geojson, "
                                "STEM.kml (and STEM.nmea) into --out DIR, default the CSV's folder, all or none.")
    p.add_argument("csv", metavar="FILE.csv", help="solution.csv, fixes.csv or passes.csv (kind told by the header)")
    p.add_argument("--to", nargs="+", choices=FORMATS, metavar="FORMAT",
                   help="geojson, kml, nmea (default: geojson and kml, plus nmea for a solution)")
    p.add_argument("--tle", metavar="FILE", help="passes only: the element sets of the passes (default: bundled set)")
    p.add_argument("--step-s", type=float, default=10.0, help="passes only: ground-track step in seconds (default 10)")


def _read(path):
    """Header and rows of a CSV, with the kind it is."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except UnicodeDecodeError as exc:
        # No offset: the reader decodes in chunks, so exc.start is not the file's.
        raise InputError(f"{path}: not UTF-8 text (a byte 0x{exc.object[exc.start]:02x}); expected a CSV written "
                         "by leosop") from None
    if not rows:
        raise InputError(f"{path}: empty file, expected a CSV header")
    header = [h.strip() for h in rows[0]]
    for kind, needed in KINDS.items():
        if set(needed) <= set(header):
            break
    else:
        raise InputError(f"{path}: not a solution, fixes or passes CSV (header {','.join(header[:6])}...)")
    body = rows[1:]
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise InputError(f"{path}:{i + 2}: {len(r)} fields, the header has {len(header)}")
    if not body:
        raise InputError(f"{path}: no data rows")
    return kind, header, body


def _column(path, header, body, name, kind=float):
    """One column as an array; empty fields become NaN (floats); bad values name their line."""
    j = header.index(name)
    if kind is str:
        return np.array([r[j].strip() for r in body], dtype=object)
    if kind == "time":
        return np.array([parse_utc(r[j], name=f"{path}:{i + 2}: {name}") for i, r in enumerate(body)],
                        dtype="datetime64[ns]")
    out = np.empty(len(body))
    for i, r in enumerate(body):
        text = r[j].strip()
        try:
            out[i] = float(text) if text else np.nan
        except ValueError:
            raise InputError(f"{path}:{i + 2}: {name} {text!r} is not a number") from None
    outside = np.abs(out) > 90.0
    if name.endswith("lat_deg") and outside.any():
        i = int(np.argmax(outside))
        raise InputError(f"{path}:{i + 2}: {name} {body[i][j].strip()} is outside [-90, 90] deg")
    return out


def _solution(path, header, body):
    col = lambda name, kind=float: _column(path, header, body, name, kind)  # noqa: E731
    t = col("time_utc", "time")
    layers = []
    for prefix, label in SOLUTION_TRACKS:
        if f"{prefix}_lat_deg" in header:
            layers.append(Layer(label, "track", col(f"{prefix}_lat_deg"), col(f"{prefix}_lon_deg"),
                                col(f"{prefix}_alt_m"), t))
    if "fix_lat_deg" in header:
        layers.insert(len(layers) - 1, Layer("LEO fixes", "points", col("fix_lat_deg"), col("fix_lon_deg"),
                                             col("fix_alt_m"), t))
    n_sats = col("n_visible") if "n_visible" in header else None
    if n_sats is not None and not np.all(np.isfinite(n_sats)):
        n_sats = None
    lat, lon, alt = col("fused_lat_deg"), col("fused_lon_deg"), col("fused_alt_m")
    nmea = [s for pair in zip(nmea_gga(t, lat, lon, alt, n_sats=n_sats),
                              nmea_rmc(t, lat, lon, col("fused_ve_mps"), col("fused_vn_mps"))) for s in pair]
    return layers, nmea


def _fixes(path, header, body):
    col = lambda name, kind=float: _column(path, header, body, name, kind)  # noqa: E731
    extra = [h for h in ("sigma_e_m", "sigma_n_m", "sigma_u_m", "n_used", "gdop") if h in header]
    values = {h: col(h) for h in extra}
    if "n_used" in values and np.all(np.isfinite(values["n_used"])):
        values["n_used"] = values["n_used"].astype(int)  # a count, not a measurement
    status = col("status", str)
    props = [{"status": status[i], **{h: values[h][i] for h in extra}} for i in range(len(body))]
    return [Layer("fixes", "points", col("lat_deg"), col("lon_deg"), col("alt_m"), col("time_utc", "time"),
                  point_properties=props)]


def _passes(path, header, body, tle, step_s):
    col = lambda name, kind=float: _column(path, header, body, name, kind)  # noqa: E731
    ids, rise, set_, elev = col("sat_id", str), col("rise_utc", "time"), col("set_utc", "time"), col("max_elev_deg")
    if np.any(set_ < rise):
        raise InputError(f"{path}: a pass sets before it rises (row {int(np.argmax(set_ < rise)) + 2})")
    const = load_constellation(tle)
    index = const.index_of(ids)
    step = np.timedelta64(int(round(step_s * 1e9)), "ns")
    times = [np.append(np.arange(r, s, step), s) for r, s in zip(rise, set_)]
    sat = np.repeat(index, [len(t) for t in times])
    pos, _, status = state_ecef_pairs(const, sat, np.concatenate(times))
    lat, lon, _ = ecef_to_geodetic(pos)
    lat_deg, lon_deg = np.degrees(lat), np.degrees(lon)
    lat_deg[status != 0] = np.nan
    layers, start = [], 0
    for k, t in enumerate(times):
        sl = slice(start, start + len(t))
        start += len(t)
        layers.append(Layer(f"{ids[k]} {str(rise[k])[:19]}Z", "track", lat_deg[sl], lon_deg[sl], None, t,
                            properties={"sat_id": ids[k], "max_elev_deg": elev[k]}))
    return layers


def run(args):
    src = Path(args.csv)
    kind, header, body = _read(src)
    formats = args.to or (["geojson", "kml"] + (["nmea"] if kind == "solution" else []))
    if "nmea" in formats and kind != "solution":
        raise InputError(f"--to nmea: only a fused solution (solution.csv) has NMEA output, {src.name} is {kind}")
    step_s = positive(args.step_s, "--step-s")
    if kind == "solution":
        layers, nmea = _solution(src, header, body)
    elif kind == "fixes":
        layers, nmea = _fixes(src, header, body), []
    else:
        layers, nmea = _passes(src, header, body, args.tle, step_s), []
    out = Path(args.out) if args.out else src.parent
    texts = {
        "geojson": lambda: json_text(to_geojson(layers), compact=True) + "\n",
        "kml": lambda: to_kml(layers, name=f"leosop {src.name}"),
        "nmea": lambda: "\r\n".join(nmea) + "\r\n",
    }
    paths = [out / f"{src.stem}.{fmt}" for fmt in dict.fromkeys(formats)]
    with atomic_files(paths) as tmps:
        for tmp, path in zip(tmps, paths):
            tmp.write_text(texts[path.suffix[1:]](), encoding="utf-8", newline="")
    return {"input": str(src), "kind": kind, "files": [str(p) for p in paths],
            "layers": [{"name": la.name, "kind": la.kind, "n_points": int(la.valid.sum())} for la in layers],
            "n_nmea_sentences": len(nmea) if "nmea" in formats else 0}


def summary(doc):
    n_layers = len(doc["layers"])
    lines = [f"{doc['input']} ({doc['kind']}): {n_layers} layer(s), "
             f"{sum(la['n_points'] for la in doc['layers'])} points"]
    if doc["n_nmea_sentences"]:
        lines.append(f"{doc['n_nmea_sentences']} NMEA sentences (GGA + RMC per epoch)")
    lines += [f"wrote {f}" for f in doc["files"]]
    return "\n".join(lines)
