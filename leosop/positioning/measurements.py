"""Doppler measurement tables (DESIGN 4.3) and the satellite states they need.

A table has a header row and one measurement per row: ``time_utc`` (ISO
8601 UTC; an offset such as ``+01:00`` is converted to UTC) or ``t_s``;
``sat_id``; ``doppler_hz``; optional ``sigma_hz``, ``carrier_hz`` and the
satellite state ``x_sv_m, y_sv_m, z_sv_m, vx_sv_mps, vy_sv_mps, vz_sv_mps``
(ECEF at the measurement time); optional ``pass_id`` (a label: rows of one
pass share a transmitter frequency offset in a static fix, an extension of
DESIGN 4.3); optional ``phase_cycles``,
``phase_sigma_cycles`` and ``arc``: the accumulated carrier phase (the
integral of ``doppler_hz``, cycles), its standard deviation and a label of
the arc its whole cycles are continuous over (replay's ``carrier.csv``
names; an empty ``phase_cycles`` leaves the row a Doppler row alone; the
differential carrier aid, :mod:`leosop.fusion.aids_differential`, takes
them). A missing column is an
error for the whole file; a bad row (empty, NaN or non-numeric value,
non-positive sigma or carrier, duplicate of an earlier row) is set aside with
its reason in :attr:`Measurements.rejected` so that the rest can be solved.

Carrier of a row: its ``carrier_hz`` value; else the default carrier of its
satellite's family (:data:`leosop.constellations.REGISTRY`, the family
from the element sets' names); else the caller's ``carrier_hz``
(``--carrier-hz``); else, when nothing in the file points to another carrier,
:data:`DEFAULT_CARRIER_HZ`. A row left without a carrier in a file that mixes
carriers is an error naming its line. Receiver clock of a row
(:func:`clock_groups`): its family; rows of no known family (e.g. a table
with state columns and no element sets) are grouped by carrier, one clock per
distinct ``carrier_hz``.

Satellite states from element sets include the light time: the state is
taken at the transmit time ``t - |r_s - r_r| / c`` and rotated into the ECEF
frame of the reception time (the Earth turns ``omega_e * tau`` meanwhile).
"""

import csv
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..constants import C_MPS, DAY_S
from ..constellations import DEFAULT_FAMILY, REGISTRY, carriers_hz
from ..errors import InputError
from ..fileio import check_input_file, write_csv
from ..frames import rotate_to_later_ecef
from ..orbits.constellation import Constellation
from ..orbits.propagate import state_ecef_pairs
from ..timebase import format_utc, seconds_since, split_utc_offset

__all__ = ["Measurements", "read_measurements", "write_measurements", "sv_states_from_tle", "clock_groups",
           "row_families", "SV_STATE_COLUMNS", "DEFAULT_CARRIER_HZ", "MAX_TLE_AGE_DAYS"]

#: Satellite state columns, ECEF at the measurement time.
SV_STATE_COLUMNS = ("x_sv_m", "y_sv_m", "z_sv_m", "vx_sv_mps", "vy_sv_mps", "vz_sv_mps")
#: Carrier when neither the table nor the caller gives one: the default family's (Starlink pilot).
DEFAULT_CARRIER_HZ = REGISTRY[DEFAULT_FAMILY].carrier_hz
#: Largest distance in time from an element set's epoch that is propagated [days].
MAX_TLE_AGE_DAYS = 30.0


