"""Two-line element set files (2-line and 3-line), checked strictly.

Accepts LF, CRLF, CR and the doubled CR-CR-LF line endings found in the wild,
blank lines, ``#`` comment lines, and CelesTrak's optional ``0 `` prefix on name lines. Each record
is checked for ASCII text, line numbers, the column layout, matching
catalogue numbers, the modulo-10 checksums and a number in each numeric field
(SGP4 reads text there as 0 or shifted values) before SGP4 initialises it, then
the element values for ones no orbit has (:func:`check_elements`: an
inclination of 999 deg or a day of year 999 pass the checksum). A bad
record raises :class:`~leosop.errors.InputError` naming the file and line,
or, with ``skip_bad=True``, is skipped with a warning.
"""

import math
import os
import re
import warnings
from pathlib import Path

import numpy as np
from sgp4.api import Satrec

from ..constants import JD_UNIX_EPOCH
from ..errors import InputError
from ..fileio import check_input_file
from ..timebase import utc_from_jd
from .constellation import Constellation

__all__ = ["read_tle", "parse_tle_lines", "tle_checksum", "satrec_epoch_utc", "check_elements"]

#: Element-set epochs outside these years cannot be right: two-digit TLE years
#: cover 1957-2056, and datetime64[ns] ends in 2262.
_EPOCH_YEARS = (1957, 2200)
#: Largest mean motion [rev/day] of an orbit above the atmosphere (~16.5 at reentry).
_MAX_REV_PER_DAY = 20.0
# Columns (0-based) that must be blank in each line of a valid element set.
_BLANKS = {"1": (1, 8, 17, 32, 43, 52, 61, 63), "2": (1, 7, 16, 25, 33, 42, 51)}
_DECIMAL = (re.compile(r" *[+-]?(\d+\.?\d*|\.\d+) *", re.ASCII), "a decimal number")
_INTEGER = (re.compile(r" *\d*", re.ASCII), "a whole number")
_EXPONENT = (re.compile(r"[ +-][\d ]{5}[ +-][\d ]", re.ASCII), "a number in TLE exponent form such as -12345-4")
_CATALOGUE = (re.compile(r" *\d+|[A-HJ-NP-Z]\d{4}", re.ASCII), "a catalogue number (digits, or a letter and 4 digits)")
# The numeric fields of each line: first and last column (1-based), name, pattern and what it should hold. Blanks
# in the implied-decimal fields read as zeros, as in SGP4's own parser.
_FIELDS = {
    "1": ((3, 7, "catalogue number", *_CATALOGUE),
          (19, 20, "epoch year", re.compile(r"[ \d]\d", re.ASCII), "two digits"),
          (21, 32, "epoch day of year", *_DECIMAL), (34, 43, "mean motion derivative", *_DECIMAL),
          (45, 52, "mean motion second derivative", *_EXPONENT), (54, 61, "BSTAR", *_EXPONENT),
          (63, 63, "ephemeris type", re.compile(r"[ \d]", re.ASCII), "a digit"),
          (65, 68, "element set number", *_INTEGER)),
    "2": ((3, 7, "catalogue number", *_CATALOGUE), (9, 16, "inclination", *_DECIMAL),
          (18, 25, "right ascension of the node", *_DECIMAL),
          (27, 33, "eccentricity", re.compile(r"[\d ]{7}", re.ASCII), "7 digits after an implied decimal point"),
          (35, 42, "argument of perigee", *_DECIMAL), (44, 51, "mean anomaly", *_DECIMAL),
          (53, 63, "mean motion", *_DECIMAL), (64, 68, "revolution number", *_INTEGER)),
}
# What each byte adds to the checksum: its value for a digit, 1 for '-', else 0. A table look-up in C: parsing a
# 10,000-satellite snapshot spent 60% of its time summing characters one by one in Python.
_CHECKSUM_VALUES = bytes(b - 48 if 48 <= b <= 57 else int(b == 45) for b in range(256))


