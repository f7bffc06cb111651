"""Writers for map viewers and NMEA tools: GeoJSON, KML, NMEA 0183 GGA/RMC.

A map export is a list of :class:`Layer` objects, each a track (one line
through its points) or a set of points, in WGS84 geodetic coordinates.
:func:`to_geojson` and :func:`to_kml` turn the same layers into either
format; :func:`nmea_gga` and :func:`nmea_rmc` make sentences of a position
(and velocity) time series. Nothing here reads files; ``leosop export``
(:mod:`leosop.cli.export`) reads the toolkit's CSV outputs and calls these.

Conventions of the formats, and what we do about them:

- GeoJSON (RFC 7946) and KML give coordinates as ``lon, lat[, alt]``. A
  track that crosses the antimeridian is cut there (the crossing point
  interpolated) into a ``MultiLineString`` (RFC 7946 sec. 3.1.9), and a
  track is also cut where a point is missing (NaN), so no line is drawn
  across the map or through a gap.
- Heights: the toolkit's ``alt_m`` is the height above the WGS84 ellipsoid.
  GeoJSON takes it as is (RFC 7946: height above the ellipsoid). KML and NMEA
  expect heights above mean sea level; no geoid model is applied, so they
  carry the ellipsoidal height (tens of metres off MSL, up to ~100 m) and the
  GGA geoid-separation field is left empty.
- NMEA: the checksum is the XOR of every character between ``$`` and ``*``
  as two upper-case hex digits. The fused LEO/INS solution is neither GPS nor
  a survey: GGA quality 6 ("estimated", dead reckoning) and RMC mode ``E``
  are the codes that say so; the talker is ``GN`` (any navigation system).
"""

import dataclasses
import math
import xml.etree.ElementTree as ET

import numpy as np

from ..errors import InputError
from ..timebase import format_utc

__all__ = ["Layer", "to_geojson", "to_kml", "nmea_checksum", "nmea_sentence", "nmea_gga", "nmea_rmc",
           "MPS_TO_KNOTS", "KML_NS"]

#: Metres per second to knots (1 kn = 1852 m / 3600 s, exact).
MPS_TO_KNOTS = 3600.0 / 1852.0
#: KML 2.2 namespace.
KML_NS = "http://www.opengis.net/kml/2.2"
#: Line and point colours, one per layer in order (``#rrggbb``).
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf")


@dataclasses.dataclass(frozen=True)
class Layer:
    """One track or set of points to draw.

    Attributes
    ----------
    name : str
    kind : {"track", "points"}
        ``track``: one line through the points in order (with ``properties``
        for the whole line); ``points``: a marker each (with
        ``point_properties``).
    lat_deg, lon_deg : ndarray, (n,)
        WGS84 geodetic; NaN rows are left out (and cut a track).
    alt_m : ndarray, (n,), optional
        Height above the WGS84 ellipsoid; None for positions on the ground
        (e.g. a satellite's ground track).
    times_utc : ndarray of datetime64, (n,), optional
    properties : dict
        Of the whole layer (a track's feature properties).
    point_properties : list of dict, optional
        One dict per point (``points`` layers only).
    """

    name: str
    kind: str
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray = None
    times_utc: np.ndarray = None
    properties: dict = dataclasses.field(default_factory=dict)
    point_properties: list = None

    def __post_init__(self):
        if self.kind not in ("track", "points"):
            raise ValueError(f"Layer kind {self.kind!r} must be 'track' or 'points'")
        lat = np.atleast_1d(np.asarray(self.lat_deg, dtype=float))
        lon = np.atleast_1d(np.asarray(self.lon_deg, dtype=float))
        n = lat.shape[0]
        if lat.shape != (n,) or lon.shape != (n,):
            raise ValueError(f"layer {self.name!r}: lat_deg {lat.shape} and lon_deg {lon.shape} must be (n,)")
        object.__setattr__(self, "lat_deg", lat)
        object.__setattr__(self, "lon_deg", lon)
        for name in ("alt_m", "times_utc"):
            v = getattr(self, name)
            if v is not None:
                v = np.atleast_1d(np.asarray(v, dtype=float if name == "alt_m" else "datetime64[ns]"))
                if v.shape != (n,):
                    raise ValueError(f"layer {self.name!r}: {name} {v.shape} must be ({n},)")
                object.__setattr__(self, name, v)
        if self.point_properties is not None and len(self.point_properties) != n:
            raise ValueError(f"layer {self.name!r}: {len(self.point_properties)} point_properties for {n} points")

    @property
    def valid(self):
        """Rows with a finite position, (n,) bool."""
        ok = np.isfinite(self.lat_deg) & np.isfinite(self.lon_deg)
        return ok if self.alt_m is None else ok & np.isfinite(self.alt_m)


