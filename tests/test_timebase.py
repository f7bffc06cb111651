"""Time base: Julian dates, UT1 (vs skyfield), ISO parsing."""

import numpy as np
import pytest

from leosop import timebase


def test_jd_utc_of_j2000_noon_and_nanoseconds_survive():
    jd, fr = timebase.jd_utc(np.array(["2000-01-01T12:00:00", "2000-01-01T12:00:00.000000001"], dtype="datetime64[ns]"))
    assert jd.tolist() == [2451544.5, 2451544.5]
    assert fr[0] == 0.5
    # The day fraction near 0.5 resolves 0.01 ns (double precision), so 1 ns survives to 2 %.
    assert (fr[1] - fr[0]) * 86400e9 == pytest.approx(1.0, rel=2e-2)


def test_ut1_matches_skyfield_and_steps_at_the_2016_leap_second():
    from skyfield.api import load

    ts = load.timescale(builtin=True)
    times = timebase.parse_utc(["2016-12-31T23:30:00", "2017-01-01T00:30:00", "2024-06-01T07:13:20"])
    expected = [ts.utc(2016, 12, 31, 23, 30).dut1, ts.utc(2017, 1, 1, 0, 30).dut1, ts.utc(2024, 6, 1, 7, 13, 20).dut1]
    # Hourly interpolation: UT1-UTC drifts < 3 ms/day, so < 0.2 ms error.
    np.testing.assert_allclose(timebase.ut1_minus_utc_s(times), expected, atol=2e-4)
    assert timebase.ut1_minus_utc_s(times)[1] - timebase.ut1_minus_utc_s(times)[0] == pytest.approx(1.0, abs=1e-2)


def test_parse_and_format_round_trip():
    t = timebase.parse_utc("2026-04-08T12:34:56.789Z")
    assert timebase.format_utc(t) == "2026-04-08T12:34:56.789000Z"
    assert timebase.seconds_since(t, "2026-04-08T12:00:00") == pytest.approx(2096.789)


@pytest.mark.parametrize("text", ["yesterday", "2026-13-01T00:00:00", "2026-04-08T00:00:00+02:00"])
def test_parse_refuses_bad_or_offset_times(text):
    with pytest.raises(ValueError, match="--start"):
        timebase.parse_utc(text, name="--start")
