"""Bad IMU logs and GNSS products: one-line errors that name the file, line and field, in the file's own values.

Each test reproduces an audit finding; the command-line tests also check that
only that one line reaches stderr.
"""

import gzip
import json
import warnings

import hatanaka
import numpy as np
import pytest

from leosop.cli import main
from leosop.errors import InputError
from leosop.gnss.rinex import read_obs
from leosop.gnss.products import Clocks, Orbits, read_sp3, uncovered_note
from leosop.ins import imu_io
from tests.helpers import ESBC_CLK, ESBC_NAV, ESBC_OBS, ESBC_SP3, data_path

_PSINS_HEADER = ["% PSINS-format SIMU log file", "", "0 0 -90.6 0 0 0", "34.246048 108.909664 380 0 10 9.780327",
                 "0.1 0.1 0.1 125 125 125"]


def _write_psins(path, header=_PSINS_HEADER, n=200):
    path.write_text("\n".join(header + ["0 0 2 0 0 80"] * n) + "\n")
    return path


def _cli_error(capsys, argv):
    """Run the CLI, expect exit 2 and exactly one stderr line; return that line."""
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2
    assert len(err.strip().splitlines()) == 1, err
    return err.strip()


def test_psins_header_latitude_named_as_the_file_field(tmp_path, capsys):
    header = _PSINS_HEADER.copy()
    header[3] = "134.24604800 108.909664 380 0 10 9.780327"
    path = _write_psins(tmp_path / "lat.imu", header)
    err = _cli_error(capsys, ["align", "--imu", str(path)])
    assert "--lat-deg" not in err
    assert "lat.imu:4: header latitude 134.24604800 deg must be within [-90, 90]" in err


def test_psins_zero_quanta_reported_on_their_own_line(tmp_path):
    header = _PSINS_HEADER.copy()
    header[4] = "0 0 0 0 0 0"
    path = _write_psins(tmp_path / "sf0.imu", header)
    with pytest.raises(InputError, match=r"sf0\.imu:5: the gyro and accelerometer quanta \[0, 0, 0, 0, 0, 0\]"):
        imu_io.read_psins(path)


def test_imu_time_going_back_quoted_as_written(tmp_path, capsys):
    rows = [f"{1756402241.5630851 + 0.006 * k:.7f},-0.0168877,-0.0065302,1.0107665,0.0017089,-0.0026242,0.0029633,"
            "0,0,0,0" for k in range(200)]
    rows[100] = "1756402141.6020906" + rows[100][rows[100].index(","):]
    path = tmp_path / "sf_back.csv"
    path.write_text("\n".join(rows) + "\n")
    err = _cli_error(capsys, ["align", "--imu", str(path), "--format", "csv", "--lat-deg", "45"])
    assert "np.float64" not in err
    assert (f"sf_back.csv:101: time 1756402141.6020906 is not after the previous sample's {rows[99].split(',')[0]}"
            in err)


def _write_sp3(path, x_text="-11562.163582", epoch="2020  6 25  0  0  0.00000000"):
    lines = ["#dP2020  6 25  0  0  0.00000000       2 ORBIT IGS14 FIT  GRG",
             f"*  {epoch}",
             f"PE01 {x_text:>13s}  14053.114306  23345.128269   -884.707516",
             "*  2020  6 25  0 15  0.00000000",
             "PE01 -11562.163582  14053.114306  23345.128269   -884.707516",
             "EOF"]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("x_text, epoch, message", [
    ("abc2.163582", "2020  6 25  0  0  0.00000000",
     "x.sp3: line 3: position record PE01: X coordinate [km] 'abc2.163582' is not a number"),
    ("-11562.163582", "2   abc.163582 0  0.00000000",
     "x.sp3: line 2: epoch record '*  2   abc.163582 0  0.00000000': month 'abc.163582' is not a number"),
])
def test_sp3_unreadable_field_named(tmp_path, x_text, epoch, message):
    with pytest.raises(InputError) as info:
        read_sp3(_write_sp3(tmp_path / "x.sp3", x_text, epoch))
    assert message in str(info.value)


