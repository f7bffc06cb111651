"""RINEX 3 observation and navigation headers -> arrays.

Hatanaka-compressed files (``.crx``, ``.crx.gz``, ``.XXd``) are expanded by
the maintained ``hatanaka`` package (0.3 s for the 24 h, 30 s ESBC00DNK day).
The expanded text is then parsed here rather than by ``georinex``: georinex
took 113 s for the GPS + Galileo part of that day (it merges an xarray per
epoch), the minimal fixed-width parser below 1.4-2 s; the numbers are
printed by ``tools/bench_ppp_readers.py``. Only what PPP needs is read: the
header fields below and the chosen systems' observables with their LLI flags.

Time: epochs are returned in the file's time system (GPS time for GPS and
mixed files, RINEX 3.05 section 6.7), as ``datetime64[ns]`` named ``time_gps``.
"""

import gzip
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["ObsData", "read_obs", "read_text", "check_nav", "epochs_gps"]


@dataclass
class ObsData:
    """Observations of one RINEX 3 file, per epoch and satellite.

    Attributes
    ----------
    time_gps : ndarray of datetime64[ns], shape (n_epochs,)
        Receiver epochs in GPS time.
    sv : list of str, length n_sats
        Satellite ids (``G05``, ``E11``), sorted.
    obs : dict of str -> ndarray, shape (n_epochs, n_sats)
        Observable by system-qualified RINEX code (``G:C1W``), NaN when
        missing. Code in m, phase in cycles, Doppler in Hz.
    lli : dict of str -> ndarray of int8, shape (n_epochs, n_sats)
        Loss-of-lock indicator of the phase observables (0 when blank).
    approx_pos_ecef_m : ndarray, shape (3,)
        Header ``APPROX POSITION XYZ`` (zeros when absent).
    antenna_delta_hen_m : ndarray, shape (3,)
        Header ``ANTENNA: DELTA H/E/N`` (ARP above the marker).
    obs_types : dict of str -> list of str
        Header observation types per system letter.
    """

    path: str
    version: float
    marker: str
    time_gps: np.ndarray
    sv: list
    obs: dict
    lli: dict
    approx_pos_ecef_m: np.ndarray
    antenna_delta_hen_m: np.ndarray
    interval_s: float
    obs_types: dict = field(default_factory=dict)
    antenna_type: str = ""


def read_text(path):
    """Text of a RINEX / SP3 / CLK file, gunzipped and Hatanaka-expanded as needed.

    Returns
    -------
    list of str
        Lines without their line ends.
    """
    lines, notes = _expand(path)
    for note in notes:
        warnings.warn(note, stacklevel=2)
    return lines


