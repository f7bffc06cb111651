"""Hostile files for the readers: wrong types, impossible values, wrong encodings (issue 13).

Every rejection is an InputError whose one-line message names the file and
the field.
"""

import copy
import json

import pytest

from leosop.cli import main
from leosop.ins.imu_io import read_rtklib_sf_csv
from leosop.orbits import DEFAULT_TLE, read_omm, read_tle
from leosop.orbits.tle import tle_checksum
from leosop.signal.iq import open_sigmf

from tests.helpers import one_line_error

_OMM = {"OBJECT_NAME": "STARLINK-1007", "NORAD_CAT_ID": 44713, "EPOCH": "2025-01-01T00:00:00.000",
        "MEAN_MOTION": 15.06, "ECCENTRICITY": 0.0001, "INCLINATION": 53.05, "RA_OF_ASC_NODE": 10.0,
        "ARG_OF_PERICENTER": 90.0, "MEAN_ANOMALY": 270.0, "BSTAR": 0.0001, "MEAN_MOTION_DOT": 1e-5,
        "MEAN_MOTION_DDOT": 0}


@pytest.mark.parametrize("top", ["0", "null", '"starlink"', "3.5"])
def test_omm_json_top_level_not_a_list(tmp_path, top):
    path = tmp_path / "set.json"
    path.write_text(top)
    one_line_error(lambda: read_omm(path), "set.json", "expected a JSON list of OMM objects")


@pytest.mark.parametrize("field, value, message", [
    ("BSTAR", "NaN", "BSTAR nan is not a finite number"),
    ("MEAN_MOTION", -15.06, "mean motion -15.06 rev/day is outside"),
    ("INCLINATION", 999.9999, "inclination 999.9999 deg is outside [0, 180]"),
    ("ECCENTRICITY", 1.5, "eccentricity"),
    ("EPOCH", "7827-01-01T00:00:00.000", "epoch year 7827"),
    ("NORAD_CAT_ID", "4" * 60, "OMM field NORAD_CAT_ID: expected a catalogue number 1..339999"),
])
def test_omm_impossible_values(tmp_path, field, value, message):
    path = tmp_path / "set.json"
    path.write_text(json.dumps([{**_OMM, field: value}]))
    one_line_error(lambda: read_omm(path), "set.json: record 1", message)


def test_omm_good_record_still_reads(tmp_path):
    path = tmp_path / "set.json"
    path.write_text(json.dumps([_OMM]))
    assert list(read_omm(path).sat_ids) == ["44713"]


def _tle_with(line_no, col0, text):
    """The bundled first element set with ``text`` at 0-based column ``col0`` of line 1 or 2, checksum fixed."""
    name, l1, l2 = DEFAULT_TLE.read_text().splitlines()[:3]
    lines = {1: l1, 2: l2}
    line = lines[line_no]
    line = line[:col0] + text + line[col0 + len(text):68]
    lines[line_no] = line + str(tle_checksum(line))
    return f"{name}\n{lines[1]}\n{lines[2]}\n"


@pytest.mark.parametrize("line_no, col0, text, where, message", [
    (2, 8, "999.9999", 2, "inclination 999.9999 deg is outside [0, 180]"),
    (1, 20, "999.00000000", 2, "epoch day of year 999"),
    (2, 52, "99.00000000", 2, "mean motion 99 rev/day is outside"),
    (2, 17, "400.0000", 2, "right ascension of the node 400.0000 deg"),
])
def test_tle_valid_checksum_impossible_values(tmp_path, line_no, col0, text, where, message):
    path = tmp_path / "bad.tle"
    path.write_text(_tle_with(line_no, col0, text))
    one_line_error(lambda: read_tle(path), f"bad.tle:{where}:", message)


def test_tle_unchanged_record_reads(tmp_path):
    path = tmp_path / "good.tle"
    path.write_text(_tle_with(2, 8, " 53.0000"))
    assert len(read_tle(path)) == 1


_META = {"global": {"core:datatype": "cf32_le", "core:sample_rate": 1000.0, "core:version": "1.2.0"},
         "captures": [{"core:sample_start": 0, "core:frequency": 11325000000.0,
                       "core:datetime": "2025-01-01T00:00:00Z"}],
         "annotations": [{"core:sample_start": 0, "core:sample_count": 64, "leosop:sat_id": "1",
                          "leosop:doppler_hz": 5.0}]}