@dataclass(frozen=True, eq=False)
class Measurements:
    """Accepted rows of a measurement table, in file order.

    Attributes
    ----------
    t_s : ndarray, (n,)
        Seconds after ``epoch_utc`` (or as given in a ``t_s`` column).
    time_utc : ndarray of datetime64[ns], (n,), or None
        None when the table has only ``t_s``.
    sat_id : ndarray of str, (n,)
    doppler_hz, sigma_hz, carrier_hz : ndarray, (n,)
        ``sigma_hz`` is NaN where not given.
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n, 3), or None
        From the state columns, None without them.
    line : ndarray of int, (n,), or None
        Line number of each row in the file; None for a table made in code.
    pass_id : ndarray of str, (n,), or None
        From the optional ``pass_id`` column (empty fields read as ``""``).
    family : ndarray of str, (n,), or None
        Constellation of each row's satellite (a key of :data:`leosop.constellations.REGISTRY`, ``""``
        unknown); None when read without element sets.
    phase_cycles, phase_sigma_cycles : ndarray, (n,), or None
        Accumulated carrier phase (``d phase / dt = doppler_hz``) and its
        standard deviation, NaN where not given; None without the column.
    arc : ndarray of str, (n,), or None
        Label of the phase's arc (a cycle slip starts a new one); None without the column.
    rejected : tuple of (int, str)
        Line number and reason of every row set aside.
    source : str
    """

    t_s: np.ndarray
    time_utc: np.ndarray | None
    sat_id: np.ndarray
    doppler_hz: np.ndarray
    sigma_hz: np.ndarray
    carrier_hz: np.ndarray
    pos_sv_ecef_m: np.ndarray | None = None
    vel_sv_ecef_mps: np.ndarray | None = None
    line: np.ndarray | None = None
    rejected: tuple = ()
    source: str = ""
    pass_id: np.ndarray | None = None
    family: np.ndarray | None = None
    phase_cycles: np.ndarray | None = None
    phase_sigma_cycles: np.ndarray | None = None
    arc: np.ndarray | None = None

    def __len__(self):
        return len(self.doppler_hz)

    @property
    def epoch_utc(self):
        """First measurement time (the origin of ``t_s``), or None."""
        return None if self.time_utc is None else self.time_utc.min()

    def take(self, index):
        """Rows at ``index``; rejected rows are kept."""
        pick = lambda a: None if a is None else a[index]  # noqa: E731
        return replace(self, t_s=self.t_s[index], time_utc=pick(self.time_utc), sat_id=self.sat_id[index],
                       doppler_hz=self.doppler_hz[index], sigma_hz=self.sigma_hz[index],
                       carrier_hz=self.carrier_hz[index], pos_sv_ecef_m=pick(self.pos_sv_ecef_m),
                       vel_sv_ecef_mps=pick(self.vel_sv_ecef_mps), line=self.line[index],
                       pass_id=pick(self.pass_id), family=pick(self.family), phase_cycles=pick(self.phase_cycles),
                       phase_sigma_cycles=pick(self.phase_sigma_cycles), arc=pick(self.arc))


def _floats(values):
    """Floats of text values and a mask of those that are not finite numbers."""
    out = np.empty(len(values))
    for k, v in enumerate(values):
        try:
            out[k] = float(v)
        except ValueError:
            out[k] = np.nan
    return out, ~np.isfinite(out)


def _utc_ns(texts):
    """datetime64[ns] UTC of ISO 8601 texts ending in ``Z``, an offset (``+01:00``) or nothing; NaT where one is
    not a time. Array (n,)."""
    parts = [split_utc_offset(s) for s in texts]  # the zone off (numpy would parse it with a warning)
    minutes = np.array([m or 0 for _, m in parts], dtype="timedelta64[m]")
    try:  # the usual table at once; a date numpy cannot read sends it row by row
        out = np.array([s if m is not None else "NaT" for s, m in parts], dtype="datetime64[ns]")
    except ValueError:
        out = np.empty(len(parts), dtype="datetime64[ns]")
        for k, (s, m) in enumerate(parts):
            try:
                out[k] = np.datetime64(s if m is not None else "NaT", "ns")
            except ValueError:
                out[k] = np.datetime64("NaT")
    return out - minutes


