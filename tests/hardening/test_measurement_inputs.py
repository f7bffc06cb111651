"""Damaged measurement tables and positioning inputs: each gives a one-line InputError naming the file and line."""

import io
import lzma
import tarfile

import numpy as np
import pytest

from leosop.cli import main
from leosop.ins.imu_io import read_rtklib_sf_csv
from leosop.orbits import DEFAULT_TLE
from leosop.positioning.datasets import read_doptrack, read_fll, read_gsdc
from leosop.positioning.measurements import read_measurements

from tests.helpers import one_line_error

# A warning (numpy's about time zones) is output without a file or line: none may appear.
pytestmark = pytest.mark.filterwarnings("error")


def _xz_tar(files):
    """Bytes of a tar.xz archive holding ``{name: text or bytes}``."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:xz") as tar:
        for name, text in files.items():
            data = text.encode() if isinstance(text, str) else text
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


@pytest.mark.parametrize("damage, message", [
    (lambda b: b[:len(b) // 2], "truncated"),
    (lambda b: b"", "not an xz-compressed tar archive"),
    (lambda b: b"time,frequency\n", "not an xz-compressed tar archive"),
    (lambda b: lzma.compress(b"no tar inside"), "not an xz-compressed tar archive"),
], ids=["truncated", "empty", "text", "xz-not-tar"])
def test_doptrack_damaged_archive(tmp_path, damage, message):
    (tmp_path / "data.tar.xz").write_bytes(damage(_xz_tar({"data/pass.csv": "0.0,145870000.0\n" * 200})))
    one_line_error(lambda: read_doptrack(tmp_path), "data.tar.xz", message)


def test_doptrack_truncated_archive_is_exit_2(tmp_path, capsys):
    archive = _xz_tar({"data/pass.csv": "0.0,145870000.0\n" * 200})
    (tmp_path / "data.tar.xz").write_bytes(archive[:len(archive) // 2])
    assert main(["position", str(tmp_path), "--format", "doptrack", "--static"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "data.tar.xz: truncated" in err


_FLL = "index,doppler_offset,timestamp,measured_freq\n0,2240.5,2018-01-13T16:12:01.862011Z,145882240.5\n"


@pytest.mark.parametrize("last, message", [
    ("1,2239.0,2018", "fll.csv:3: no measured_freq field"),
    ("1,2239.0,2018-01-13T16:12:01.962011Z,1458822x", "fll.csv:3: measured_freq '1458822x' is not a number"),
    ("1,2239.0,2018-01-13T25:12:01Z,145882239.0", "fll.csv:3: timestamp: '2018-01-13T25:12:01Z'"),
], ids=["cut-off", "number", "time"])
def test_fll_bad_last_line_names_line_and_field(tmp_path, last, message):
    path = tmp_path / "fll.csv"
    path.write_text(_FLL + last)
    one_line_error(lambda: read_fll(path, "43137"), message)


def test_measurement_table_with_a_byte_order_mark(tmp_path):
    path = tmp_path / "meas.csv"
    path.write_text("\ufefftime_utc,sat_id,doppler_hz\n2025-01-01T19:40:00Z,70002,-186307.1\n", encoding="utf-8")
    meas = read_measurements(path)
    assert list(meas.sat_id) == ["70002"] and meas.doppler_hz[0] == -186307.1


def test_export_csv_with_a_byte_order_mark(tmp_path, capsys):
    path = tmp_path / "fixes.csv"
    path.write_text("\ufefftime_utc,lat_deg,lon_deg,alt_m,status\n2025-01-01T19:40:00Z,34.3,108.9,400.0,ok\n",
                    encoding="utf-8")
    assert main(["export", str(path), "--to", "geojson"]) == 0
    assert (tmp_path / "fixes.geojson").is_file()


def test_imu_csv_with_a_byte_order_mark(tmp_path):
    path = tmp_path / "imu_sf.csv"
    rows = [f"{1.6e9 + 0.01 * k:.2f},0,0,1,0,0,0,0,0,0,0" for k in range(20)]
    path.write_text("\ufeff" + "\n".join(rows) + "\n", encoding="utf-8")
    assert read_rtklib_sf_csv(path).t_s.size == 19


def test_gsdc_csv_with_a_byte_order_mark(tmp_path):
    values = {"utcTimeMillis": "1619712000000", "Svid": "5", "ConstellationType": "1", "SignalType": "GPS_L1",
              "PseudorangeRateMetersPerSecond": "100.0", "PseudorangeRateUncertaintyMetersPerSecond": "0.1",
              "SvClockDriftMetersPerSecond": "0.0", "RawPseudorangeMeters": "2.2e7", "DriftNanosPerSecond": "0.0",
              **{f"SvPosition{a}EcefMeters": "1.5e7" for a in "XYZ"},
              **{f"SvVelocity{a}EcefMetersPerSecond": "1000.0" for a in "XYZ"}}
    path = tmp_path / "device_gnss.csv"
    path.write_text("\ufeff" + ",".join(values) + "\n" + ",".join(values.values()) + "\n", encoding="utf-8")
    assert read_gsdc(path).meas.time_utc[0] == np.datetime64("2021-04-29T16:00:00", "ns")


@pytest.mark.parametrize("time_utc", ["2025-01-01T20:40:00+01:00", "2025-01-01T14:40:00-0500",
                                      "2025-01-01T20:40:00 +01:00"])
def test_measurement_time_with_utc_offset_is_converted(tmp_path, time_utc):
    path = tmp_path / "meas.csv"
    path.write_text(f"time_utc,sat_id,doppler_hz\n{time_utc},70002,-186307.1\n")
    assert read_measurements(path).time_utc[0] == np.datetime64("2025-01-01T19:40:00", "ns")


@pytest.mark.parametrize("time_utc", ["2025-01-01T19:40:00+1", "2025-01-01T19:40:00.5x", "2025-01-01T19:40:00+25:00"])
def test_measurement_time_with_bad_suffix_names_line_and_value(tmp_path, time_utc):
    path = tmp_path / "meas.csv"
    path.write_text(f"time_utc,sat_id,doppler_hz\n2025-01-01T19:40:00Z,70002,1.0\n{time_utc},70003,2.0\n")
    (line, reason), = read_measurements(path).rejected
    assert line == 3 and reason.startswith(f"time_utc is {time_utc!r}, expected ISO 8601 in UTC or with a UTC offset")


@pytest.mark.parametrize("row", ["1,inf,2018-01-13T16:12:01.962011Z,145882239.0",
                                 "1,2239.0,2018-01-13T16:12:01.962011Z,-5.0"])
def test_fll_offset_not_finite_or_carrier_not_positive_names_the_line(tmp_path, row):
    path = tmp_path / "fll.csv"
    path.write_text(_FLL + row + "\n")
    one_line_error(lambda: read_fll(path, "43137"), "fll.csv:3: doppler_offset", "(1 such row(s))")


def test_fll_time_with_a_bad_suffix_is_refused_without_a_warning(tmp_path):
    path = tmp_path / "fll.csv"
    path.write_text(_FLL + "1,2239.0,2018-01-13T16:12:01.962011+01,145882239.0\n")
    one_line_error(lambda: read_fll(path, "43137"), "fll.csv:3: timestamp: '2018-01-13T16:12:01.962011+01'")


def test_no_sat_id_of_the_table_in_the_element_sets(tmp_path, capsys):
    tle = tmp_path / "one.tle"
    tle.write_text("\n".join(DEFAULT_TLE.read_text().splitlines()[:3]) + "\n")
    path = tmp_path / "meas.csv"
    path.write_text("time_utc,sat_id,doppler_hz\n2025-01-01T19:40:00Z,99999,1.0\n2025-01-01T19:40:00Z,99998,2.0\n")
    assert main(["position", str(path), "--tle", str(tle)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "meas.csv: no sat_id of the table (99998, 99999) has an element set in " in err
    assert "one.tle; give the satellites' element sets as --tle" in err


def test_export_latitude_out_of_range_names_line_and_value(tmp_path, capsys):
    path = tmp_path / "fixes.csv"
    path.write_text("time_utc,lat_deg,lon_deg,alt_m,status\n2025-01-01T19:40:00Z,34.3,108.9,400.0,ok\n"
                    "2025-01-01T19:40:01Z,123,108.9,400.0,ok\n")
    assert main(["export", str(path), "--to", "geojson"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "fixes.csv:3: lat_deg 123 is outside [-90, 90] deg" in err


@pytest.mark.parametrize("csv_bytes, yml_bytes, message", [
    (b"0;145871000\n", b"{}", "pass p: malformed p.csv or p.yml (ValueError: could not convert"),
    (b"0,145871000\n", b"tracking: {}\n", "pass p: malformed p.csv or p.yml (KeyError: 'epoch')"),
    (b"0,145871000\n", b"a: [\n", "pass p: malformed p.csv or p.yml (ParserError"),
    (b"\xff\xfe0,1\n", b"{}", "data.tar.xz: data/p.csv is not UTF-8 text"),
])
def test_doptrack_malformed_member_names_the_pass(tmp_path, csv_bytes, yml_bytes, message):
    """A valid archive whose files are not DopTrack's gave an internal error (ValueError, KeyError, YAML)."""
    (tmp_path / "data.tar.xz").write_bytes(_xz_tar({"data/p.csv": csv_bytes}))
    (tmp_path / "metadata.tar.xz").write_bytes(_xz_tar({"metadata/p.yml": yml_bytes}))
    one_line_error(lambda: read_doptrack(tmp_path), message)