def tle_checksum(line):
    """Modulo-10 checksum of the first 68 columns (ASCII digits, and 1 for each '-')."""
    return sum(line[:68].encode("ascii", "replace").translate(_CHECKSUM_VALUES)) % 10


def satrec_epoch_utc(satrec):
    """Element-set epoch of a Satrec as datetime64[ns]."""
    return utc_from_jd(satrec.jdsatepoch, satrec.jdsatepochF)


def check_elements(sat, where):
    """Refuse element values that no orbit has, naming ``where`` (file:line or record).

    They pass checksums and often SGP4's own checks, then give NaN states or
    satellites that are never visible without a word.

    Raises
    ------
    InputError
    """
    year = 1970.0 + (sat.jdsatepoch + sat.jdsatepochF - JD_UNIX_EPOCH) / 365.25
    rev_per_day = sat.no_kozai * 1440.0 / (2.0 * math.pi)
    angles = (("inclination", sat.inclo, 180.0), ("right ascension of the node", sat.nodeo, 360.0),
              ("argument of perigee", sat.argpo, 360.0), ("mean anomaly", sat.mo, 360.0))
    if not _EPOCH_YEARS[0] <= year <= _EPOCH_YEARS[1]:
        raise InputError(f"{where}: epoch year {year:.0f} is outside {_EPOCH_YEARS[0]}..{_EPOCH_YEARS[1]}")
    if not 1.0 <= sat.epochdays < 367.0:
        raise InputError(f"{where}: epoch day of year {sat.epochdays:.8f} is outside 1..366")
    for name, value, top in angles:
        if not 0.0 <= math.degrees(value) <= top:
            raise InputError(f"{where}: {name} {math.degrees(value):.4f} deg is outside [0, {top:g}]")
    if not 0.0 <= sat.ecco < 1.0:
        raise InputError(f"{where}: eccentricity {sat.ecco:g} is outside [0, 1)")
    if not 0.0 < rev_per_day <= _MAX_REV_PER_DAY:
        raise InputError(f"{where}: mean motion {rev_per_day:g} rev/day is outside (0, {_MAX_REV_PER_DAY:g}]")
    for name, value in (("BSTAR", sat.bstar), ("mean motion derivative", sat.ndot),
                        ("mean motion second derivative", sat.nddot)):
        if not math.isfinite(value):
            raise InputError(f"{where}: {name} {value} is not a finite number")


def _check_line(text, expect, where):
    if len(text) < 69:
        raise InputError(f"{where}: truncated TLE line {expect} ({len(text)} characters, expected 69)")
    if len(text) > 69:
        raise InputError(f"{where}: TLE line {expect} too long ({len(text)} characters, expected 69)")
    if text[0] != expect:
        raise InputError(f"{where}: expected TLE line {expect}, found line number {text[0]!r}")
    bad = [c + 1 for c in _BLANKS[expect] if text[c] != " "]
    if bad:
        raise InputError(f"{where}: TLE line {expect} column layout broken (column {bad[0]} must be blank)")
    if not text[68].isdigit():
        raise InputError(f"{where}: TLE line {expect} checksum column holds {text[68]!r}, expected a digit")
    if tle_checksum(text) != int(text[68]):
        raise InputError(
            f"{where}: bad TLE checksum on line {expect} (column 69 says {text[68]}, computed {tle_checksum(text)})"
        )
    for first, last, name, pattern, expected in _FIELDS[expect]:
        field = text[first - 1:last]
        if not pattern.fullmatch(field):
            columns = f"column {first}" if first == last else f"columns {first}-{last}"
            raise InputError(f"{where}: {name} {field!r} in {columns} of TLE line {expect} is not {expected}")