def read_measurements(path: str | os.PathLike[str], *, carrier_hz: float | None = None,
                      constellation: Constellation | None = None) -> Measurements:
    """Read a Doppler measurement CSV (DESIGN 4.3).

    Parameters
    ----------
    path : str or Path
    carrier_hz : float, optional
        Carrier of rows with neither a ``carrier_hz`` value nor a satellite
        of a known family; default :data:`DEFAULT_CARRIER_HZ` unless the
        file mixes carriers (then such a row is an error).
    constellation : Constellation, optional
        Element sets whose names give each satellite's family (its carrier
        and receiver clock).

    Returns
    -------
    Measurements
        Only accepted rows; the others are listed in ``rejected``.
    """
    path = Path(path)
    check_input_file(path, "measurement file")
    with open(path, newline="", encoding="utf-8-sig", errors="replace") as fh:  # a BOM (Excel) is not a field
        rows = [r for r in csv.reader(fh)]
    numbered = [(k + 1, r) for k, r in enumerate(rows) if r and any(c.strip() for c in r)]
    if not numbered:
        raise InputError(f"{path}: empty file, expected a header row and Doppler measurements")
    header = [c.strip().lower() for c in numbered[0][1]]
    body = numbered[1:]
    col = {name: k for k, name in enumerate(header)}
    missing = [c for c in ("sat_id", "doppler_hz") if c not in col]
    if "time_utc" not in col and "t_s" not in col:
        missing.insert(0, "time_utc or t_s")
    if missing:
        raise InputError(f"{path}: missing column {', '.join(missing)} (columns: {', '.join(header)})")
    state_given = [c for c in SV_STATE_COLUMNS if c in col]
    if state_given and len(state_given) < len(SV_STATE_COLUMNS):
        absent = [c for c in SV_STATE_COLUMNS if c not in col]
        raise InputError(f"{path}: incomplete satellite state, missing column {', '.join(absent)}")
    if not body:
        raise InputError(f"{path}: no measurement rows after the header")

    lines = np.array([n for n, _ in body])
    reason = np.full(len(body), "", dtype=object)
    width = len(header)
    short = np.array([len(r) < width for _, r in body])
    reason[short] = f"expected {width} fields"
    field = lambda name: [r[col[name]].strip() if len(r) > col[name] else "" for _, r in body]  # noqa: E731

    def number(name, default=None, positive=False):
        if name not in col:
            return np.full(len(body), np.nan if default is None else default)
        text = field(name)
        values, bad = _floats(text)
        if default is not None:
            blank = np.array([t == "" for t in text])
            values[blank], bad[blank] = default, False
        if positive:
            bad |= ~(values > 0)
        for k in np.flatnonzero(bad & (reason == "")):
            reason[k] = f"{name} is {text[k]!r}, expected a {'positive ' if positive else ''}number"
        return values

    time_utc = None
    if "time_utc" in col:
        text = field("time_utc")
        time_utc = _utc_ns(text)
        for i in np.flatnonzero(np.isnat(time_utc) & (reason == "")):
            reason[i] = (f"time_utc is {text[i]!r}, expected ISO 8601 in UTC or with a UTC offset "
                         "(e.g. 2024-01-02T03:04:05Z, 2024-01-02T04:04:05+01:00)")
        t_s = np.zeros(len(body))
    else:
        t_s = number("t_s")
    sat_id = np.array(field("sat_id"), dtype=str)
    for k in np.flatnonzero((sat_id == "") & (reason == "")):
        reason[k] = "sat_id is empty"
    doppler = number("doppler_hz")
    sigma = number("sigma_hz", default=np.nan)
    for k in np.flatnonzero(np.isfinite(sigma) & ~(sigma > 0) & (reason == "")):
        reason[k] = f"sigma_hz is {sigma[k]:g}, expected a positive number or an empty field"
    family = row_families(sat_id, constellation) if constellation is not None else np.full(len(body), "")
    carrier = number("carrier_hz", default=0.0)
    text_c = field("carrier_hz") if "carrier_hz" in col else [""] * len(body)
    blank = np.array([t == "" for t in text_c], dtype=bool)
    for k in np.flatnonzero(~blank & ~(carrier > 0) & (reason == "")):
        reason[k] = f"carrier_hz is {text_c[k]!r}, expected a positive number"
    carrier = _fill_carriers(path, carrier, blank, family, carrier_hz, lines, sat_id, reason)
    state = np.stack([number(c) for c in SV_STATE_COLUMNS], axis=-1) if state_given else None
    phase = number("phase_cycles", default=np.nan) if "phase_cycles" in col else None
    phase_sigma = number("phase_sigma_cycles", default=np.nan) if "phase_sigma_cycles" in col else None
    if phase_sigma is not None:
        for k in np.flatnonzero(np.isfinite(phase_sigma) & ~(phase_sigma > 0) & (reason == "")):
            reason[k] = f"phase_sigma_cycles is {phase_sigma[k]:g}, expected a positive number or an empty field"

    # Duplicates: the same satellite at the same time; the first row is kept.
    key_time = time_utc.astype(np.int64) if time_utc is not None else t_s
    first: dict[tuple, int] = {}  # (time, sat_id) -> index of its first row
    for k in np.flatnonzero(reason == ""):
        key = (key_time[k], sat_id[k])
        if key in first:
            reason[k] = f"duplicate of line {lines[first[key]]} (same sat_id and time)"
        else:
            first[key] = int(k)
    ok = reason == ""
    rejected = tuple((int(lines[k]), str(reason[k])) for k in np.flatnonzero(~ok))
    if not ok.any():
        raise InputError(f"{path}: no usable measurement rows (line {rejected[0][0]}: {rejected[0][1]})")
    if time_utc is not None:
        t_s = seconds_since(time_utc, time_utc[ok].min())
    return Measurements(
        t_s=t_s[ok], time_utc=None if time_utc is None else time_utc[ok], sat_id=sat_id[ok],
        doppler_hz=doppler[ok], sigma_hz=sigma[ok], carrier_hz=carrier[ok],
        pos_sv_ecef_m=None if state is None else state[ok, :3],
        vel_sv_ecef_mps=None if state is None else state[ok, 3:], line=lines[ok], rejected=rejected,
        source=str(path), pass_id=np.array(field("pass_id"), dtype=str)[ok] if "pass_id" in col else None,
        family=family[ok] if constellation is not None else None,
        phase_cycles=None if phase is None else phase[ok],
        phase_sigma_cycles=None if phase_sigma is None else phase_sigma[ok],
        arc=np.array(field("arc"), dtype=str)[ok] if "arc" in col else None,
    )


