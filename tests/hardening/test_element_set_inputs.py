"""Element sets as an auditor fed them: text in numeric TLE fields, bad OMM values, and ``tle fetch`` errors.

Every rejection is one line naming the file (or URL), the line or record and
the field, with exit status 2 for the user's input.
"""

import csv
import io
import json
import re
import urllib.request

import pytest

from leosop.cli import main
from leosop.errors import InputError
from leosop.orbits import read_omm, read_tle
from leosop.orbits.tle import tle_checksum

# ISS (ZARYA), a public element set with valid checksums (as in tests/orbits/test_tle.py).
L1 = "1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927"
L2 = "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537"
OMM = {"OBJECT_NAME": "STARLINK-1007", "NORAD_CAT_ID": 44713, "EPOCH": "2025-01-01T00:00:00.000",
       "MEAN_MOTION": 15.06, "ECCENTRICITY": 0.0001, "INCLINATION": 53.05, "RA_OF_ASC_NODE": 10.0,
       "ARG_OF_PERICENTER": 90.0, "MEAN_ANOMALY": 270.0, "BSTAR": 0.0001, "MEAN_MOTION_DOT": 1e-5,
       "MEAN_MOTION_DDOT": 0}


def _with_text(line, first, last):
    """``line`` with the first digit of columns ``first``-``last`` made an ``x``, its checksum fixed."""
    field = re.sub(r"\d", "x", line[first - 1:last], count=1)
    line = line[:first - 1] + field + line[last:]
    return line[:68] + str(tle_checksum(line)), field


def test_blank_counters_still_read(tmp_path):
    """Hand-made element sets leave the element set and revolution numbers blank; SGP4 reads them as 0."""
    l1, l2 = L1[:64] + "    " + L1[68:], L2[:63] + "     " + L2[68:]
    l1, l2 = (ln[:68] + str(tle_checksum(ln)) for ln in (l1, l2))
    path = tmp_path / "blank.tle"
    path.write_text(f"ISS\n{l1}\n{l2}\n")
    assert len(read_tle(path)) == 1


@pytest.mark.parametrize("n, first, last, name", [
    (1, 3, 7, "catalogue number"), (1, 19, 20, "epoch year"), (1, 21, 32, "epoch day of year"),
    (1, 34, 43, "mean motion derivative"), (1, 45, 52, "mean motion second derivative"), (1, 54, 61, "BSTAR"),
    (1, 63, 63, "ephemeris type"), (1, 65, 68, "element set number"),
    (2, 3, 7, "catalogue number"), (2, 9, 16, "inclination"), (2, 18, 25, "right ascension of the node"),
    (2, 27, 33, "eccentricity"), (2, 35, 42, "argument of perigee"), (2, 44, 51, "mean anomaly"),
    (2, 53, 63, "mean motion"), (2, 64, 68, "revolution number"),
])
def test_text_in_a_numeric_tle_field_is_named(tmp_path, n, first, last, name):
    lines = [L1, L2]
    lines[n - 1], field = _with_text(lines[n - 1], first, last)
    path = tmp_path / "iss.tle"
    path.write_text("\n".join(lines) + "\n")
    columns = f"column {first}" if first == last else f"columns {first}-{last}"
    with pytest.raises(InputError, match=re.escape(f"iss.tle:{n}: {name} {field!r} in {columns} of TLE line {n}")):
        read_tle(path)


def test_text_in_an_omm_csv_field_is_named(tmp_path):
    path = tmp_path / "set.csv"
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, OMM)
        writer.writeheader()
        writer.writerow({**OMM, "INCLINATION": "abc"})
    with pytest.raises(InputError, match=re.escape("set.csv:2: OMM field INCLINATION: expected a number, found 'abc'")):
        read_omm(path)


@pytest.mark.parametrize("norad_id", [-5, 0])
def test_omm_catalogue_number_must_be_positive(tmp_path, norad_id):
    path = tmp_path / "set.json"
    path.write_text(json.dumps([{**OMM, "NORAD_CAT_ID": norad_id}]))
    with pytest.raises(InputError, match=f"set.json: record 1: OMM field NORAD_CAT_ID: .* found {norad_id}$"):
        read_omm(path)


def _fetch(capsys, monkeypatch, tmp_path, body, *options):
    """``tle fetch starlink`` from a fake mirror serving ``body``: (status, stdout, stderr)."""
    monkeypatch.setattr(urllib.request, "urlopen", lambda url, timeout: io.BytesIO(body))
    status = main(["tle", "fetch", "starlink", "-o", str(tmp_path / "s.tle"), "--url", "http://mirror/gp.php",
                   *options])
    out, err = capsys.readouterr()
    return status, out, err


def test_fetch_errors_name_the_url_not_a_temporary_file(tmp_path, capsys, monkeypatch):
    bad = L1[:68] + str((int(L1[68]) + 1) % 10)
    status, _, err = _fetch(capsys, monkeypatch, tmp_path, f"{bad}\n{L2}\n".encode())
    assert status == 1 and len(err.strip().splitlines()) == 1, err
    assert "http://mirror/gp.php?GROUP=starlink&FORMAT=tle:1: bad TLE checksum on line 1" in err
    assert ".part" not in err and not (tmp_path / "s.tle").exists()


def test_fetched_constellation_names_the_url(tmp_path, capsys, monkeypatch):
    status, out, _ = _fetch(capsys, monkeypatch, tmp_path, f"{L1}\n{L2}\n".encode(), "--json")
    doc = json.loads(out)
    assert status == 0 and doc["source"] == "http://mirror/gp.php?GROUP=starlink&FORMAT=tle"
    assert doc["written"] == str(tmp_path / "s.tle")


def test_fetch_url_that_is_not_http_names_the_option(tmp_path, capsys):
    status = main(["tle", "fetch", "starlink", "-o", str(tmp_path / "s.tle"), "--url", "notaurl"])
    err = capsys.readouterr().err
    assert status == 2
    assert err == ("leosop tle: error: --url 'notaurl': expected an http:// or https:// URL such as "
                   "https://celestrak.org/NORAD/elements/gp.php\n")