def _coords(layer, rows):
    """``[lon, lat(, alt)]`` lists of the given rows, to 1e-9 deg (0.1 mm) and 1 mm."""
    cols = [layer.lon_deg[rows], layer.lat_deg[rows]] + ([] if layer.alt_m is None else [layer.alt_m[rows]])
    return [[round(v, 9 if k < 2 else 3) for k, v in enumerate(c)] for c in np.column_stack(cols).tolist()]


def _wrap_deg(lon_deg):
    return (np.asarray(lon_deg) + 180.0) % 360.0 - 180.0


def track_segments(layer):
    """A track's coordinates cut at missing points and at the antimeridian.

    Returns
    -------
    list of list of [lon, lat] or [lon, lat, alt]
        Each segment has at least two points; at an antimeridian crossing
        both sides end on +-180 deg at the interpolated latitude (and height).
    """
    ok = layer.valid
    segments = []
    for run in np.split(np.arange(ok.size), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1):
        if run.size < 2 or not ok[run[0]]:
            continue
        pts = _coords(layer, run)
        for p in pts:
            if not -180.0 <= p[0] <= 180.0:
                p[0] = round(float(_wrap_deg(p[0])), 9)
        current = [pts[0]]
        for prev, p in zip(pts[:-1], pts[1:]):
            if abs(p[0] - prev[0]) > 180.0:
                side = math.copysign(180.0, prev[0])
                span = 360.0 - abs(p[0] - prev[0])
                w = (180.0 - abs(prev[0])) / span if span > 0 else 0.5
                cross = [prev[k] + w * (p[k] - prev[k]) for k in range(1, len(p))]
                current.append([side, *cross])
                segments.append(current)
                current = [[-side, *cross]]
            current.append(p)
        segments.append(current)
    return [s for s in segments if len(s) >= 2]


def _track_geometry(layer):
    """GeoJSON geometry type and coordinates of a track; a track of one point is a Point, of none None."""
    segments = track_segments(layer)
    if len(segments) == 1:
        return "LineString", segments[0]
    if segments:
        return "MultiLineString", segments
    rows = np.flatnonzero(layer.valid)
    return ("Point", _coords(layer, rows[:1])[0]) if rows.size else (None, None)


def _json_value(v):
    """Properties as JSON values: numpy scalars to Python, NaN to None, datetimes to ISO text."""
    if isinstance(v, np.datetime64):
        return format_utc(v)
    if isinstance(v, (np.generic,)):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _time_props(layer, rows):
    if layer.times_utc is None or rows.size == 0:
        return {}
    return {"start_utc": format_utc(layer.times_utc[rows[0]]), "end_utc": format_utc(layer.times_utc[rows[-1]])}


def to_geojson(layers):
    """A GeoJSON FeatureCollection of the layers (RFC 7946).

    A track is one LineString (MultiLineString when cut, Point when it has
    a single point) feature; a points
    layer one Point feature per valid row. Every feature's properties carry
    ``layer`` and a ``stroke`` or ``marker-color`` (simplestyle) colour.

    Parameters
    ----------
    layers : sequence of Layer

    Returns
    -------
    dict
        Ready for ``json.dump``.
    """
    features = []
    for i, layer in enumerate(layers):
        color = PALETTE[i % len(PALETTE)]
        rows = np.flatnonzero(layer.valid)
        if layer.kind == "track":
            kind, coords = _track_geometry(layer)
            if kind is None:
                continue
            geometry = {"type": kind, "coordinates": coords}
            props = {"layer": layer.name, **_time_props(layer, rows),
                     **{k: _json_value(v) for k, v in layer.properties.items()}, "stroke": color}
            features.append({"type": "Feature", "geometry": geometry, "properties": props})
            continue
        coords = _coords(layer, rows)
        for r, c in zip(rows, coords):
            props = {"layer": layer.name}
            if layer.times_utc is not None:
                props["time_utc"] = format_utc(layer.times_utc[r])
            if layer.point_properties is not None:
                props.update({k: _json_value(v) for k, v in layer.point_properties[r].items()})
            props["marker-color"] = color
            features.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": c},
                             "properties": props})
    return {"type": "FeatureCollection", "features": features}


def _kml_color(hex_rgb):
    """``#rrggbb`` as KML's opaque ``aabbggrr``."""
    r, g, b = hex_rgb[1:3], hex_rgb[3:5], hex_rgb[5:7]
    return f"ff{b}{g}{r}"


def _sub(parent, tag, text=None, **attrib):
    el = ET.SubElement(parent, f"{{{KML_NS}}}{tag}", attrib)
    if text is not None:
        el.text = text
    return el