def _fill_carriers(path, carrier, blank, family, carrier_hz, lines, sat_id, reason):
    """Carriers of the rows without a value: family, caller, default (see the module notes)."""
    carrier = carrier.copy()
    fam = blank & (family != "")
    carrier[fam] = carriers_hz(family[fam])
    rest = blank & ~fam & (reason == "")
    if not rest.any():
        return carrier
    if carrier_hz is not None:
        carrier[blank & ~fam] = float(carrier_hz)
        return carrier
    known = np.unique(carrier[~blank | fam][(reason == "")[~blank | fam]])
    if known.size > 1 or (known.size == 1 and known[0] != DEFAULT_CARRIER_HZ):
        k = np.flatnonzero(rest)[0]
        shown = ", ".join(f"{f:g}" for f in known[:4]) + (" ..." if known.size > 4 else "")
        raise InputError(f"{path}:{lines[k]}: carrier of satellite {sat_id[k]} cannot be determined: give "
                         "carrier_hz, constellation (element sets naming its family), or a carrier_hz value on the "
                         f"row (it has none, no known family in the element sets, and the file has carriers {shown} "
                         "Hz)", param=("carrier_hz", "constellation"))
    carrier[blank & ~fam] = DEFAULT_CARRIER_HZ
    return carrier


def row_families(sat_id, constellation):
    """Family (registry key, ``""`` unknown) of each satellite id from the element sets' names, (n,)."""
    ids = np.asarray(sat_id, dtype=str)
    if constellation is None:
        return np.full(ids.shape, "")
    lookup = dict(zip(constellation.sat_ids.tolist(), constellation.families.tolist()))
    return np.array([lookup.get(s, "") for s in ids.tolist()], dtype=object).astype(str).reshape(ids.shape)


