"""TLE and OMM readers: every real snapshot, line endings, and malformed records."""

import json
import warnings

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.orbits import load_constellation, read_omm, read_tle
from leosop.orbits.propagate import state_teme
from leosop.orbits.tle import tle_checksum

from tests.helpers import data_path

# ISS (ZARYA), a public element set with valid checksums.
NAME = "ISS (ZARYA)"
L1 = "1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927"
L2 = "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537"


# Counts from ../shared/data/tle/PROVENANCE.md (computed there with sgp4).
@pytest.mark.parametrize("name, count", [
    ("starlink_3le_2022-12-02_TrevorBurgoyne.txt", 3280),
    ("starlink_3le_2026-04-08_Bochika.txt", 10138),
    ("active_3le_2026-04-10_Bochika.txt", 15008),
    ("active_3le_2021-08-06_atqlong.txt", 4602),
    ("gps-ops_3le_2021-08-05_atqlong.txt", 30),
    ("gnss_2012-10-31/TLE_GNSS_20121101.txt", 93),
])
def test_real_snapshots_parse_with_expected_counts(name, count):
    const = read_tle(data_path("tle", *name.split("/")))
    assert len(const) == count
    assert len(set(const.sat_ids)) == count


def test_families_of_the_mixed_active_snapshot():
    const = read_tle(data_path("tle", "active_3le_2026-04-10_Bochika.txt"))
    fam, n = np.unique(const.families, return_counts=True)
    counts = dict(zip(fam.tolist(), n.tolist()))
    # PROVENANCE.md: STARLINK 10161, ONEWEB 651, IRIDIUM 80 (all NEXT), ORBCOMM 15.
    assert (counts["starlink"], counts["oneweb"], counts["iridium"], counts["orbcomm"]) == (10161, 651, 80, 15)
    iridium = const.family("iridium")
    assert all(int(s) >= 41917 for s in iridium.sat_ids)


def test_epoch_span_of_a_real_snapshot():
    const = read_tle(data_path("tle", "starlink_3le_2022-12-02_TrevorBurgoyne.txt"))
    # PROVENANCE.md: min 2022-11-29 07:07:29, max 2022-12-02 14:01:28 UTC.
    assert str(const.epochs_utc.min().astype("datetime64[s]")) == "2022-11-29T07:07:29"
    assert str(const.epochs_utc.max().astype("datetime64[s]")) == "2022-12-02T14:01:28"


@pytest.mark.parametrize("eol", ["\n", "\r\n", "\r\r\n", "\r"])
@pytest.mark.parametrize("three_line", [True, False])
def test_line_endings_and_blank_lines(tmp_path, eol, three_line):
    lines = ([NAME] if three_line else []) + [L1, L2, ""]
    path = tmp_path / "iss.tle"
    path.write_bytes((eol.join(["", *lines, "", "0 " + NAME, L1, L2]) + eol).encode())
    with warnings.catch_warnings(record=True):
        const = read_tle(path)
    assert const.sat_ids.tolist() == ["25544"]  # duplicate record folded into one
    assert const.names[0] == NAME


def _write(tmp_path, l1=L1, l2=L2, name=NAME, raw=None):
    path = tmp_path / "bad.tle"
    path.write_bytes(raw if raw is not None else "\n".join([name, l1, l2, ""]).encode())
    return path


def _bad_checksum(line):
    return line[:68] + str((tle_checksum(line) + 1) % 10)


@pytest.mark.parametrize("kwargs, message", [
    (dict(l1=_bad_checksum(L1)), r"bad\.tle:2: bad TLE checksum on line 1"),
    (dict(l2=L2[:50]), r"bad\.tle:3: truncated TLE line 2"),
    (dict(l2="3" + L2[1:]), r"bad\.tle:3: expected TLE line 2"),
    (dict(l2=L2[:2] + "25545" + L2[7:68] + str(tle_checksum(L2[:2] + "25545" + L2[7:]))), r"catalogue number 25545"),
    (dict(raw=(NAME + "\n" + L1[:20] + "é" + L1[21:] + "\n" + L2 + "\n").encode()), r"bad\.tle:2: non-ASCII"),
    (dict(raw=b""), r"empty file"),
    (dict(raw=b"\r\n\r\n"), r"empty file"),
    (dict(raw=(NAME + "\n" + L1 + "\n").encode()), r"truncated file"),
    (dict(l1=L1[:8] + "X" + L1[9:]), r"column layout broken \(column 9"),
])
def test_malformed_records_name_file_and_line(tmp_path, kwargs, message):
    with pytest.raises(InputError, match=message):
        read_tle(_write(tmp_path, **kwargs))