def _kml_coords(coords):
    return " ".join(",".join(f"{x:.9g}" if k < 2 else f"{x:.3f}" for k, x in enumerate(c)) for c in coords)


def _kml_extended(placemark, props):
    if not props:
        return
    ext = _sub(placemark, "ExtendedData")
    for k, v in props.items():
        v = _json_value(v)
        _sub(_sub(ext, "Data", name=str(k)), "value", "" if v is None else str(v))


def _kml_geometry(parent, tag, layer):
    geom = _sub(parent, tag)
    if layer.alt_m is not None:
        _sub(geom, "altitudeMode", "absolute")
    else:
        _sub(geom, "tessellate", "1")
    return geom


def to_kml(layers, *, name):
    """A KML 2.2 document of the layers: a folder each, a style per layer.

    Tracks are ``LineString`` placemarks (a ``MultiGeometry`` when cut) with
    a ``TimeSpan``; points are ``Point`` placemarks with a ``TimeStamp`` and
    their properties as ``ExtendedData``. Heights (``absolute``) are the
    ellipsoidal ``alt_m``; layers without heights are drawn on the ground.

    Parameters
    ----------
    layers : sequence of Layer
    name : str
        Document name shown by the viewer.

    Returns
    -------
    str
        The XML text, UTF-8 declaration included.
    """
    ET.register_namespace("", KML_NS)
    root = ET.Element(f"{{{KML_NS}}}kml")
    doc = _sub(root, "Document")
    _sub(doc, "name", name)
    for i, layer in enumerate(layers):
        style_id = f"layer{i}"
        style = _sub(doc, "Style", id=style_id)
        color = _kml_color(PALETTE[i % len(PALETTE)])
        line = _sub(style, "LineStyle")
        _sub(line, "color", color)
        _sub(line, "width", "2")
        icon = _sub(style, "IconStyle")
        _sub(icon, "color", color)
        _sub(icon, "scale", "0.5")
    for i, layer in enumerate(layers):
        folder = _sub(doc, "Folder")
        _sub(folder, "name", layer.name)
        rows = np.flatnonzero(layer.valid)
        if layer.kind == "track":
            kind, coords = _track_geometry(layer)
            if kind is None:
                continue
            pm = _sub(folder, "Placemark")
            _sub(pm, "name", layer.name)
            _sub(pm, "styleUrl", f"#layer{i}")
            times = _time_props(layer, rows)
            if times:
                span = _sub(pm, "TimeSpan")
                _sub(span, "begin", times["start_utc"])
                _sub(span, "end", times["end_utc"])
            _kml_extended(pm, layer.properties)
            if kind == "Point":
                _sub(_kml_geometry(pm, "Point", layer), "coordinates", _kml_coords([coords]))
                continue
            parent = _sub(pm, "MultiGeometry") if kind == "MultiLineString" else pm
            for seg in coords if kind == "MultiLineString" else [coords]:
                _sub(_kml_geometry(parent, "LineString", layer), "coordinates", _kml_coords(seg))
            continue
        for r, c in zip(rows, _coords(layer, rows)):
            pm = _sub(folder, "Placemark")
            _sub(pm, "styleUrl", f"#layer{i}")
            if layer.times_utc is not None:
                _sub(_sub(pm, "TimeStamp"), "when", format_utc(layer.times_utc[r]))
            if layer.point_properties is not None:
                _kml_extended(pm, layer.point_properties[r])
            _sub(_kml_geometry(pm, "Point", layer), "coordinates", _kml_coords([c]))
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def nmea_checksum(body):
    """NMEA 0183 checksum of a sentence body (the text between ``$`` and ``*``): two hex digits."""
    value = 0
    for ch in body.encode("ascii"):
        value ^= ch
    return f"{value:02X}"


def nmea_sentence(body):
    """``$body*HH`` with its checksum; refuses characters NMEA reserves."""
    bad = set(body) & set("$*!\r\n")
    if bad or not body.isascii():
        raise InputError(f"NMEA sentence body {body!r} holds reserved or non-ASCII characters")
    return f"${body}*{nmea_checksum(body)}"


def _utc_fields(times_utc):
    """``hhmmss.ss`` and ``ddmmyy`` of each instant (rounded to 10 ms)."""
    t = np.asarray(times_utc, dtype="datetime64[ns]")
    t = (t + np.timedelta64(5, "ms")).astype("datetime64[ms]")
    days = t.astype("datetime64[D]")
    ms = (t - days).astype(np.int64)
    out = []
    for d, m in zip(days.astype(str), ms):
        hh, rem = divmod(int(m), 3_600_000)
        mm, rem = divmod(rem, 60_000)
        out.append((f"{hh:02d}{mm:02d}{rem // 10 / 100:05.2f}", f"{d[8:10]}{d[5:7]}{d[2:4]}"))
    return out


