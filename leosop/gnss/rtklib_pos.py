"""RTKLIB solution files (``.pos``): read GNSS fixes, write a navigation solution RTKLIB's tools plot.

Layout (RTKLIB manual, appendix B "solution file"): header lines start with
``%``; each epoch row is the GPST time (``YYYY/MM/DD HH:MM:SS.sss``, or GPS
week and seconds of week), latitude and longitude [deg], ellipsoidal height
[m], the quality flag ``Q`` (1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP,
7 dead reckoning), the number of satellites, the standard deviations
``sdn sde sdu`` [m] and the signed square roots of the covariances ``sdne
sdeu sdun`` [m], the age of differential [s] and the ratio; with velocity
output, ``vn ve vu`` [m/s] and ``sdvn sdve sdvu sdvne sdveu sdvun``. Only the
geodetic (latitude/longitude in degrees) form is read; ECEF or ENU files are
refused.

Times are "Unix-style GPST" seconds: GPST counted from 1970-01-01 without
leap seconds (as RTKLIB's ``gtime_t``), the scale of the rtklibexplorer IMU
logs (:mod:`leosop.ins.imu_io`).
"""

import dataclasses
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import atomic_path

__all__ = ["Q_DR", "Q_FIX", "Q_FLOAT", "Q_SINGLE", "PosSolution", "read_pos", "write_pos"]

Q_FIX, Q_FLOAT, Q_SINGLE, Q_DR = 1, 2, 5, 7
#: GPS week 0 began 1980-01-06 (GPST), in Unix-style GPST seconds.
_GPS_EPOCH_S = 315_964_800.0
_N_BASE, _N_VEL = 15, 24  # columns with the date and time as two fields


@dataclasses.dataclass(frozen=True)
class PosSolution:
    """Epochs of an RTKLIB solution file (n rows).

    Attributes
    ----------
    t_gpst_s : ndarray, (n,)
        Unix-style GPST seconds.
    lat_deg, lon_deg, alt_m : ndarray, (n,)
    q : ndarray of int, (n,)
        Quality flag.
    n_sats : ndarray of int, (n,)
    cov_enu_m2 : ndarray, (n, 3, 3)
        Position covariance in ENU (from ``sdn sde sdu sdne sdeu sdun``).
    vel_enu_mps : ndarray, (n, 3), or None
        Velocity when the file has it.
    cov_vel_enu_m2ps2 : ndarray, (n, 3, 3), or None
    source : str
    """

    t_gpst_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    q: np.ndarray
    n_sats: np.ndarray
    cov_enu_m2: np.ndarray
    vel_enu_mps: np.ndarray | None
    cov_vel_enu_m2ps2: np.ndarray | None
    source: str


def _cov_enu(sd):
    """ENU covariance from RTKLIB's ``sdn sde sdu sdne sdeu sdun`` (signed square roots), (n, 6) -> (n, 3, 3)."""
    sn, se, su, sne, seu, sun = (sd[:, i] for i in range(6))

    def c(x):
        return np.sign(x) * x * x  # RTKLIB stores sgn(c) sqrt|c|

    cov = np.empty((sd.shape[0], 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = se**2, sn**2, su**2
    cov[:, 0, 1] = cov[:, 1, 0] = c(sne)
    cov[:, 0, 2] = cov[:, 2, 0] = c(seu)
    cov[:, 1, 2] = cov[:, 2, 1] = c(sun)
    return cov


def _signed_roots(cov):
    """RTKLIB's ``sdn sde sdu sdne sdeu sdun`` of ENU covariances, (n, 3, 3) -> (n, 6)."""

    def r(x):
        return np.sign(x) * np.sqrt(np.abs(x))

    return np.stack([np.sqrt(cov[:, 1, 1]), np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 2, 2]),
                     r(cov[:, 0, 1]), r(cov[:, 0, 2]), r(cov[:, 1, 2])], axis=-1)


def _time_s(path, line_no, date, time):
    """Unix-style GPST seconds of a row's two time fields."""
    try:
        if "/" in date:
            iso = date.replace("/", "-") + "T" + time
            return (np.datetime64(iso, "ns") - np.datetime64("1970-01-01T00:00:00", "ns")) / np.timedelta64(1, "s")
        return _GPS_EPOCH_S + int(date) * 604_800.0 + float(time)
    except ValueError:
        raise InputError(f"{path}:{line_no}: GPST time {date} {time!r} is neither YYYY/MM/DD HH:MM:SS nor "
                         "week and seconds") from None


