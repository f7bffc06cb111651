"""Readers for real IMU logs, returning one :class:`ImuLog` in our body frame.

Formats (see ``../shared/data/gnss-ins/PROVENANCE.md``):

* PSINS text (``read_psins``): ``%`` comment lines, then three header rows
  (initial ``pitch roll yaw [deg] VE VN VU [m/s]``; ``lat lon [deg] h [m]
  t0 [s] dt [ms] g [m/s^2]``; gyro quanta [arcsec] and accelerometer quanta
  [ug*s]) and one row of six integer counts per sample. Axes are
  Right-Forward-Up, ours; ``ug`` uses the header's ``g``.
* rtklibexplorer raw CSV (``read_rtklib_csv``): ``ax ay az [g], gx gy gz
  [deg/s], tick [ms]`` without header; the first and last lines are cut
  mid-line by the logger and are always skipped. Times come from the RTKLIB
  ``.tag`` file beside it: the IMU ticks are stretched linearly so that the
  log spans the tag's start time to start + last tag tick (the method of the
  data's own repository).
* rtklibexplorer converted CSV (``read_rtklib_sf_csv``): ``t [s GPST since
  1970] ax ay az [g] gx gy gz [rad/s]`` and four unused columns.
* Any delimited text (``read_csv_columns``) with a column map naming the
  unit of each column (:data:`CSV_COLUMNS`), e.g. ``{"t_gpst_s": 0, "ax_g": 1,
  ..., "gz_deg_per_s": 6}``.

Sensor axes are rotated into the body frame with ``C_b_s``; the mountings of
the two rtklibexplorer data sets are :data:`DRIVE_0708_C_B_S` and
:data:`WALK_0827_C_B_S`. Rate samples become increments over the interval
that ends at the sample (``rate_k * (t_k - t_{k-1})``); the first sample only
opens the first interval.

Bad input policy: wrong column counts, non-numeric fields, non-increasing or
duplicate times and impossible sample rates raise :class:`InputError` naming
the file and line. Gaps (an interval over 2.5 times the median) are kept,
reported by a ``UserWarning`` and listed in ``metadata["gaps"]``: real logs
have them and an integrator can bridge short ones.
"""

import dataclasses
import math
import struct
import warnings
from pathlib import Path

import numpy as np

from ..constants import G0_MPS2
from ..errors import InputError
from ..rotations import euler_to_dcm

__all__ = ["ImuLog", "read_psins", "read_rtklib_csv", "read_rtklib_sf_csv", "read_csv_columns", "CSV_COLUMNS",
           "DRIVE_0708_C_B_S", "WALK_0827_C_B_S", "mount_C_b_s"]

GAP_FACTOR = 2.5
_RATE_RANGE_HZ = (1.0, 10_000.0)
#: GPST seconds since 1970 that a log can start at: 1970 .. 2100-01-01.
_GPST_RANGE_S = (0.0, 4_102_444_800.0)

# The data's repository gives the mounting as roll, pitch, yaw [deg] of the
# sensor in its forward-right-down body, composed Rz(yaw) Ry(pitch) Rx(roll)
# (drive: 180, 0, 180; walk: 180, 0, -90). Both products are symmetric, so
# they map sensor axes to forward-right-down; rows below re-order that to
# Right-Forward-Up.
_RFU_FROM_FRD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: Sensor to body (RFU) rotation of the rtklibexplorer drive_0708 IMU: R = y, F = -x, U = z.
DRIVE_0708_C_B_S = _RFU_FROM_FRD @ np.diag([-1.0, 1.0, -1.0])
#: Sensor to body (RFU) rotation of the rtklibexplorer walk_0827 IMU: R = -x, F = -y, U = z.
WALK_0827_C_B_S = _RFU_FROM_FRD @ np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def mount_C_b_s(roll_deg, pitch_deg, yaw_deg):
    """Sensor-to-body (Right-Forward-Up) rotation of an IMU mounted at roll, pitch, yaw in a forward-right-down body.

    The convention of rtklibexplorer/GNSS_IMU's ``imu_misalign`` (DESIGN 4.5):
    ``f_frd = C f_sensor`` with ``C`` Groves' (2013) ``Euler_to_CTM`` of the
    three angles, ``Rx(roll) Ry(pitch) Rz(yaw)`` as passive rotations; the rows
    are then re-ordered to Right-Forward-Up.

    Returns
    -------
    ndarray, (3, 3)
    """
    r, p, y = np.radians([roll_deg, pitch_deg, yaw_deg])
    sr, cr, sp, cp, sy, cy = np.sin(r), np.cos(r), np.sin(p), np.cos(p), np.sin(y), np.cos(y)
    C = np.array([[cp * cy, cp * sy, -sp],
                  [-cr * sy + sr * sp * cy, cr * cy + sr * sp * sy, sr * cp],
                  [sr * sy + cr * sp * cy, -sr * cy + cr * sp * sy, cr * cp]])
    return _RFU_FROM_FRD @ C