def _expand(path):
    """:func:`read_text`'s lines, and the Hatanaka expander's warnings, one line each naming the file.

    A reader warns them only once the text has passed its checks: a file it
    refuses gives the one error line alone.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise InputError(f"{path}: truncated or corrupt gzip data ({exc})") from None
    notes = []
    if raw[:80].find(b"COMPACT RINEX FORMAT") >= 0 or raw[60:80].startswith(b"CRINEX VERS"):
        import hatanaka

        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                raw = hatanaka.decompress(raw)
        except Exception as exc:  # the library raises several types for a damaged file
            raise InputError(f"{path}: Hatanaka decompression failed ({str(exc).splitlines()[0]})") from None
        notes = [f"{path}: {' '.join(str(w.message).split())}" for w in caught]
    try:
        return raw.decode("ascii", errors="replace").splitlines(), notes
    except Exception as exc:  # pragma: no cover - decode with replace does not fail
        raise InputError(f"{path}: not text ({exc})") from None


#: Calendar years accepted in epochs: the GNSS era (also keeps ``datetime64[ns]`` far from overflow).
EPOCH_YEARS = (1980, 2099)


def epochs_gps(fields, line_numbers, path):
    """Calendar epoch fields -> ``datetime64[ns]``, refusing impossible dates.

    Parameters
    ----------
    fields : array_like, shape (n, 6)
        Year, month, day, hour, minute (whole numbers) and seconds.
    line_numbers : array_like of int, shape (n,)
        Line of each epoch in ``path``, for the error message.
    path : str

    Returns
    -------
    ndarray of datetime64[ns], shape (n,)

    Raises
    ------
    InputError
        At the first epoch outside years 1980-2099, month 1-12, the month's
        days, hour 0-23, minute 0-59 or seconds [0, 61) (leap second).
    """
    f = np.asarray(fields, float).reshape(-1, 6)
    y, mo, d, h, mi, s = f.T
    whole = np.all(np.isfinite(f[:, :5]) & (f[:, :5] == np.round(f[:, :5])), axis=1)
    ok = (whole & (y >= EPOCH_YEARS[0]) & (y <= EPOCH_YEARS[1]) & (mo >= 1) & (mo <= 12) & (d >= 1)
          & (h >= 0) & (h <= 23) & (mi >= 0) & (mi <= 59) & (s >= 0) & (s < 61))
    month = np.where(ok, (y - 1970) * 12 + mo - 1, 0).astype(np.int64).astype("datetime64[M]")
    day = month.astype("datetime64[D]") + np.where(ok, d - 1, 0).astype(np.int64)
    ok &= day.astype("datetime64[M]") == month
    bad = np.flatnonzero(~ok)
    if bad.size:
        k = bad[0]
        shown = " ".join(f"{v:g}" for v in f[k])
        raise InputError(f"{path}: line {int(np.asarray(line_numbers)[k])}: impossible epoch {shown} "
                         f"(expected year {EPOCH_YEARS[0]}-{EPOCH_YEARS[1]}, a valid date, hour 0-23, minute 0-59, "
                         "seconds 0-60)")
    return (day.astype("datetime64[ns]") + ((h * 3600 + mi * 60) * 1e9).astype(np.int64).astype("timedelta64[ns]")
            + np.round(s * 1e9).astype(np.int64).astype("timedelta64[ns]"))


def _header(lines, path):
    """Header records as a list of (label, content, line_number) up to END OF HEADER."""
    out = []
    for i, line in enumerate(lines):
        label = line[60:].strip()
        out.append((label, line[:60], i + 1))
        if label == "END OF HEADER":
            return out, i + 1
    raise InputError(f"{path}: line {len(lines)}: no END OF HEADER (truncated file?)")


def _floats(text, n, path, lineno, label):
    try:
        vals = [float(v) for v in text.split()[:n]]
    except ValueError:
        vals = []
    if len(vals) != n:
        raise InputError(f"{path}: line {lineno}: {label}: expected {n} numbers")
    return np.array(vals)


def read_obs(path, *, systems="GE", codes=None):
    """Read a RINEX 3 observation file (plain, gzip or Hatanaka).

    Parameters
    ----------
    path : str or Path
    systems : str
        System letters to keep (``"GE"``: GPS and Galileo).
    codes : dict of str -> list of str, optional
        Observables to keep per system (``{"G": ["C1W", "L1C"]}``); default
        every header type of the kept systems.

    Returns
    -------
    ObsData

    Raises
    ------
    InputError
        Not RINEX 3 observation data, a mixed-version file (a RINEX 2 epoch
        record in the data), a truncated epoch, a bad number; the message
        names the file and line.

    Warns
    -----
    UserWarning
        The Hatanaka expander's warnings (e.g. epochs it skipped), each naming
        the file, once the file has been read.
    """
    lines, notes = _expand(path)
    path = str(path)
    if not lines:
        raise InputError(f"{path}: line 1: empty file")
    head, n_head = _header(lines, path)
    first = lines[0]
    if first[60:].strip() != "RINEX VERSION / TYPE":
        raise InputError(f"{path}: line 1: expected a RINEX VERSION / TYPE record")
    try:
        version = float(first[:9])
    except ValueError:
        raise InputError(f"{path}: line 1: unreadable RINEX version {first[:9]!r}") from None
    if first[20:21] != "O":
        raise InputError(f"{path}: line 1: not an observation file (type {first[20:21]!r})")
    if not 3.0 <= version < 4.0:
        raise InputError(f"{path}: line 1: RINEX version {version:g}, this reader needs RINEX 3")
    obs_types, approx, delta, interval, marker, ant = {}, np.zeros(3), np.zeros(3), np.nan, "", ""
    pending = None
    for label, text, lineno in head:
        if label == "SYS / # / OBS TYPES":
            if text[0] != " ":
                try:
                    n = int(text[3:6])
                except ValueError:
                    raise InputError(f"{path}: line {lineno}: SYS / # / OBS TYPES: expected the number of "
                                     f"observation types in columns 4-6, got {text[3:6]!r}") from None
                sys_letter = text[0]
                obs_types[sys_letter] = text[7:].split()
                pending = (sys_letter, n)
            elif pending:
                obs_types[pending[0]] += text[7:].split()
        elif label == "APPROX POSITION XYZ":
            approx = _floats(text, 3, path, lineno, label)
        elif label == "ANTENNA: DELTA H/E/N":
            delta = _floats(text, 3, path, lineno, label)
        elif label == "INTERVAL":
            interval = _floats(text, 1, path, lineno, label)[0]
        elif label == "MARKER NAME":
            marker = text.strip()
        elif label == "ANT # / TYPE":
            ant = text[20:40].strip()
        elif label == "TIME OF FIRST OBS" and text[48:51].strip() not in ("", "GPS"):
            raise InputError(f"{path}: line {lineno}: time system {text[48:51].strip()!r}, only GPS time is read")
    for s, types in obs_types.items():
        if s in systems and pending and len(types) == 0:
            raise InputError(f"{path}: SYS / # / OBS TYPES for {s} is empty")
    keep = {}
    for s in systems:
        if s not in obs_types:
            continue
        wanted = obs_types[s] if codes is None or s not in codes else codes[s]
        keep[s] = [(c, obs_types[s].index(c)) for c in wanted if c in obs_types[s]]
    if not keep:
        raise InputError(f"{path}: no observation types for systems {systems!r}")

    # Pass 1: epoch records and the data lines of the kept systems.
    epochs, epoch_lines, rows = [], [], {s: [] for s in keep}
    i, n = n_head, len(lines)
    while i < n:
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        if line[0] != ">":
            raise InputError(f"{path}: line {i + 1}: expected an epoch record starting with '>' "
                             "(a RINEX 2 record in a RINEX 3 file?)")
        try:
            flag = int(line[31:32] or 0)
            nsat = int(line[32:35])
            ep = (int(line[2:6]), int(line[7:9]), int(line[10:12]), int(line[13:15]), int(line[16:18]),
                  float(line[18:29]))
        except ValueError:
            raise InputError(f"{path}: line {i + 1}: unreadable epoch record") from None
        if nsat < 0:
            raise InputError(f"{path}: line {i + 1}: negative satellite count {nsat} in the epoch record")
        if flag > 1:  # events: header lines follow, no observations
            i += 1 + nsat
            continue
        if i + nsat > n - 1:
            raise InputError(f"{path}: line {n}: epoch at line {i + 1} announces {nsat} satellites, "
                             f"the file ends after {n - 1 - i} (truncated file?)")
        k = len(epochs)
        epochs.append(ep)
        epoch_lines.append(i + 1)
        for j in range(i + 1, i + 1 + nsat):
            data = lines[j]
            if data[:1] == ">":
                raise InputError(f"{path}: line {j + 1}: epoch record where a satellite record was expected "
                                 f"(epoch at line {i + 1} announces {nsat})")
            s = data[:1]
            if s in rows:
                rows[s].append((k, data, j + 1))
        i += 1 + nsat
    if not epochs:
        raise InputError(f"{path}: line {n_head + 1}: no observation epochs")
    time_gps = epochs_gps(epochs, epoch_lines, path)
    sv = sorted({r[1][:3].replace(" ", "0") for s in rows for r in rows[s]})
    col = {name: c for c, name in enumerate(sv)}
    n_ep, n_sv = len(epochs), len(sv)
    obs, lli = {}, {}
    for s, recs in rows.items():
        if not recs:
            continue
        r_ep = np.fromiter((r[0] for r in recs), int, len(recs))
        r_sv = np.fromiter((col[r[1][:3].replace(" ", "0")] for r in recs), int, len(recs))
        for code, idx in keep[s]:
            a, b = 3 + 16 * idx, 3 + 16 * idx + 14
            vals = np.full(len(recs), np.nan)
            for m, (_, data, lineno) in enumerate(recs):
                txt = data[a:b]
                if txt.strip():
                    try:
                        vals[m] = float(txt)
                    except ValueError:
                        raise InputError(f"{path}: line {lineno}: {s}:{code} {txt.strip()!r} is not a number") from None
            arr = np.full((n_ep, n_sv), np.nan)
            arr[r_ep, r_sv] = vals
            obs[f"{s}:{code}"] = arr
            if code[0] == "L":
                flags = np.zeros(len(recs), np.int8)
                for m, (_, data, _) in enumerate(recs):
                    ch = data[b:b + 1]
                    if ch.strip() and ch.isdigit():
                        flags[m] = int(ch)
                la = np.zeros((n_ep, n_sv), np.int8)
                la[r_ep, r_sv] = flags
                lli[f"{s}:{code}"] = la
    for note in notes:
        warnings.warn(note, stacklevel=2)
    return ObsData(path=path, version=version, marker=marker, time_gps=time_gps, sv=sv, obs=obs, lli=lli,
                   approx_pos_ecef_m=approx, antenna_delta_hen_m=delta, interval_s=float(interval),
                   obs_types=obs_types, antenna_type=ant)


def check_nav(path):
    """Check a RINEX 3 navigation file's header; return the first record's date.

    The float PPP here takes orbits and clocks from SP3 and CLK; the
    navigation file is read only to check that it is RINEX 3 navigation data
    for the same day (broadcast orbits for real-time use are not built yet).

    Returns
    -------
    numpy.datetime64 or None
        Date (day) of the first navigation record, None when there is none.
    """
    lines = read_text(path)
    path = str(path)
    head, n_head = _header(lines, path)
    first = lines[0] if lines else ""
    if first[60:].strip() != "RINEX VERSION / TYPE" or first[20:21] != "N":
        raise InputError(f"{path}: line 1: not a RINEX navigation file")
    try:
        version = float(first[:9])
    except ValueError:
        raise InputError(f"{path}: line 1: unreadable RINEX version {first[:9]!r}") from None
    if not 3.0 <= version < 4.0:
        raise InputError(f"{path}: line 1: RINEX navigation version {version:g}, expected RINEX 3")
    for j in range(n_head, len(lines)):
        line = lines[j]
        if line[:1].isalpha():
            try:
                return np.datetime64(f"{int(line[4:8]):04d}-{int(line[9:11]):02d}-{int(line[12:14]):02d}")
            except ValueError:
                raise InputError(f"{path}: line {j + 1}: unreadable navigation record epoch") from None
    return None