def read_pos(path):
    """Read an RTKLIB ``.pos`` solution file (geodetic form).

    Returns
    -------
    PosSolution

    Raises
    ------
    InputError
        Unreadable file, ECEF/ENU form, UTC or local time, wrong column
        count, non-numeric field, time going backwards; the message names
        the file and line.
    """
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read as text ({exc})") from None
    header = [ln for ln in lines if ln.startswith("%")]
    columns = next((ln for ln in reversed(header) if "latitude" in ln or "x-ecef" in ln or "e-baseline" in ln), "")
    if "x-ecef" in columns or "e-baseline" in columns:
        raise InputError(f"{path}: only the latitude/longitude form of RTKLIB solutions is read (this one is "
                         "ECEF or ENU)")
    if "UTC" in columns or "JST" in columns:
        raise InputError(f"{path}: times must be GPST (the header says {columns.split()[1]!r})")
    rows = [(i + 1, ln.split()) for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("%")]
    if not rows:
        raise InputError(f"{path}: no solution rows (RTKLIB .pos expected)")
    n_cols = len(rows[0][1])
    if n_cols not in (_N_BASE, _N_VEL):
        raise InputError(f"{path}:{rows[0][0]}: {n_cols} fields; an RTKLIB solution row has {_N_BASE} "
                         f"(or {_N_VEL} with velocity): GPST date time lat lon h Q ns sdn sde sdu sdne sdeu sdun "
                         "age ratio [vn ve vu sdvn ...]")
    t = np.empty(len(rows))
    values = np.empty((len(rows), n_cols - 2))
    for k, (line_no, fields) in enumerate(rows):
        if len(fields) != n_cols:
            raise InputError(f"{path}:{line_no}: {len(fields)} fields, expected {n_cols} as on line {rows[0][0]}")
        t[k] = _time_s(path, line_no, fields[0], fields[1])
        try:
            values[k] = [float(f) for f in fields[2:]]
        except ValueError:
            raise InputError(f"{path}:{line_no}: non-numeric field in {' '.join(fields[2:])!r}") from None
    bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if bad.size:
        raise InputError(f"{path}:{rows[bad[0]][0]}: non-finite value")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise InputError(f"{path}:{rows[back[0] + 1][0]}: time is not after the previous row's")
    lat, lon = values[:, 0], values[:, 1]
    if np.any(np.abs(lat) > 90) or np.any(np.abs(lon) > 360):
        k = int(np.flatnonzero((np.abs(lat) > 90) | (np.abs(lon) > 360))[0])
        raise InputError(f"{path}:{rows[k][0]}: latitude/longitude out of range (degrees expected)")
    q = values[:, 3].astype(int)
    bad_q = np.flatnonzero((q < 0) | (q > 7) | (q != values[:, 3]))
    if bad_q.size:
        raise InputError(f"{path}:{rows[bad_q[0]][0]}: quality flag Q={values[bad_q[0], 3]:g} is not 0..7")
    vel = cov_vel = None
    if n_cols == _N_VEL:
        vel = values[:, [14, 13, 15]]  # vn ve vu -> ENU
        cov_vel = _cov_enu(values[:, 16:22])
    return PosSolution(t, lat, lon, values[:, 2], q, values[:, 4].astype(int), _cov_enu(values[:, 5:11]), vel,
                       cov_vel, str(path))


_HEADER = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
           "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)     sdvn     sdve     sdvu"
           "    sdvne    sdveu    sdvun")


def write_pos(path, sol, *, comments=()):
    """Write a :class:`PosSolution` with velocity as an RTKLIB ``.pos`` file, atomically.

    Parameters
    ----------
    path : path-like
    sol : PosSolution
        ``vel_enu_mps`` and ``cov_vel_enu_m2ps2`` must be given.
    comments : sequence of str
        Header lines (``%`` is prepended).
    """
    t = np.asarray(sol.t_gpst_s, dtype=float)
    stamp = (np.datetime64("1970-01-01T00:00:00", "ms") + np.round(t * 1e3).astype("int64").astype("timedelta64[ms]"))
    text = np.datetime_as_string(stamp, unit="ms")
    sd = _signed_roots(sol.cov_enu_m2)
    sdv = _signed_roots(sol.cov_vel_enu_m2ps2)
    v = sol.vel_enu_mps
    with atomic_path(path) as tmp, open(tmp, "w") as fh:
        fh.writelines(f"% {c}\n" for c in comments)
        fh.write(_HEADER + "\n")
        for k in range(t.size):
            date, time = text[k].split("T")
            fh.write(f"{date.replace('-', '/')} {time} {sol.lat_deg[k]:14.9f} {sol.lon_deg[k]:14.9f} "
                     f"{sol.alt_m[k]:10.4f} {sol.q[k]:3d} {sol.n_sats[k]:3d} "
                     + " ".join(f"{x:8.4f}" for x in sd[k]) + "   0.00    0.0 "
                     + " ".join(f"{x:10.5f}" for x in (v[k, 1], v[k, 0], v[k, 2])) + " "
                     + " ".join(f"{x:8.5f}" for x in sdv[k]) + "\n")