@dataclasses.dataclass(frozen=True)
class ImuLog:
    """IMU increments in the body frame (Right-Forward-Up).

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        End of each increment's interval [s] since ``epoch``.
    dt_s : ndarray, shape (n,)
        Length of each interval [s].
    dtheta_b_rad, dvel_b_mps : ndarray, shape (n, 3)
        Angle and velocity increments.
    epoch : str or None
        ISO 8601 instant of ``t_s = 0`` with its time scale (e.g. ``"... GPST"``),
        None when the source has no absolute time.
    source : str
        The file read.
    metadata : dict
        Everything else the source states (initial attitude, position, quanta,
        sample rate, gaps).
    """

    t_s: np.ndarray
    dt_s: np.ndarray
    dtheta_b_rad: np.ndarray
    dvel_b_mps: np.ndarray
    epoch: str | None
    source: str
    metadata: dict

    @property
    def gyro_rad_per_s(self):
        """Mean body rate over each interval, shape (n, 3)."""
        return self.dtheta_b_rad / self.dt_s[:, None]

    @property
    def accel_mps2(self):
        """Mean specific force over each interval, shape (n, 3)."""
        return self.dvel_b_mps / self.dt_s[:, None]

    @property
    def epoch_gpst_s(self):
        """``epoch`` as Unix-style GPST seconds (GPST since 1970 without leap seconds); None unless in GPST."""
        if self.epoch is None or not self.epoch.endswith("Z GPST"):
            return None
        iso = self.epoch[:-len("Z GPST")]
        return float((np.datetime64(iso, "ns") - np.datetime64("1970-01-01T00:00:00", "ns")) / np.timedelta64(1, "s"))

    @property
    def rate_hz(self):
        """Nominal sample rate (from the median interval)."""
        return 1.0 / float(np.median(self.dt_s))


def _table(path, lines, first_line, n_cols, delimiter):
    """Parse text rows into floats; InputError names the first bad line (1-based in the file)."""
    try:
        data = np.loadtxt(lines, delimiter=delimiter, ndmin=2, dtype=float)
        if data.shape[0] == len(lines) and (data.shape[1] == n_cols or len(lines) == 0):
            if np.all(np.isfinite(data)):
                return data.reshape(-1, n_cols)
    except ValueError:
        pass
    for i, line in enumerate(lines):
        fields = line.split(delimiter) if delimiter else line.split()
        where = f"{path}:{first_line + i}"
        if len(fields) != n_cols:
            raise InputError(f"{where}: expected {n_cols} values, got {len(fields)}")
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise InputError(f"{where}: non-numeric value in {line.strip()!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{where}: non-finite value in {line.strip()!r}")
    raise InputError(f"{path}: could not parse the data rows")


