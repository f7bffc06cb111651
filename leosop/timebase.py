"""Time: UTC instants at the edges, split Julian dates for SGP4 and UT1.

UTC instants are ``numpy.datetime64[ns]`` (ISO 8601 in files). SGP4 takes
UTC Julian dates split into a whole part and a fraction so that nanoseconds
survive; Earth orientation needs UT1, taken from skyfield's bundled IERS
table (observed values, then its predictions).
"""

import re
from functools import lru_cache

import numpy as np

from .constants import DAY_S, JD_UNIX_EPOCH
from .errors import InputError

__all__ = ["parse_utc", "split_utc_offset", "round_utc", "format_utc", "seconds_since", "utc_from_seconds",
           "jd_utc", "jd_ut1", "utc_from_jd", "ut1_minus_utc_s"]

_NS_PER_DAY = int(DAY_S) * 1_000_000_000


#: First and last instants a datetime64[ns] holds (whole days inside its range).
_NS_SPAN = (np.datetime64("1678-01-01"), np.datetime64("2261-12-31"))


#: An ISO 8601 time of day ending in a UTC offset: the time, sign, hours and minutes (``+01:00``, ``+0100``,
#: ``+01``). numpy parses such offsets with a warning and shifts by them; the toolkit reads them itself.
_UTC_OFFSET = re.compile(r"(.*\d:\d\d(?::\d\d(?:\.\d*)?)?)\s*([+-])(\d\d)(?::?(\d\d))?")


#: What numpy is given: an ISO 8601 date and time without a zone (numpy would parse any text after the time
#: as one, with a warning).
_ISO_TIME = re.compile(r"[+-]?\d{4,}(?:-\d\d(?:-\d\d(?:[T ]\d\d(?::\d\d(?::\d\d(?:\.\d*)?)?)?)?)?)?")


def split_utc_offset(text):
    """ISO 8601 ``text`` without its zone, and the zone's offset east of UTC [min].

    A trailing ``Z``, ``+00:00`` or no zone gives 0; an offset beyond 14 h
    (or minutes beyond 59), or text that is no ISO 8601 time
    (``_ISO_TIME``) once the zone is off, gives None.

    Returns
    -------
    time : str
    offset_min : int or None
    """
    s = text.strip()
    offset = 0
    if s.endswith("Z"):
        s = s[:-1]
    elif (m := _UTC_OFFSET.fullmatch(s)) is not None:
        hours, minutes = int(m.group(3)), int(m.group(4) or 0)
        if hours > 14 or minutes > 59:
            return s, None
        s, offset = m.group(1), (60 * hours + minutes) * (1 if m.group(2) == "+" else -1)
    return s, offset if _ISO_TIME.fullmatch(s) else None


def parse_utc(value, *, name="time"):
    """UTC instant(s) from ISO 8601 text or datetime64.

    A trailing ``Z`` or ``+00:00`` is accepted; other offsets are refused
    rather than silently shifted.

    Parameters
    ----------
    value : str, datetime64 or array_like of those
    name : str
        What the value is, for the error message.

    Returns
    -------
    numpy.datetime64 or ndarray of datetime64[ns]
    """
    arr = np.asarray(value)
    if np.issubdtype(arr.dtype, np.datetime64):
        return arr.astype("datetime64[ns]")[()]
    flat = []
    for text in arr.ravel():
        s, offset_min = split_utc_offset(str(text))
        if offset_min:
            raise InputError(f"{name}: {str(text)!r} has a UTC offset; give the time in UTC (ending in Z)")
        try:
            if offset_min is None:
                raise ValueError
            native = np.datetime64(s)  # its own unit: years beyond datetime64[ns] do not wrap around here
        except ValueError:
            raise InputError(f"{name}: {str(text)!r} is not an ISO 8601 UTC time (e.g. 2024-01-02T03:04:05Z)") from None
        if not np.isnat(native) and not _NS_SPAN[0] <= native <= _NS_SPAN[1]:
            raise InputError(f"{name}: {str(text)!r} is outside the years 1678..2261 that the toolkit's "
                             "nanosecond times hold")
        flat.append(native.astype("datetime64[ns]"))
    out = np.array(flat, dtype="datetime64[ns]").reshape(arr.shape)
    return out[()]