def test_skip_bad_warns_and_keeps_the_good_records(tmp_path):
    good2 = [L1.replace("25544", "25545")[:68], L2.replace("25544", "25545")[:68]]
    good2 = [ln + str(tle_checksum(ln)) for ln in good2]
    text = "\n".join([NAME, _bad_checksum(L1), L2, "OTHER", *good2, ""])
    path = tmp_path / "mixed.tle"
    path.write_text(text)
    with pytest.raises(InputError, match="mixed.tle:2"):
        read_tle(path)
    with pytest.warns(UserWarning, match="skipping bad record: .*mixed.tle:2"):
        const = read_tle(path, skip_bad=True)
    assert const.sat_ids.tolist() == ["25545"] and const.names == ("OTHER",)


def test_missing_and_directory_paths(tmp_path):
    with pytest.raises(InputError, match="no such TLE file"):
        read_tle(tmp_path / "nope.tle")
    with pytest.raises(InputError, match="is a directory"):
        read_tle(tmp_path)


def _omm_record():
    # The same ISS element set written as CelesTrak OMM fields.
    return {
        "OBJECT_NAME": NAME, "OBJECT_ID": "1998-067A", "EPOCH": "2008-09-20T12:25:40.104192",
        "MEAN_MOTION": 15.72125391, "ECCENTRICITY": 0.0006703, "INCLINATION": 51.6416,
        "RA_OF_ASC_NODE": 247.4627, "ARG_OF_PERICENTER": 130.536, "MEAN_ANOMALY": 325.0288,
        "EPHEMERIS_TYPE": 0, "CLASSIFICATION_TYPE": "U", "NORAD_CAT_ID": 25544, "ELEMENT_SET_NO": 292,
        "REV_AT_EPOCH": 56353, "BSTAR": -1.1606e-5, "MEAN_MOTION_DOT": -2.182e-5, "MEAN_MOTION_DDOT": 0,
    }


@pytest.mark.parametrize("fmt", ["json", "csv"])
def test_omm_matches_the_tle_it_describes(tmp_path, fmt):
    rec = _omm_record()
    path = tmp_path / f"iss.{fmt}"
    if fmt == "json":
        path.write_text(json.dumps([rec]))
    else:
        path.write_text(",".join(rec) + "\n" + ",".join(str(v) for v in rec.values()) + "\n")
    omm = read_omm(path)
    tle = read_tle(_write(tmp_path))
    assert omm.sat_ids.tolist() == ["25544"] and omm.names == (NAME,)
    times = tle.epochs_utc[0] + np.arange(0, 86400, 3600).astype("timedelta64[s]")
    r1, _, _ = state_teme(omm, times)
    r2, _, _ = state_teme(tle, times)
    # The TLE rounds the epoch to 1e-8 day (~1 ms, ~8 m along track at most);
    # both carry the same elements otherwise.
    np.testing.assert_allclose(r1, r2, atol=10.0)
    assert load_constellation(path).sat_ids.tolist() == ["25544"]


def test_omm_missing_field(tmp_path):
    rec = _omm_record()
    del rec["MEAN_MOTION"]
    path = tmp_path / "x.json"
    path.write_text(json.dumps([rec]))
    with pytest.raises(InputError, match="record 1: missing OMM field MEAN_MOTION"):
        read_omm(path)


def test_unknown_ids_and_families_are_named():
    const = load_constellation()
    with pytest.raises(InputError, match="99999"):
        const.select_ids(["70001", "99999"])
    with pytest.raises(InputError, match="unknown constellation"):
        const.family("galileo")
