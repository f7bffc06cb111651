"""Bad IMU logs and GNSS products: one-line errors that name the file, line and field, in the file's own values.

Each test reproduces an audit finding; the command-line tests also check that
only that one line reaches stderr.
"""

import pytest

from leosop.cli import main
from leosop.errors import InputError
from leosop.gnss.products import read_sp3
from leosop.ins import imu_io

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
