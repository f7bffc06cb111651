"""Product and observation readers on small hand-written files: epochs, record grids, bad input.

The expected epochs are calendar facts (2020 is a leap year, 2021 is not);
the expected refusals are the one-line InputErrors of DESIGN 4.1, naming the
file and the line.
"""

import gzip

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.gnss.products import read_clk, read_sp3
from leosop.gnss.rinex import epochs_gps, read_obs, read_text

_CLK_HEAD = ("     3.00           C                                       RINEX VERSION / TYPE\n"
             "                                                            END OF HEADER\n")


def _clk(tmp_path, epochs, name="sat.clk"):
    """A clock file with G01 and G02 records at ``epochs`` (strings 'yyyy mm dd hh mi ss.ssssss')."""
    body = "".join(f"AS {sv}  {e}  2    1.0e-04  1.0e-11\n" for e in epochs for sv in ("G01", "G02"))
    path = tmp_path / name
    path.write_text(_CLK_HEAD + body)
    return path


def test_epochs_gps_calendar():
    fields = [[2020, 2, 29, 23, 59, 30.5], [2020, 12, 31, 0, 0, 60.0]]  # leap day; a leap second's label
    t = epochs_gps(fields, [10, 20], "f")
    assert t[0] == np.datetime64("2020-02-29T23:59:30.5", "ns")
    assert t[1] == np.datetime64("2020-12-31T00:01:00", "ns")


@pytest.mark.parametrize("fields, line", [
    ([2021, 2, 29, 0, 0, 0.0], 7),  # no leap day in 2021
    ([2020, 0, 1, 0, 0, 0.0], 7),  # month 0
    ([2020, 6, 25, 24, 0, 0.0], 7),  # hour 24
    ([5777, 6, 25, 0, 0, 0.0], 7),  # far outside datetime64[ns] arithmetic's safe range
    ([2020, 6, 25, 1.5, 0, 0.0], 7),  # fractional hour
    ([2020, 6, 25, 0, 0, np.inf], 7),
])
def test_epochs_gps_refuses_impossible_dates(fields, line):
    with pytest.raises(InputError, match=rf"^f: line {line}: impossible epoch"):
        epochs_gps([[2020, 6, 25, 0, 0, 0.0], fields], [3, line], "f")


def test_clk_grid_with_gap(tmp_path):
    clk = read_clk(_clk(tmp_path, ["2020 06 25 00 00  0.000000", "2020 06 25 00 00 30.000000",
                                   "2020 06 25 00 02  0.000000"]))
    np.testing.assert_array_equal(clk.t_s, [0, 30, 60, 90, 120])
    assert np.isnan(clk.bias_s[2:4]).all() and clk.bias_s[[0, 1, 4]] == pytest.approx(1e-4)


def test_clk_refuses_dense_grid(tmp_path):
    # Epochs 1 microsecond apart and one a day later: a regular grid would have 8.6e10 rows (the fuzzer's
    # multi-GB allocation); refused from the record spacing instead.
    path = _clk(tmp_path, ["2020 06 25 00 00  0.000000", "2020 06 25 00 00  0.000001",
                           "2020 06 25 00 00  0.000002", "2020 06 26 00 00  0.000000"])
    with pytest.raises(InputError, match=r"sat\.clk: clock epochs 1e-06 s apart .*at least 1 s apart"):
        read_clk(path)


def test_clk_refuses_off_grid_and_repeated_epochs(tmp_path):
    path = _clk(tmp_path, ["2020 06 25 00 00  0.000000", "2020 06 25 00 00 30.000000",
                           "2020 06 25 00 01  0.000000", "2020 06 25 00 01 40.000000"])
    with pytest.raises(InputError, match=r"sat\.clk: line 9: clock epoch off the 30 s record grid"):
        read_clk(path)
    path = _clk(tmp_path, ["2020 06 25 00 00 30.000000", "2020 06 25 00 01  0.000000",
                           "2020 06 25 00 00 60.000000"])
    with pytest.raises(InputError, match=r"sat\.clk: line 7: clock epoch repeated"):
        read_clk(path)


def test_sp3_epoch_out_of_order(tmp_path):
    lines = ["#dP2020  6 25  0  0  0.00000000       3 ORBIT IGS14 HLM  IGS"]
    for k, minute in enumerate((0, 30, 15)):
        lines += [f"*  2020  6 25  0 {minute:2d}  0.00000000", "PG01  15000.000000  15000.000000  15000.000000"]
    path = tmp_path / "orb.sp3"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"orb\.sp3: line 4: SP3 epochs not in time order"):
        read_sp3(path)


def test_corrupt_gzip(tmp_path):
    data = bytearray(gzip.compress(_CLK_HEAD.encode() * 50))
    data[30:40] = b"\xff" * 10  # inside the deflate stream: zlib.error, not OSError
    path = tmp_path / "sat.clk.gz"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"sat\.clk\.gz: truncated or corrupt gzip data"):
        read_text(path)


def test_obs_negative_satellite_count(tmp_path):
    head = ("     3.04           OBSERVATION DATA    M                   RINEX VERSION / TYPE\n"
            "G    2 C1C L1C                                              SYS / # / OBS TYPES\n"
            "                                                            END OF HEADER\n")
    path = tmp_path / "obs.rnx"
    path.write_text(head + "> 2020 06 25 00 00  0.0000000  4 -1\n")
    with pytest.raises(InputError, match=r"obs\.rnx: line 4: negative satellite count"):
        read_obs(path)