def _check_times(path, t, first_line, written=None):
    """Reject non-increasing times and impossible rates; warn about gaps. Returns the gap list.

    ``written(i)``, when given, is sample ``i``'s time as the file writes it, for the message.
    """
    if t.size < 2:
        raise InputError(f"{path}: fewer than two samples")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        written = written or (lambda k: repr(float(t[k])))
        raise InputError(f"{path}:{first_line + i}: time {written(i)} is not after the previous sample's "
                         f"{written(i - 1)}")
    med = float(np.median(dt))
    rate = 1.0 / med
    if not _RATE_RANGE_HZ[0] <= rate <= _RATE_RANGE_HZ[1]:
        raise InputError(f"{path}: sample rate {rate:.6g} Hz is outside {_RATE_RANGE_HZ} Hz")
    gaps = [{"line": first_line + int(i) + 1, "t_s": float(t[i + 1]), "gap_s": float(dt[i])}
            for i in np.flatnonzero(dt > GAP_FACTOR * med)]
    if gaps:
        warnings.warn(f"{path}: {len(gaps)} gap(s) longer than {GAP_FACTOR} x the {med:.4g} s interval, "
                      f"first at line {gaps[0]['line']} ({gaps[0]['gap_s']:.4g} s)", UserWarning, stacklevel=3)
    return gaps


def _rotate(C_b_s, x):
    C = np.asarray(C_b_s, dtype=float)
    if C.shape != (3, 3) or not np.allclose(C @ C.T, np.eye(3), atol=1e-9) or np.linalg.det(C) < 0:
        raise InputError("C_b_s must be a (3, 3) rotation matrix")
    return x @ C.T


def _from_rates(path, t, accel_mps2, gyro_rad_per_s, first_line, C_b_s, epoch, metadata, written=None):
    gaps = _check_times(path, t, first_line, written)
    dt = np.diff(t)
    dtheta = _rotate(C_b_s, gyro_rad_per_s[1:]) * dt[:, None]
    dvel = _rotate(C_b_s, accel_mps2[1:]) * dt[:, None]
    metadata = dict(metadata, gaps=gaps, rate_hz=1.0 / float(np.median(dt)))
    return ImuLog(t[1:] - t[0], dt, dtheta, dvel, epoch, str(path), metadata)


def _read_lines(path):
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read as text ({exc})") from None


def read_psins(path):
    """Read a PSINS ``.imu`` text log (increments in gyro/accelerometer quanta).

    Returns
    -------
    ImuLog
        ``t_s`` from the header's ``t0``; ``epoch`` None (PSINS states no
        absolute time); metadata ``pitch_deg, roll_deg, yaw_deg`` (yaw
        counter-clockwise from North, as ours), ``vel_enu_mps``, ``lat_deg,
        lon_deg, alt_m``, ``g_mps2``, ``gyro_quantum_arcsec``,
        ``accel_quantum_ug_s``, ``C_n_b0`` (from the header attitude).
    """
    lines = _read_lines(path)
    rows = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("%")]
    if len(rows) < 5:
        raise InputError(f"{path}: expected 3 header rows and samples after the % comments")
    header = []
    for (ln, text), n_cols in zip(rows[:3], (6, 6, 6)):
        header.append(_table(path, [text], ln, n_cols, None)[0])
    att, pos, quanta = header
    (pos_line, pos_text), (quanta_line, quanta_text) = rows[1], rows[2]
    pos_fields = pos_text.split()
    dt_ms, g = float(pos[4]), float(pos[5])
    if not -90.0 <= pos[0] <= 90.0:
        raise InputError(f"{path}:{pos_line}: header latitude {pos_fields[0]} deg must be within [-90, 90]")
    if not 0.1 <= dt_ms <= 1000.0:
        raise InputError(f"{path}:{pos_line}: sampling interval {dt_ms} ms is outside 0.1..1000 ms")
    if not 9.7 <= g <= 9.9:
        raise InputError(f"{path}:{pos_line}: g {pos_fields[5]} m/s^2 is outside 9.7..9.9 m/s^2")
    if not np.all(quanta > 0):
        raise InputError(f"{path}:{quanta_line}: the gyro and accelerometer quanta [{', '.join(quanta_text.split())}] "
                         "must all be > 0")
    first = rows[3][0]
    body = [text for _, text in rows[3:]]
    if rows[-1][0] - first + 1 != len(body):
        blank = next(r for r, (a, b) in enumerate(zip(rows[3:], rows[4:])) if b[0] != a[0] + 1)
        raise InputError(f"{path}:{rows[3 + blank][0] + 1}: blank or comment line inside the samples")
    counts = _table(path, body, first, 6, None)
    n = counts.shape[0]
    dt = dt_ms * 1e-3
    t = pos[3] + dt * np.arange(1, n + 1)
    metadata = {
        "format": "psins", "pitch_deg": float(att[0]), "roll_deg": float(att[1]), "yaw_deg": float(att[2]),
        "vel_enu_mps": att[3:6].tolist(), "lat_deg": float(pos[0]), "lon_deg": float(pos[1]),
        "alt_m": float(pos[2]), "t0_s": float(pos[3]),
        "g_mps2": g, "gyro_quantum_arcsec": quanta[0:3].tolist(), "accel_quantum_ug_s": quanta[3:6].tolist(),
        "C_n_b0": euler_to_dcm(*np.radians(att[[0, 1, 2]])).tolist(), "gaps": [], "rate_hz": 1.0 / dt,
    }
    return ImuLog(t, np.full(n, dt), counts[:, 0:3] * np.radians(quanta[0:3] / 3600.0),
                  counts[:, 3:6] * (quanta[3:6] * 1e-6 * g), None, str(path), metadata)


