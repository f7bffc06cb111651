"""GeoJSON, KML and NMEA writers (leosop.apps.export) and ``leosop export``.

NMEA checksums are checked against published example sentences and against
an independent XOR in this file; map files are parsed back with the standard
library (json, xml.etree) and compared with the positions that went in.
"""

import functools
import json
import math
import operator
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from leosop.cli import main
from leosop.apps.export import KML_NS, MPS_TO_KNOTS, Layer, nmea_checksum, nmea_gga, nmea_rmc, to_geojson, to_kml
from leosop.frames import geodetic_to_ecef

#: Printed positions keep 1e-6 arc minutes (NMEA) or 1e-9 deg (maps): 2e-8 deg covers both.
POS_TOL_DEG = 2e-8
#: Heights are written to the millimetre.
ALT_TOL_M = 1e-3

# Published example sentences of the NMEA 0183 GGA and RMC layouts (the
# classic 1994 Munich examples quoted by most NMEA references), checksums as printed.
PUBLISHED = [
    "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47",
    "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A",
]


def _xor(body):
    return functools.reduce(operator.xor, body.encode("ascii"), 0)


def _parse_angle(text, hemi):
    """ddmm.mmmm / dddmm.mmmm -> signed degrees (independent of the writer)."""
    head, frac = text.split(".")
    deg, minutes = int(head[:-2]), float(head[-2:] + "." + frac)
    return (deg + minutes / 60.0) * (-1.0 if hemi in "SW" else 1.0)


def _fields(sentence):
    assert sentence.startswith("$") and sentence[-3] == "*"
    body = sentence[1:-3]
    assert int(sentence[-2:], 16) == _xor(body)
    return body.split(",")


@pytest.mark.parametrize("sentence", PUBLISHED)
def test_checksum_of_published_sentences(sentence):
    body, printed = sentence[1:].split("*")
    assert nmea_checksum(body) == printed


def test_gga_and_rmc_parse_back():
    t = np.array(["2025-01-01T19:40:00.004", "2025-01-01T23:59:59.996", "2025-01-02T00:00:01.25"],
                 dtype="datetime64[ns]")
    lat = np.array([34.342, -33.9, 0.5])
    lon = np.array([108.94, -18.4, -179.999999])
    alt = np.array([3000.0, -12.3456, 0.0])
    ve, vn = np.array([10.0, 0.0, -3.0]), np.array([0.0, -5.0, -4.0])
    gga = nmea_gga(t, lat, lon, alt, n_sats=[9, 10, 7])
    rmc = nmea_rmc(t, lat, lon, ve, vn)
    # 23:59:59.996 rounds to the next day at 10 ms: time and date both roll over.
    expect_time = ["194000.00", "000000.00", "000001.25"]
    expect_date = ["010125", "020125", "020125"]
    for k in range(3):
        g, r = _fields(gga[k]), _fields(rmc[k])
        assert len(g) == 15 and g[0] == "GNGGA" and len(r) == 13 and r[0] == "GNRMC"
        assert g[1] == r[1] == expect_time[k] and r[9] == expect_date[k]
        for f in (g, r):
            i = 2 if f is g else 3
            assert _parse_angle(f[i], f[i + 1]) == pytest.approx(lat[k], abs=POS_TOL_DEG)
            assert _parse_angle(f[i + 2], f[i + 3]) == pytest.approx(lon[k], abs=POS_TOL_DEG)
        assert g[6] == "6" and int(g[7]) == [9, 10, 7][k] and float(g[9]) == pytest.approx(alt[k], abs=ALT_TOL_M)
        assert r[2] == "A" and r[12] == "E"
        assert float(r[7]) == pytest.approx(math.hypot(ve[k], vn[k]) * 3600 / 1852, abs=0.005)
        course = math.degrees(math.atan2(ve[k], vn[k])) % 360
        assert float(r[8]) == pytest.approx(course, abs=0.005)
    assert MPS_TO_KNOTS == pytest.approx(1.0 / 0.514444, rel=1e-6)


def test_nmea_without_a_position_says_invalid():
    t = np.array(["2025-01-01T00:00:00"], dtype="datetime64[ns]")
    g = _fields(nmea_gga(t, [np.nan], [1.0], [0.0])[0])
    r = _fields(nmea_rmc(t, [np.nan], [1.0], [0.0], [0.0])[0])
    assert g[6] == "0" and g[2] == "" and r[2] == "V" and r[12] == "N" and r[3] == ""