def clock_groups(meas, constellation=None):
    """Receiver clock of each row: its constellation, else its carrier.

    Parameters
    ----------
    meas : Measurements
    constellation : Constellation, optional
        Element sets for the families when ``meas.family`` is None.

    Returns
    -------
    index : ndarray of int, (n,)
        Clock of each row, into ``labels``.
    labels : tuple of str
        A family key, or ``"<carrier> Hz"`` for rows of no known family
        (one clock per distinct carrier).
    """
    family = meas.family if meas.family is not None else row_families(meas.sat_id, constellation)
    names = np.where(family != "", family, np.char.add(np.array([f"{f:.10g}" for f in meas.carrier_hz], dtype=str),
                                                      " Hz") if len(meas) else family)
    labels, index = np.unique(names.astype(str), return_inverse=True)
    return index.ravel(), tuple(labels.tolist())


def write_measurements(path, meas):
    """Write measurements as a DESIGN 4.3 table, atomically.

    Parameters
    ----------
    path : str or Path
    meas : Measurements
    """
    header, cols = [], []
    if meas.time_utc is not None:
        header.append("time_utc")
        cols.append(format_utc(meas.time_utc))
    else:
        header.append("t_s")
        cols.append([repr(float(v)) for v in meas.t_s])
    header += ["sat_id", "doppler_hz"]
    cols += [list(meas.sat_id), [repr(float(v)) for v in meas.doppler_hz]]
    if np.isfinite(meas.sigma_hz).any():
        header.append("sigma_hz")
        cols.append(["" if not np.isfinite(v) else repr(float(v)) for v in meas.sigma_hz])
    header.append("carrier_hz")
    cols.append([repr(float(v)) for v in meas.carrier_hz])
    if meas.pos_sv_ecef_m is not None:
        header += list(SV_STATE_COLUMNS)
        state = np.concatenate([meas.pos_sv_ecef_m, meas.vel_sv_ecef_mps], axis=-1)
        cols += [[repr(float(v)) for v in state[:, j]] for j in range(6)]
    if meas.pass_id is not None:
        header.append("pass_id")
        cols.append([str(v) for v in meas.pass_id])
    for name in ("phase_cycles", "phase_sigma_cycles"):
        values = getattr(meas, name)
        if values is not None:
            header.append(name)
            cols.append(["" if not np.isfinite(v) else repr(float(v)) for v in values])
    if meas.arc is not None:
        header.append("arc")
        cols.append([str(v) for v in meas.arc])
    write_csv(path, header, zip(*cols))


#: Step of the central difference that gives the apparent satellite velocity [s].
APPARENT_STEP_S = 0.5


def _apparent_states(constellation, index, t_rx, rx):
    """SGP4 state at the transmit time, rotated into the ECEF frame of the reception time.

    Fixed point of tau = |R(omega tau) r_s(t - tau) - r_r| / c; each pass
    gains a factor |range rate| / c ~ 3e-5, so four passes leave well under
    1 ns. Without ``rx`` the state at the reception time.
    """
    tau = np.zeros(len(index))
    for _ in range(4 if rx is not None else 1):
        t_tx = t_rx - np.round(tau * 1e9).astype("timedelta64[ns]")
        p, v, status = state_ecef_pairs(constellation, index, t_tx)
        p, v = rotate_to_later_ecef(p, tau), rotate_to_later_ecef(v, tau)
        if rx is not None:
            tau = np.linalg.norm(p - rx, axis=-1) / C_MPS
    return p, v, status


