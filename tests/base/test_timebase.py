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


def _reference_text(ns):
    """ISO text of ``ns`` nanoseconds since 1970 rounded half up to the microsecond, by integer arithmetic and
    :mod:`datetime` (an implementation independent of numpy's datetime64)."""
    import datetime

    us = (int(ns) + 500) // 1000
    t = datetime.datetime(1970, 1, 1) + datetime.timedelta(microseconds=us)
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def test_format_rounds_to_the_microsecond_not_truncates():
    start = np.datetime64("2025-01-01T19:40:04", "ns")
    # A 20 000-sample block at 1 MS/s is centred 9999.5 us after its start: printed ...04.010000, not ...04.009999.
    assert timebase.format_utc(start + np.timedelta64(9_999_500, "ns")) == "2025-01-01T19:40:04.010000Z"
    assert timebase.format_utc(start + np.timedelta64(9_999_499, "ns")) == "2025-01-01T19:40:04.009999Z"
    # Before 1970 the integer count is negative: rounding must still go to the nearest microsecond.
    assert timebase.format_utc(np.datetime64("1969-12-31T23:59:59.9999995", "ns")) == "1970-01-01T00:00:00.000000Z"
    assert timebase.format_utc(np.array(["NaT"], dtype="datetime64[ns]")) == ["NaTZ"]
    rng = np.random.default_rng(20)
    ns = np.concatenate([rng.integers(-2 * 10**18, 4 * 10**18, 2000), rng.integers(0, 10**9, 2000) // 500 * 500])
    assert timebase.format_utc(ns.astype("datetime64[ns]")) == [_reference_text(n) for n in ns]


@pytest.mark.parametrize("unit, text", [("ms", "2025-01-01T19:40:04.010"), ("s", "2025-01-01T19:40:04")])
def test_round_utc_to_coarser_units(unit, text):
    t = np.datetime64("2025-01-01T19:40:04.0099995", "ns")
    assert str(timebase.round_utc(t, unit)) == text
    assert timebase.round_utc(np.array([t, t]), unit).dtype == np.dtype(f"datetime64[{unit}]")


def test_time_grids_from_float_steps_land_on_whole_nanoseconds():
    # k * 0.3 * 1e9 is a hair below k * 3e8 for a quarter of the k: a cast would lose 1 ns there.
    k = np.arange(100_000)
    times = timebase.utc_from_seconds(k * 0.3, "2025-01-01T00:00:00")
    exact = np.datetime64("2025-01-01T00:00:00", "ns") + (k * 300_000_000).astype("timedelta64[ns]")
    np.testing.assert_array_equal(times, exact)
    assert timebase.seconds_since(times, "2025-01-01T00:00:00") == pytest.approx(k * 0.3, abs=1e-9)


def test_utc_from_jd_inverts_sgp4_jday_and_jd_utc():
    # sgp4's own calendar-to-Julian-date conversion is the independent reference.
    from sgp4.api import jday

    jd, fr = jday(2020, 6, 25, 13, 47, 10.25)
    assert timebase.utc_from_jd(jd, fr) == np.datetime64("2020-06-25T13:47:10.250", "ns")
    # A jd that is not at midnight (TLE epochs as Satrec splits them) carries its fraction.
    assert timebase.utc_from_jd(jd + 0.25, fr - 0.25) == np.datetime64("2020-06-25T13:47:10.250", "ns")
    t = np.array(["1957-10-04T19:28:34.123456789", "2056-12-31T23:59:59.999999999"], dtype="datetime64[ns]")
    assert np.array_equal(timebase.utc_from_jd(*timebase.jd_utc(t)), t)