def _read_tag(path):
    """Start time [s GPST since 1970] and span [s] of an RTKLIB time-tag file."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the time-tag file ({exc})") from None
    if len(raw) < 84 or not raw.startswith(b"TIMETAG RTKLIB") or (len(raw) - 76) % 8:
        raise InputError(f"{path}: not an RTKLIB time-tag file (60-byte TIMETAG header, start time, 8-byte records)")
    time_s, frac_s = struct.unpack("<Id", raw[64:76])
    last_tick_ms = struct.unpack("<I", raw[-8:-4])[0]
    return _check_gpst(path, "start time", time_s + frac_s), last_tick_ms / 1000.0


def _check_gpst(path, what, unix_style_gpst_s):
    """Refuse a start time that is not GPST seconds since 1970 of the GPS era."""
    if not _GPST_RANGE_S[0] <= unix_style_gpst_s <= _GPST_RANGE_S[1]:
        raise InputError(f"{path}: {what} {float(unix_style_gpst_s):.6g} is not GPST seconds since 1970 "
                         "(before 2100)")
    return unix_style_gpst_s


def _gpst_iso(unix_style_gpst_s):
    return f"{np.datetime64(int(round(unix_style_gpst_s * 1e6)), 'us')}Z GPST"


def read_rtklib_csv(path, *, tag_path=None, C_b_s=np.eye(3)):
    """Read an rtklibexplorer raw IMU CSV with its RTKLIB ``.tag`` file.

    Parameters
    ----------
    path : path-like
    tag_path : path-like, optional
        Default ``path + ".tag"``.
    C_b_s : array_like, shape (3, 3)
        Sensor-to-body rotation, e.g. :data:`DRIVE_0708_C_B_S`.

    Returns
    -------
    ImuLog
        ``epoch`` is the first kept sample's GPST time.
    """
    lines = _read_lines(path)
    if len(lines) < 4:
        raise InputError(f"{path}: fewer than 4 lines (the first and last are skipped as partial)")
    data = _table(path, lines[1:-1], 2, 7, ",")
    start_s, span_s = _read_tag(tag_path or f"{path}.tag")
    tick_s = (data[:, 6] - data[0, 6]) / 1000.0
    _check_times(path, tick_s, 2, lambda i: f"{lines[1 + i].split(',')[6].strip()} ms")
    t = tick_s * (span_s / tick_s[-1])
    metadata = {"format": "rtklib_csv", "tag_start_gpst": _gpst_iso(start_s), "tick_scale": float(span_s / tick_s[-1]),
                "C_b_s": np.asarray(C_b_s, dtype=float).tolist()}
    return _from_rates(path, t, data[:, 0:3] * G0_MPS2, np.radians(data[:, 3:6]), 2, C_b_s,
                       _gpst_iso(start_s), metadata)


def read_rtklib_sf_csv(path, *, C_b_s=np.eye(3)):
    """Read an rtklibexplorer converted IMU CSV (``imu_*_sf.csv``, GPST time column).

    Returns
    -------
    ImuLog
        ``epoch`` is the first sample's GPST time.
    """
    lines = _read_lines(path)
    if len(lines) < 2:
        raise InputError(f"{path}: {len(lines)} line(s); expected rows of 11 comma-separated values "
                         "(t, accelerometer [g], gyro [rad/s], 4 unused)")
    data = _table(path, lines, 1, 11, ",")
    t = data[:, 0]
    _check_gpst(path, "first time", t[0])
    metadata = {"format": "rtklib_sf_csv", "C_b_s": np.asarray(C_b_s, dtype=float).tolist()}
    return _from_rates(path, t - t[0], data[:, 1:4] * G0_MPS2, data[:, 4:7], 1, C_b_s, _gpst_iso(t[0]), metadata,
                       lambda i: lines[i].split(",")[0].strip())


#: Column names of :func:`read_csv_columns` and their factors to SI: time (Unix-style GPST seconds, or seconds
#: of no stated epoch), specific force per axis in m/s^2 or g, body rate in rad/s or deg/s.
CSV_COLUMNS = {"t_gpst_s": 1.0, "t_s": 1.0,
               **{f"a{x}_mps2": 1.0 for x in "xyz"}, **{f"a{x}_g": G0_MPS2 for x in "xyz"},
               **{f"g{x}_rad_per_s": 1.0 for x in "xyz"}, **{f"g{x}_deg_per_s": math.pi / 180.0 for x in "xyz"}}


def read_csv_columns(path, columns, *, C_b_s=np.eye(3), delimiter=",", skip_rows=0):
    """Read a delimited IMU log of rates with a column map.

    Parameters
    ----------
    path : path-like
    columns : dict of str to int
        0-based column of each quantity, named as in :data:`CSV_COLUMNS`: one
        time (``t_gpst_s`` or ``t_s``), one accelerometer and one gyro column
        per axis, each in one unit (``ax_g`` or ``ax_mps2``, ...).
    C_b_s : array_like, (3, 3)
        Sensor-to-body rotation.
    delimiter : str
    skip_rows : int
        Header lines to skip.

    Returns
    -------
    ImuLog
        ``epoch`` the first sample's GPST time with ``t_gpst_s``, else None.
    """
    unknown = sorted(set(columns) - set(CSV_COLUMNS))
    if unknown:
        raise InputError(f"{path}: unknown IMU column name(s) {', '.join(unknown)}; known: {', '.join(CSV_COLUMNS)}")
    picks = {}
    for q in ["t"] + [f"{s}{x}" for s in "ag" for x in "xyz"]:
        names = [c for c in columns if c.startswith(q + "_")]
        if len(names) != 1:
            raise InputError(f"{path}: the column map needs exactly one {q}_* column, got {names or 'none'}")
        picks[q] = names[0]
    idx = [int(columns[picks[q]]) for q in picks]
    if min(idx) < 0 or len(set(idx)) != len(idx):
        raise InputError(f"{path}: column indices {idx} must be distinct and >= 0")
    lines = _read_lines(path)[skip_rows:]
    n_cols = len(lines[0].split(delimiter)) if lines else 0
    if n_cols <= max(idx):
        raise InputError(f"{path}:{skip_rows + 1}: {n_cols} column(s); the column map needs {max(idx) + 1}")
    used = []
    for i, line in enumerate(lines):
        fields = line.split(delimiter)
        if len(fields) <= max(idx):
            raise InputError(f"{path}:{skip_rows + 1 + i}: {len(fields)} column(s); "
                             f"the column map needs {max(idx) + 1}")
        used.append(",".join(fields[j] for j in idx))
    data = _table(path, used, skip_rows + 1, len(idx), ",")
    col = {q: data[:, k] * CSV_COLUMNS[name] for k, (q, name) in enumerate(picks.items())}
    t = col["t"]
    epoch = None
    if picks["t"] == "t_gpst_s":
        epoch = _gpst_iso(_check_gpst(path, "first time", t[0]))
    accel = np.stack([col["ax"], col["ay"], col["az"]], axis=-1)
    gyro = np.stack([col["gx"], col["gy"], col["gz"]], axis=-1)
    metadata = {"format": "csv", "columns": dict(columns), "C_b_s": np.asarray(C_b_s, dtype=float).tolist()}
    return _from_rates(path, t - t[0], accel, gyro, skip_rows + 1, C_b_s, epoch, metadata,
                       lambda i: used[i].split(",")[0].strip())