def _sigmf(tmp_path, edit):
    meta = copy.deepcopy(_META)
    meta = edit(meta) or meta
    (tmp_path / "r.sigmf-data").write_bytes(bytes(8 * 1000))
    path = tmp_path / "r.sigmf-meta"
    path.write_text(json.dumps(meta))
    return path


@pytest.mark.parametrize("edit, message", [
    (lambda m: [m], "expected a JSON object with a 'global' object"),
    (lambda m: m["captures"][0].update({"core:frequency": "11e9"}), "core:frequency '11e9' must be a positive"),
    (lambda m: m["captures"][0].update({"core:frequency": 0}), "core:frequency 0 must be a positive number"),
    (lambda m: m["global"].update({"leosop:n_tones": "9"}), "leosop:n_tones '9' must be an odd integer"),
    (lambda m: m["global"].update({"leosop:n_tones": 4}), "leosop:n_tones 4 must be an odd integer"),
    (lambda m: m["global"].update({"leosop:tone_spacing_hz": "x"}), "leosop:tone_spacing_hz 'x' must be a number"),
    (lambda m: m["global"].update({"core:sample_rate": "1000"}), "core:sample_rate '1000' must be a number"),
    (lambda m: m["global"].update({"core:num_channels": True}), "core:num_channels True must be an integer"),
    # 0 crashed the sigmf package (a division by it); 2 was refused only after it.
    (lambda m: m["global"].update({"core:num_channels": 0}), "core:num_channels 0 is not supported; expected 1"),
    (lambda m: m["global"].update({"core:num_channels": 2}), "core:num_channels 2 is not supported; expected 1"),
    (lambda m: m["annotations"][0].update({"core:sample_start": "0"}), "annotation 0: core:sample_start '0'"),
    (lambda m: m["annotations"][0].update({"core:sample_count": 6.5}), "annotation 0: core:sample_count 6.5"),
    (lambda m: m["annotations"][0].update({"leosop:doppler_hz": "5"}), "annotation 0: leosop:doppler_hz '5'"),
    (lambda m: m["annotations"][0].update({"leosop:sat_id": 1}), "annotation 0: leosop:sat_id 1 must be a string"),
])
def test_sigmf_wrong_types(tmp_path, edit, message):
    path = _sigmf(tmp_path, edit)
    one_line_error(lambda: open_sigmf(path), "r.sigmf-meta", message)


def test_sigmf_empty_data_file_is_named(tmp_path):
    path = _sigmf(tmp_path, lambda m: None)
    path.with_suffix(".sigmf-data").write_bytes(b"")
    one_line_error(lambda: open_sigmf(path), "r.sigmf-data", "empty SigMF data file (no samples for r.sigmf-meta)")


def test_sigmf_good_metadata_opens(tmp_path):
    rec = open_sigmf(_sigmf(tmp_path, lambda m: None))
    assert rec.center_hz == 11325000000.0 and rec.n_samples == 1000


def test_scenario_not_utf8_is_bad_input(tmp_path, capsys):
    path = tmp_path / "scenario.json"
    path.write_bytes(b'{"name": "caf\xe9"}')
    status = main(["simulate", "--scenario", str(path), "--level", "measurement", "--json"])
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert "not UTF-8 text" in err and len(err.strip().splitlines()) == 1


def test_empty_imu_sf_csv(tmp_path):
    path = tmp_path / "imu_sf.csv"
    path.write_text("")
    one_line_error(lambda: read_rtklib_sf_csv(path), "imu_sf.csv", "0 line(s)")


def test_imu_sf_csv_time_beyond_gps_era(tmp_path):
    path = tmp_path / "imu_sf.csv"
    rows = [f"{1.6e15 + 0.01 * k:.2f},0,0,1,0,0,0,0,0,0,0" for k in range(20)]
    path.write_text("\n".join(rows) + "\n")
    one_line_error(lambda: read_rtklib_sf_csv(path), "imu_sf.csv", "is not GPST seconds since 1970")


def test_omm_csv_with_a_byte_order_mark(tmp_path):
    path = tmp_path / "set.csv"
    path.write_text("\ufeff" + ",".join(_OMM) + "\n" + ",".join(str(v) for v in _OMM.values()) + "\n")
    assert list(read_omm(path).sat_ids) == ["44713"]