def _angle(value_deg, width, hemispheres):
    """``(d)ddmm.mmmmmm`` and hemisphere letter of a signed angle."""
    hemi = hemispheres[0] if value_deg >= 0 else hemispheres[1]
    a = abs(float(value_deg))
    deg = int(a)
    minutes = round((a - deg) * 60.0, 6)
    if minutes >= 60.0:
        deg, minutes = deg + 1, 0.0
    return f"{deg:0{width}d}{minutes:09.6f}", hemi


def _check_series(times_utc, *cols):
    t = np.atleast_1d(np.asarray(times_utc, dtype="datetime64[ns]"))
    arrays = [np.atleast_1d(np.asarray(c, dtype=float)) for c in cols]
    for a in arrays:
        if a.shape != t.shape or t.ndim != 1:
            raise ValueError(f"NMEA series must be (n,) arrays of equal length, got {t.shape} and {a.shape}")
    return t, arrays


def nmea_gga(times_utc, lat_deg, lon_deg, alt_m, *, n_sats=None, quality=6, talker="GN"):
    """GGA sentences (time, position, fix quality, height) of a position series.

    Epochs with a non-finite position are written with quality 0 and empty
    position fields. HDOP is left empty (the Doppler solution has no range
    HDOP); the height is the ellipsoidal ``alt_m`` and the geoid separation
    empty (see the module docstring).

    Parameters
    ----------
    times_utc : array_like of datetime64, (n,)
    lat_deg, lon_deg, alt_m : array_like, (n,)
    n_sats : array_like of int, (n,), optional
        Satellites used (or visible); empty field when None.
    quality : int
        GGA fix quality, 6 = estimated (dead reckoning).
    talker : str

    Returns
    -------
    list of str, (n,)
    """
    t, (lat, lon, alt) = _check_series(times_utc, lat_deg, lon_deg, alt_m)
    n = None if n_sats is None else np.atleast_1d(np.asarray(n_sats))
    out = []
    for k, (hms, _) in enumerate(_utc_fields(t)):
        sats = "" if n is None else f"{int(n[k]):02d}"
        if not (np.isfinite(lat[k]) and np.isfinite(lon[k]) and np.isfinite(alt[k])):
            out.append(nmea_sentence(f"{talker}GGA,{hms},,,,,0,{sats},,,M,,M,,"))
            continue
        la, ns = _angle(lat[k], 2, "NS")
        lo, ew = _angle(lon[k], 3, "EW")
        out.append(nmea_sentence(f"{talker}GGA,{hms},{la},{ns},{lo},{ew},{quality},{sats},,{alt[k]:.3f},M,,M,,"))
    return out


def nmea_rmc(times_utc, lat_deg, lon_deg, vel_east_mps, vel_north_mps, *, mode="E", talker="GN"):
    """RMC sentences (time, status, position, speed and course over ground, date).

    Speed in knots, course in degrees clockwise from true North, from the
    East and North velocity. Epochs with a non-finite position get status
    ``V`` and mode ``N``. NMEA 2.3 layout (mode indicator last).

    Parameters
    ----------
    times_utc : array_like of datetime64, (n,)
    lat_deg, lon_deg, vel_east_mps, vel_north_mps : array_like, (n,)
    mode : str
        FAA mode indicator, ``E`` = estimated (dead reckoning).
    talker : str

    Returns
    -------
    list of str, (n,)
    """
    t, (lat, lon, ve, vn) = _check_series(times_utc, lat_deg, lon_deg, vel_east_mps, vel_north_mps)
    speed_kn = np.hypot(ve, vn) * MPS_TO_KNOTS
    course_deg = np.degrees(np.arctan2(ve, vn)) % 360.0
    out = []
    for k, (hms, dmy) in enumerate(_utc_fields(t)):
        if not (np.isfinite(lat[k]) and np.isfinite(lon[k])):
            out.append(nmea_sentence(f"{talker}RMC,{hms},V,,,,,,,{dmy},,,N"))
            continue
        la, ns = _angle(lat[k], 2, "NS")
        lo, ew = _angle(lon[k], 3, "EW")
        sog = f"{speed_kn[k]:.2f}" if np.isfinite(speed_kn[k]) else ""
        cog = f"{course_deg[k]:.2f}" if np.isfinite(course_deg[k]) else ""
        out.append(nmea_sentence(f"{talker}RMC,{hms},A,{la},{ns},{lo},{ew},{sog},{cog},{dmy},,,{mode}"))
    return out