def test_products_short_of_the_observations_noted():
    day = np.datetime64("2020-06-25T00:00:00", "ns")
    obs_times = day + np.arange(2880) * np.timedelta64(30, "s")
    half_orbits = Orbits("s_trunc.sp3", day, 900.0 * np.arange(48), ["G01"], np.zeros((48, 1, 3)))
    note = uncovered_note(half_orbits, obs_times)
    assert note == ("s_trunc.sp3: records cover only 2020-06-25T00:00:00 to 2020-06-25T11:45:00 GPST, the "
                    "observations 2020-06-25T00:00:00 to 2020-06-25T23:59:30: 1466 of the 2880 epochs are left out")
    half_clocks = Clocks("c_trunc.clk", day, 30.0 * np.arange(1440), ["G01"], np.zeros((1440, 1)))
    assert "c_trunc.clk: records cover only 2020-06-25T00:00:00 to 2020-06-25T11:59:30 GPST" in uncovered_note(
        half_clocks, obs_times)
    # A whole day's 15-min orbits end at 23:45: the last minutes are no truncation.
    day_orbits = Orbits("day.sp3", day, 900.0 * np.arange(96), ["G01"], np.zeros((96, 1, 3)))
    assert uncovered_note(day_orbits, obs_times) is None
    # One record late at the start is: orbits answer 0.1 spacing before their first record, the first 27
    # epochs (00:00 to 00:13:00) are left out, with the day's last 26 (after 23:46:30) as always.
    late = Orbits("late.sp3", day, 900.0 * np.arange(1, 96), ["G01"], np.zeros((95, 1, 3)))
    assert uncovered_note(late, obs_times).endswith(": 53 of the 2880 epochs are left out")


def test_ppp_on_half_an_sp3_warns_and_runs(tmp_path, capsys):
    sp3 = tmp_path / "s_trunc.sp3"
    with gzip.open(data_path("rinex", "esbc_2020-177", ESBC_SP3.name), "rt") as f:
        lines = f.read().splitlines()
    sp3.write_text("\n".join(lines[:len(lines) // 2]) + "\n")
    status = main(["ppp", str(ESBC_OBS), "--nav", str(ESBC_NAV), "--sp3", str(sp3), "--clk", str(ESBC_CLK),
                   "--static", "--json"])
    out, err = capsys.readouterr()
    assert status == 0
    warned = json.loads(out)["summary"]["warnings"]
    assert len(warned) == 1 and "s_trunc.sp3: records cover only" in warned[0] and "epochs are left out" in warned[0]
    assert f"warning: {warned[0]}" in err


def _small_crinex(path, version=b"3.05"):
    """The ESBC day's header and first epoch (epoch line, clock line, one line per satellite), as RINEX ``version``."""
    with gzip.open(data_path("rinex", "esbc_2020-177", ESBC_OBS.name)) as f:
        lines = f.read().split(b"\n")
    end = next(i for i, line in enumerate(lines) if b"END OF HEADER" in line)
    n_sats = int(lines[end + 1][32:35])
    path.write_bytes(b"\n".join(lines[:end + 3 + n_sats]).replace(
        b"     3.05           OBSERVATION DATA", b"     " + version + b"           OBSERVATION DATA") + b"\n")
    return path


def test_crinex_of_rinex2_gives_the_one_error_line(tmp_path, capsys):
    crx = _small_crinex(tmp_path / "o_ver2.crx", b"2.11")
    err = _cli_error(capsys, ["ppp", str(crx), "--nav", str(ESBC_NAV), "--sp3", str(ESBC_SP3), "--clk", str(ESBC_CLK)])
    assert "crx2rnx" not in err
    assert "o_ver2.crx: line 1: RINEX version 2.11, this reader needs RINEX 3" in err


def test_expander_warning_on_a_file_read_names_the_file(tmp_path, monkeypatch):
    crx = _small_crinex(tmp_path / "o.crx")
    decompress = hatanaka.decompress

    def warning_decompress(raw):
        warnings.warn("crx2rnx: line 58 : skip until an initialized epoch is found.", stacklevel=1)
        return decompress(raw)

    monkeypatch.setattr(hatanaka, "decompress", warning_decompress)
    with pytest.warns(UserWarning) as caught:
        assert len(read_obs(crx).time_gps) == 1
    assert [str(w.message) for w in caught] == [f"{crx}: crx2rnx: line 58 : skip until an initialized epoch is found."]