def _track_layer():
    t = np.datetime64("2025-01-01T00:00:00", "ns") + np.arange(5) * np.timedelta64(1, "s")
    return Layer("sat", "track", [10.0, 11.0, 12.0, np.nan, 14.0], [178.0, 179.5, -179.5, -179.0, -178.0],
                 [100.0, 200.0, 300.0, 400.0, 500.0], t, properties={"sat_id": "7"})


def test_geojson_cuts_tracks_at_the_antimeridian_and_at_gaps():
    doc = json.loads(json.dumps(to_geojson([_track_layer()])))
    (feature,) = doc["features"]
    assert feature["geometry"]["type"] == "MultiLineString"
    seg = feature["geometry"]["coordinates"]
    # 179.5 -> -179.5 crosses halfway: latitude and height interpolated there;
    # the NaN row ends the second piece (a single point, dropped) and the last point stands alone.
    assert seg[0][-1] == pytest.approx([180.0, 11.5, 250.0]) and seg[1][0] == pytest.approx([-180.0, 11.5, 250.0])
    assert seg[1][-1] == [-179.5, 12.0, 300.0] and len(seg) == 2
    props = feature["properties"]
    assert props["sat_id"] == "7" and props["start_utc"] == "2025-01-01T00:00:00.000000Z"


def test_kml_parses_back_to_the_layers():
    t = np.datetime64("2025-01-01T00:00:00", "ns") + np.arange(3) * np.timedelta64(2, "s")
    pts = Layer("fixes", "points", [34.1, 34.2, np.nan], [108.1, 108.2, 108.3], [10.0, 20.0, 30.0], t,
                point_properties=[{"status": "ok", "sigma_e_m": 1.5}, {"status": "ok", "sigma_e_m": np.nan}, {}])
    text = to_kml([_track_layer(), pts], name="test & <check>")
    root = ET.fromstring(text.encode("utf-8"))
    ns = {"k": KML_NS}
    assert root.find("k:Document/k:name", ns).text == "test & <check>"
    folders = root.findall("k:Document/k:Folder", ns)
    assert [f.find("k:name", ns).text for f in folders] == ["sat", "fixes"]
    lines = folders[0].findall(".//k:LineString/k:coordinates", ns)
    assert len(lines) == 2
    first = [[float(v) for v in c.split(",")] for c in lines[0].text.split()]
    assert first[0] == [178.0, 10.0, 100.0] and first[-1] == pytest.approx([180.0, 11.5, 250.0])
    marks = folders[1].findall("k:Placemark", ns)
    assert len(marks) == 2  # the NaN row is left out
    lon, lat, alt = (float(v) for v in marks[1].find(".//k:coordinates", ns).text.split(","))
    assert (lon, lat, alt) == (108.2, 34.2, 20.0)
    assert marks[0].find("k:TimeStamp/k:when", ns).text == "2025-01-01T00:00:00.000000Z"
    data = {d.get("name"): d.find("k:value", ns).text for d in marks[0].findall(".//k:Data", ns)}
    assert data == {"status": "ok", "sigma_e_m": "1.5"}


def _run(argv, capsys):
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def solution_csv(tmp_path_factory):
    """The solution.csv ``leosop simulate --out`` writes (same table), of a 30 s flight, without its figures."""
    from leosop.fileio import write_csv
    from leosop.apps.scenarios import scenario_from_dict
    from leosop.apps.simulate import run_scenario, solution_table

    path = tmp_path_factory.mktemp("sim") / "solution.csv"
    result = run_scenario(scenario_from_dict({"name": "short", "duration_s": 30}), level="measurement")
    write_csv(path, *solution_table(result))
    return path


