"""Make leosop/data/coastline_110m.npz from Natural Earth 1:110m country polygons.

Input: ``naturalearth_lowres.shp`` (Natural Earth ne_110m_admin_0_countries,
public domain), e.g. as shipped in the ``geopandas`` 0.14 wheel under
``geopandas/datasets/naturalearth_lowres/``. Edges shared by two countries are
land borders and are dropped; the edges left are the coastline, chained into
NaN-separated polylines of (lon, lat) in degrees.

    python tools/make_coastline.py path/to/naturalearth_lowres.shp
"""

import struct
import sys
from pathlib import Path

import numpy as np


def read_polygon_rings(path):
    """Rings of every polygon record of an ESRI shapefile (type 5): list of (n, 2) arrays."""
    data = Path(path).read_bytes()
    rings, pos = [], 100
    while pos < len(data):
        _, length = struct.unpack(">ii", data[pos:pos + 8])
        rec = data[pos + 8:pos + 8 + 2 * length]
        pos += 8 + 2 * length
        if struct.unpack("<i", rec[:4])[0] != 5:
            continue
        n_parts, n_points = struct.unpack("<ii", rec[36:44])
        parts = list(struct.unpack(f"<{n_parts}i", rec[44:44 + 4 * n_parts])) + [n_points]
        pts = np.frombuffer(rec[44 + 4 * n_parts:44 + 4 * n_parts + 16 * n_points], "<f8").reshape(-1, 2)
        rings += [pts[a:b] for a, b in zip(parts[:-1], parts[1:])]
    return rings


def coast_polylines(rings):
    """Polylines of the ring edges that belong to one ring only."""
    key = lambda p: (round(p[0], 6), round(p[1], 6))  # noqa: E731
    seen = {}
    for ring in rings:
        for a, b in zip(ring[:-1], ring[1:]):
            e = frozenset((key(a), key(b)))
            seen[e] = seen.get(e, 0) + 1
    lines = []
    for ring in rings:
        current = []
        for a, b in zip(ring[:-1], ring[1:]):
            if seen[frozenset((key(a), key(b)))] == 1:
                if not current:
                    current = [a]
                current.append(b)
            elif current:
                lines.append(np.array(current))
                current = []
        if current:
            lines.append(np.array(current))
    return lines


def main(shp):
    lines = coast_polylines(read_polygon_rings(shp))
    out = []
    for line in lines:
        out += [line, np.full((1, 2), np.nan)]
    lonlat = np.concatenate(out).astype(np.float32)
    dest = Path(__file__).resolve().parents[1] / "leosop" / "data" / "coastline_110m.npz"
    np.savez_compressed(dest, lon_lat_deg=lonlat)
    print(f"{dest}: {len(lines)} polylines, {np.isfinite(lonlat[:, 0]).sum()} points, {dest.stat().st_size} bytes")


if __name__ == "__main__":
    main(sys.argv[1])