def round_utc(times, unit="us"):
    """UTC instants rounded to the nearest ``unit`` (halves up), not truncated as ``astype`` does.

    A block centre 9999.5 us after a capture start is ``...00.010000``, not
    ``...00.009999``; NaT stays NaT.

    Parameters
    ----------
    times : datetime64 or array_like of datetime64, (...)
    unit : str
        A numpy time unit no finer than ``ns``: ``"us"``, ``"ms"``, ``"s"``.

    Returns
    -------
    numpy.datetime64 or ndarray of datetime64[unit], (...)
    """
    t = np.asarray(times, dtype="datetime64[ns]")
    step_ns = int(np.timedelta64(1, unit) // np.timedelta64(1, "ns"))
    rounded = ((t.astype(np.int64) + step_ns // 2) // step_ns).astype(f"datetime64[{unit}]")
    return np.where(np.isnat(t), np.datetime64("NaT", unit), rounded)[()]


def format_utc(times):
    """ISO 8601 text with a trailing Z, rounded to the microsecond (:func:`round_utc`); list for arrays.

    Every UTC instant the toolkit prints or writes goes through here.
    """
    text = np.datetime_as_string(round_utc(times, "us"), unit="us")
    if np.ndim(text) == 0:
        return str(text) + "Z"
    return [s + "Z" for s in text.ravel().tolist()]


def seconds_since(times, epoch):
    """Float seconds of ``times`` after ``epoch`` (both UTC datetime64)."""
    dt = np.asarray(times, dtype="datetime64[ns]") - np.datetime64(epoch, "ns")
    return dt.astype(np.int64) * 1e-9


def utc_from_seconds(t_s, epoch):
    """UTC instants ``t_s`` float seconds after ``epoch``, rounded to the nanosecond (inverse of :func:`seconds_since`).

    ``k * step_s * 1e9`` is often a hair below a whole number (0.3 s x 3 is
    0.8999999999 s): cast straight to ``timedelta64`` it would lose a nanosecond.

    Parameters
    ----------
    t_s : float or array_like, (...)
    epoch : datetime64 or ISO 8601 text

    Returns
    -------
    numpy.datetime64 or ndarray of datetime64[ns], (...)
    """
    offset = np.round(np.asarray(t_s, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")
    return (np.datetime64(epoch, "ns") + offset)[()]


def jd_utc(times):
    """Split UTC Julian date ``(jd, fr)`` of datetime64 instants, as SGP4 takes it.

    ``jd`` is a whole day at midnight (``x.5``) and ``fr`` the day fraction.
    """
    ns = np.asarray(times, dtype="datetime64[ns]").astype(np.int64)
    days, rem = np.divmod(ns, _NS_PER_DAY)
    return days + JD_UNIX_EPOCH, rem / _NS_PER_DAY


def utc_from_jd(jd, fr):
    """datetime64[ns] UTC of a split Julian date ``(jd, fr)``, the inverse of :func:`jd_utc` (to the nanosecond).

    ``jd`` need not be at midnight: its fraction is carried into ``fr``.
    """
    whole = np.floor(np.asarray(jd, dtype=float) - JD_UNIX_EPOCH)
    carried = np.asarray(jd, dtype=float) - JD_UNIX_EPOCH - whole + np.asarray(fr, dtype=float)
    ns = whole.astype(np.int64) * _NS_PER_DAY + np.round(carried * _NS_PER_DAY).astype(np.int64)
    return ns.astype("datetime64[ns]")[()]


@lru_cache(maxsize=1)
def _timescale():
    from skyfield.api import load

    return load.timescale(builtin=True)


def ut1_minus_utc_s(times):
    """UT1 - UTC [s] at UTC instants, from skyfield's bundled IERS data."""
    t = np.asarray(times, dtype="datetime64[ns]")
    flat = t.ravel()
    if flat.size == 0:
        return np.zeros(t.shape)
    # UT1-UTC changes by well under 1 ms per hour: evaluate on an hourly grid
    # and interpolate, except across a leap second where it jumps by 1 s.
    hours = flat.astype("datetime64[h]")
    grid = np.arange(hours.min(), hours.max() + np.timedelta64(2, "h"), np.timedelta64(1, "h"))
    ymd = grid.astype("datetime64[D]")
    year = ymd.astype("datetime64[Y]").astype(int) + 1970
    month = ymd.astype("datetime64[M]").astype(int) % 12 + 1
    day = (ymd - ymd.astype("datetime64[M]")).astype(int) + 1
    hour = (grid - ymd).astype(int)
    dut1 = np.atleast_1d(_timescale().utc(year, month, day, hour).dut1)
    x = seconds_since(grid, grid[0])
    # Unwrap leap-second jumps before interpolating, wrap back after.
    steps = np.round(np.diff(dut1))
    smooth = dut1 - np.concatenate([[0.0], np.cumsum(steps)])
    xi = seconds_since(flat, grid[0])
    k = np.clip(np.searchsorted(x, xi, side="right") - 1, 0, len(x) - 1)
    jumps = np.concatenate([[0.0], np.cumsum(steps)])[k]
    return (np.interp(xi, x, smooth) + jumps).reshape(t.shape)


def jd_ut1(times):
    """Split UT1 Julian date ``(jd, fr)`` at UTC instants, for Earth rotation."""
    jd, fr = jd_utc(times)
    fr = fr + ut1_minus_utc_s(times) / DAY_S
    whole = np.floor(fr)
    return jd + whole, fr - whole