def test_export_solution_writes_all_three_that_parse_back(solution_csv, tmp_path, capsys):
    import csv

    status, out, _ = _run(["export", str(solution_csv), "--out", str(tmp_path), "--json"], capsys)
    assert status == 0
    doc = json.loads(out)
    assert doc["kind"] == "solution" and sorted(doc["files"]) == sorted(
        str(tmp_path / f"solution.{x}") for x in ("geojson", "kml", "nmea"))
    with open(solution_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    fused = np.array([[float(r["fused_lon_deg"]), float(r["fused_lat_deg"]), float(r["fused_alt_m"])] for r in rows])
    gj = json.loads((tmp_path / "solution.geojson").read_text())
    by_layer = {f["properties"]["layer"]: f for f in gj["features"] if f["geometry"]["type"] == "LineString"}
    assert set(by_layer) == {"truth", "INS only", "Starlink/INS fused"}
    assert np.allclose(by_layer["Starlink/INS fused"]["geometry"]["coordinates"], fused, atol=ALT_TOL_M)
    sentences = (tmp_path / "solution.nmea").read_bytes().decode("ascii").split("\r\n")
    assert sentences[-1] == "" and len(sentences) - 1 == 2 * len(rows)
    for k, (g, r) in enumerate(zip(sentences[0:-1:2], sentences[1:-1:2])):
        g, r = _fields(g), _fields(r)
        assert _parse_angle(g[2], g[3]) == pytest.approx(fused[k, 1], abs=POS_TOL_DEG)
        assert _parse_angle(r[5], r[6]) == pytest.approx(fused[k, 0], abs=POS_TOL_DEG)
    ET.parse(tmp_path / "solution.kml")


def test_export_passes_ground_tracks_stay_inside_the_mask_circle(tmp_path, capsys):
    site = (34.342, 108.940, 400.0)
    mask = 40.0
    assert main(["visibility", "--site", ",".join(map(str, site)), "--duration-s", "600", "--step-s", "10",
                 "--mask-deg", str(mask), "--out", str(tmp_path), "--json"]) == 0
    capsys.readouterr()
    status, out, _ = _run(["export", str(tmp_path / "passes.csv"), "--json", "--step-s", "5"], capsys)
    assert status == 0 and json.loads(out)["kind"] == "passes"
    gj = json.loads((tmp_path / "passes.geojson").read_text())
    # One feature per pass; a pass seen at a single epoch is a Point.
    assert len(gj["features"]) == len((tmp_path / "passes.csv").read_text().splitlines()) - 1
    # A satellite seen above the mask E from the site lies within the Earth
    # central angle 90 - E - asin(R cos E / (R + h)) of it; the bundled shells
    # fly below 600 km, so that angle for h = 600 km bounds every point.
    r_m, h_m = 6371e3, 600e3
    max_angle = math.radians(90 - mask) - math.asin(r_m * math.cos(math.radians(mask)) / (r_m + h_m))
    u_site = geodetic_to_ecef(*np.radians(site[:2]), 0.0)
    u_site = u_site / np.linalg.norm(u_site)
    for f in gj["features"]:
        lonlat = np.radians(np.array(f["geometry"]["coordinates"], ndmin=2))
        u = geodetic_to_ecef(lonlat[:, 1], lonlat[:, 0], 0.0)
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        # geodetic vs geocentric latitude differ by < 0.2 deg: 0.004 rad slack.
        assert np.all(np.arccos(np.clip(u @ u_site, -1, 1)) < max_angle + 0.004)


@pytest.mark.parametrize("content, extra, message", [
    ("a,b,c\n1,2,3\n", [], "not a solution, fixes or passes CSV"),
    ("time_utc,lat_deg,lon_deg,alt_m,status\n2025-01-01T00:00:00Z,x,1,2,ok\n", [], ":2: lat_deg 'x'"),
    ("time_utc,lat_deg,lon_deg,alt_m,status\n2025-01-01T00:00:00Z,1,1,2,ok\n", ["--to", "nmea"], "only a fused"),
    ("sat_id,rise_utc,set_utc,max_elev_deg\n99999999,2025-01-01T00:00:00Z,2025-01-01T00:01:00Z,50\n", [],
     "no element set"),
])
def test_export_bad_input_exit_2_without_output(tmp_path, capsys, content, extra, message):
    src = tmp_path / "in.csv"
    src.write_text(content)
    out_dir = tmp_path / "out"
    status, out, err = _run(["export", str(src), "--out", str(out_dir), *extra], capsys)
    assert status == 2 and out == ""
    assert message in err and len(err.strip().splitlines()) == 1
    assert not out_dir.exists()