def sv_states_from_tle(constellation, sat_id, time_utc, pos_rx_ecef_m=None, *, max_age_days=MAX_TLE_AGE_DAYS):
    """Satellite states for measurements, propagated from element sets with light time.

    Parameters
    ----------
    constellation : Constellation
    sat_id : array_like of str, (n,)
        NORAD catalogue numbers.
    time_utc : array_like of datetime64, (n,)
        Reception times.
    pos_rx_ecef_m : array_like, (n, 3) or (3,), optional
        Receiver position for the light time; None gives the states at the
        reception time (no light time).
    max_age_days : float
        Rows further than this from their element set's epoch are refused.

    Returns
    -------
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (n, 3)
        Position at transmit time, in the ECEF frame of the reception time;
        with a receiver position, the velocity is that position's derivative
        over reception time (so ``-u . (v_sv - v_rx)`` is the range rate of
        the light-time range for a static receiver); NaN where refused.
    reason : ndarray of str, (n,)
        Why a row was refused; ``""`` where the state is valid.
    """
    ids = np.asarray(sat_id, dtype=str)
    t_rx = np.asarray(time_utc, dtype="datetime64[ns]")
    n = len(ids)
    lookup = {sid: i for i, sid in enumerate(constellation.sat_ids)}
    index = np.array([lookup.get(s, -1) for s in ids], dtype=int)
    reason = np.full(n, "", dtype=object)
    name = Path(constellation.source).name or "the element sets"
    for k in np.flatnonzero(index < 0):
        reason[k] = f"no element set for satellite id {ids[k]} in {name}"
    known = index >= 0
    age_days = np.full(n, np.nan)
    age_days[known] = seconds_since(t_rx[known], np.datetime64(0, "ns")) / DAY_S - \
        seconds_since(constellation.epochs_utc[index[known]], np.datetime64(0, "ns")) / DAY_S
    for k in np.flatnonzero(known & ~(np.abs(age_days) <= max_age_days)):
        reason[k] = (f"time {format_utc(t_rx[k])} is {age_days[k]:+.1f} days from the element set epoch of "
                     f"satellite {ids[k]} (limit {max_age_days:g} days)")
    ok = reason == ""
    pos = np.full((n, 3), np.nan)
    vel = np.full((n, 3), np.nan)
    if ok.any():
        rows = np.flatnonzero(ok)
        rx = None if pos_rx_ecef_m is None else np.broadcast_to(np.asarray(pos_rx_ecef_m, float), (n, 3))[rows]
        p, v, status = _apparent_states(constellation, index[rows], t_rx[rows], rx)
        if rx is not None:
            # The velocity the receiver sees is the derivative of the apparent
            # (emission-time, rotated) position over reception time: it carries
            # the light time's rate (the factor 1 / (1 - u.v_inertial / c), up
            # to ~6 Hz at Ku band) and agrees with SGP4's positions, which its
            # own velocity does not (~1 cm/s). Fourth-order central difference
            # over +-APPARENT_STEP_S and twice that: truncation ~1e-14 m/s,
            # SGP4's rounding (~1e-6 m) gives ~1e-6 m/s (0.04 mHz).
            h = np.timedelta64(int(APPARENT_STEP_S * 1e9), "ns")
            d = {}
            for j in (-2, -1, 1, 2):
                d[j], _, s_j = _apparent_states(constellation, index[rows], t_rx[rows] + j * h, rx)
                status = np.where(status != 0, status, s_j)
            v = (8.0 * (d[1] - d[-1]) - (d[2] - d[-2])) / (12.0 * APPARENT_STEP_S)
        pos[rows], vel[rows] = p, v
        for k, code in zip(rows, status):
            if code:
                reason[k] = f"SGP4 error code {code} for satellite {ids[k]} at {format_utc(t_rx[k])}"
                pos[k] = vel[k] = np.nan
    return pos, vel, reason.astype(str)