def parse_tle_lines(lines, source="<text>", *, skip_bad=False):
    """Parse element sets from text lines.

    Parameters
    ----------
    lines : iterable of str or bytes
        Raw lines; line ending characters are stripped here.
    source : str
        File name used in messages.
    skip_bad : bool
        Warn and skip bad records instead of raising.

    Returns
    -------
    Constellation
    """
    entries = []
    for number, raw in enumerate(lines, start=1):
        if isinstance(raw, bytes):
            try:
                raw = raw.decode("ascii")
            except UnicodeDecodeError:
                raw = "\x00non-ascii"
        text = raw.strip("\r\n").rstrip()
        if text.strip() and not text.startswith("#"):
            entries.append((number, text))

    names, satrecs, skipped = [], [], 0
    i = 0
    while i < len(entries):
        number, text = entries[i]
        # A record is [name] line1 line2; its extent is fixed by the first two characters.
        if text.startswith("1 ") or text.startswith("2 "):
            name, start = "", i
        else:
            name, start = text[2:].strip() if text.startswith("0 ") else text.strip(), i + 1
        extent = start + 2 - i
        try:
            for k in (i, *range(start, min(start + 2, len(entries)))):
                if not entries[k][1].isascii() or "\x00" in entries[k][1]:
                    raise InputError(f"{source}:{entries[k][0]}: non-ASCII characters in a TLE file")
            if start + 1 >= len(entries):
                raise InputError(f"{source}:{number}: truncated file, element set has no line 2")
            (n1, l1), (n2, l2) = entries[start], entries[start + 1]
            _check_line(l1, "1", f"{source}:{n1}")
            _check_line(l2, "2", f"{source}:{n2}")
            if l1[2:7] != l2[2:7]:
                raise InputError(
                    f"{source}:{n2}: catalogue number {l2[2:7].strip()} on line 2 "
                    f"differs from {l1[2:7].strip()} on line 1"
                )
            try:
                sat = Satrec.twoline2rv(l1, l2)
            except Exception as exc:  # sgp4's parser raises ValueError/IndexError on bad fields
                raise InputError(f"{source}:{n1}: unreadable element set ({exc})") from None
            check_elements(sat, f"{source}:{n1}")
            if sat.error:
                raise InputError(f"{source}:{n1}: SGP4 rejects the element set (error code {sat.error})")
        except InputError as exc:
            if not skip_bad:
                raise
            warnings.warn(f"skipping bad record: {exc}", stacklevel=2)
            skipped += 1
            i += max(extent, 1)
            continue
        names.append(name)
        satrecs.append(sat)
        i += extent

    if not satrecs:
        raise InputError(f"{source}: no TLE records found" + (f" ({skipped} bad records skipped)" if skipped else ""))
    sat_ids = np.array([str(s.satnum) for s in satrecs])
    epochs = np.array([satrec_epoch_utc(s) for s in satrecs], dtype="datetime64[ns]")
    return _unique(Constellation(tuple(names), sat_ids, tuple(satrecs), epochs, str(source)))


def _unique(const):
    """Keep the newest element set of each catalogue number."""
    order = np.lexsort((const.epochs_utc, const.sat_ids))
    last = np.r_[const.sat_ids[order][1:] != const.sat_ids[order][:-1], True]
    if last.all():
        return const
    keep = np.sort(order[last])
    warnings.warn(
        f"{const.source}: {len(const) - len(keep)} duplicate catalogue numbers; kept the newest element set of each",
        stacklevel=3,
    )
    return const.subset(keep)


def read_tle(path: str | os.PathLike[str], *, skip_bad: bool = False) -> Constellation:
    """Read a 2-line or 3-line TLE file.

    Parameters
    ----------
    path : str or Path
    skip_bad : bool
        Warn and skip bad records instead of raising.

    Returns
    -------
    Constellation
    """
    path = Path(path)
    check_input_file(path, "TLE file")
    data = path.read_bytes()
    if not data.strip():
        raise InputError(f"{path}: empty file, expected TLE records")
    # splitlines() ends lines at LF, CR and CRLF; CR-CR-LF yields empty lines, skipped.
    return parse_tle_lines(data.splitlines(), str(path), skip_bad=skip_bad)
