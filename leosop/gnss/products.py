"""Precise orbits (SP3-c/d) and clocks (RINEX clock 3) -> interpolated satellite states.

Times inside are float seconds ``t_s`` since a stated GPS-time epoch
``ref_gps`` (``datetime64[ns]``), both products and queries. SP3 positions
are the satellites' centres of mass in the product's ITRF realisation.
Orbits are interpolated with a sliding 11-point Lagrange polynomial
(degree 10, the usual choice for 15-min orbits, [Schenewerk 2003]), clocks
linearly between the 30 s records. An orbit query more than 0.1 spacing
outside the records (a clock query more than one), or next to a missing
record, returns NaN.
"""

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..constants import DAY_S
from ..errors import InputError
from .rinex import epochs_gps, read_text

__all__ = ["Clocks", "Orbits", "read_clk", "read_sp3", "read_wl_biases", "seconds_gps", "uncovered_note"]

#: Lagrange interpolation points for SP3 orbits.
N_LAGRANGE = 11


def seconds_gps(times_gps, ref_gps):
    """``datetime64`` GPS instants -> float seconds since ``ref_gps``."""
    return (np.asarray(times_gps, "datetime64[ns]") - np.datetime64(ref_gps, "ns")).astype(np.int64) / 1e9


@dataclass
class Orbits:
    """SP3 orbit records.

    Attributes
    ----------
    t_s : ndarray, shape (n_records,)
        Record epochs, seconds since ``ref_gps``, evenly spaced.
    sv : list of str, length n_sats
    pos_ecef_m : ndarray, shape (n_records, n_sats, 3)
        Centre-of-mass positions, NaN where the record is missing.
    """

    path: str
    ref_gps: np.datetime64
    t_s: np.ndarray
    sv: list
    pos_ecef_m: np.ndarray
    #: Queries at most this many record spacings beyond the end records are answered.
    margin: ClassVar[float] = 0.1

    def position(self, sv_idx, t_s):
        """Satellite positions at given times.

        Parameters
        ----------
        sv_idx : ndarray of int, shape (n,)
            Index into :attr:`sv`.
        t_s : ndarray, shape (n,)
            GPS time, seconds since ``ref_gps``.

        Returns
        -------
        ndarray, shape (n, 3)
            NaN outside the product (more than 0.1 spacing beyond its end nodes).
        """
        t_s = np.asarray(t_s, float)
        sv_idx = np.asarray(sv_idx, int)
        dt = self.t_s[1] - self.t_s[0]
        n = len(self.t_s)
        u = (t_s - self.t_s[0]) / dt
        u[np.isnan(u)] = -1e9
        start = np.minimum(np.maximum(np.floor(u).astype(int) - N_LAGRANGE // 2 + 1, 0), n - N_LAGRANGE)
        k = np.arange(N_LAGRANGE)
        x = u[:, None] - (start[:, None] + k)  # query minus node, in spacings
        # Lagrange basis: prod_{j != k} (u - u_j) / (u_k - u_j) on unit-spaced nodes, (n, k, j); the diagonal's
        # 0 / 0 set to 1 (a hot path: one pass per operation).
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = x[:, None, :] / (x[:, None, :] - x[:, :, None])
        ratio[:, k, k] = 1.0
        w = np.prod(ratio, axis=2)  # (n, k)
        nodes = self.pos_ecef_m[start[:, None] + k, sv_idx[:, None]]  # (n, k, 3)
        out = np.einsum("nk,nkc->nc", w, nodes)
        # Extrapolation past the end nodes is limited to 0.1 spacing (90 s for 15-min orbits): a degree-10
        # polynomial diverges beyond its nodes: 15 min past the last GRG record of the ESBC day it is off by
        # 0.43 m (median of the satellites) and up to 43 m.
        out[(u < -self.margin) | (u > n - 1 + self.margin)] = np.nan
        return out

    def state(self, sv_idx, t_s, *, h_s=0.5):
        """Positions and velocities (central difference over ``2 h_s``).

        Returns
        -------
        pos_ecef_m, vel_ecef_mps : ndarray, shape (n, 3)
        """
        p = self.position(sv_idx, t_s)
        v = (self.position(sv_idx, np.asarray(t_s) + h_s) - self.position(sv_idx, np.asarray(t_s) - h_s)) / (2 * h_s)
        return p, v


@dataclass
class Clocks:
    """RINEX clock satellite (``AS``) records.

    Attributes
    ----------
    t_s : ndarray, shape (n_records,)
        Record epochs, seconds since ``ref_gps``, evenly spaced.
    sv : list of str
    bias_s : ndarray, shape (n_records, n_sats)
        Satellite clock offsets [s], NaN where missing.
    wl_bias_cyc : dict of str -> float
        Satellite wide-lane biases of the header (:func:`read_wl_biases`).
    pcvs_applied : str
        The ANTEX file named by ``SYS / PCVS APPLIED`` ('' when absent).
    """

    path: str
    ref_gps: np.datetime64
    t_s: np.ndarray
    sv: list
    bias_s: np.ndarray
    wl_bias_cyc: dict = field(default_factory=dict)
    pcvs_applied: str = ""
    #: Queries at most this many record spacings beyond the end records are answered.
    margin: ClassVar[float] = 1.0

    def bias(self, sv_idx, t_s):
        """Clock offsets [s] at given times, linear between records, shape (n,)."""
        t_s = np.asarray(t_s, float)
        dt = self.t_s[1] - self.t_s[0]
        u = np.nan_to_num((t_s - self.t_s[0]) / dt, nan=-1e9)
        i0 = np.clip(np.floor(u).astype(int), 0, len(self.t_s) - 2)
        f = u - i0
        out = (1 - f) * self.bias_s[i0, sv_idx] + f * self.bias_s[i0 + 1, sv_idx]
        out[(u < -self.margin) | (u > len(self.t_s) - 1 + self.margin)] = np.nan
        return out


def uncovered_note(product, times_gps):
    """A one-line warning when a product falls short of the epochs by more than one record spacing, else None.

    A day's product ends one spacing before midnight (23:45 for 15-min
    orbits): the observations' last minutes beyond it are left out without a
    warning, as they are with every complete product.

    Parameters
    ----------
    product : Orbits or Clocks
    times_gps : ndarray of datetime64, shape (n,)
        The epochs to serve, e.g. the observations'.

    Returns
    -------
    str or None
        Names the product's file, its record span and how many of the epochs
        fall outside it (their queries return NaN: those epochs are left out).
    """
    t_s = seconds_gps(times_gps, product.ref_gps)
    step = product.t_s[1] - product.t_s[0]
    # A day's product starts at its first epoch: only its end has a spacing of slack.
    if product.t_s[0] - product.margin * step <= t_s[0] and t_s[-1] <= product.t_s[-1] + step:
        return None
    outside = (t_s < product.t_s[0] - product.margin * step) | (t_s > product.t_s[-1] + product.margin * step)
    first, last = (str(product.ref_gps + np.timedelta64(round(s * 1e9), "ns"))[:19] for s in product.t_s[[0, -1]])
    return (f"{product.path}: records cover only {first} to {last} GPST, the observations {str(times_gps[0])[:19]} "
            f"to {str(times_gps[-1])[:19]}: {int(outside.sum())} of the {outside.size} epochs are left out")


_EPOCH_FIELDS = ("year", "month", "day", "hour", "minute", "seconds")


def _epoch_fields(line, a, path, lineno):
    """Year, month, day, hour, minute, seconds of an epoch written from column ``a`` on."""
    f = line[a:].split()[:6]
    for name, text in zip(_EPOCH_FIELDS, f + [""] * (6 - len(f))):
        try:
            float(text)
        except ValueError:
            shown = f"{text!r} is not a number" if text else "is missing"
            raise InputError(f"{path}: line {lineno}: epoch record {line.strip()!r}: {name} {shown}") from None
    return tuple(float(v) for v in f)


#: Shortest record interval accepted [s] (RINEX clock products are 1 s to 5 min).
MIN_STEP_S = 1.0
#: Longest product span accepted [s]: a week of records and a day either side.
MAX_SPAN_S = 9 * DAY_S


def _grid(times, line_numbers, path, what):
    """Sorted epochs and their smallest spacing; every epoch on that grid, the grid a bounded size.

    Returns
    -------
    t : ndarray of datetime64[ns], shape (n,)
    step : timedelta64[ns]
    index : ndarray of int, shape (n,)
        Row of each sorted epoch in the regular grid ``t[0] + k * step``.
    order : ndarray of int, shape (n,)
        Sorting permutation of ``times``.
    """
    times = np.asarray(times)
    if len(times) < 2:
        raise InputError(f"{path}: fewer than two {what} epochs")
    order = np.argsort(times, kind="stable")
    t, lines = times[order], np.asarray(line_numbers)[order]
    dt = np.diff(t).astype(np.int64) * 1e-9
    if np.any(dt <= 0):
        raise InputError(f"{path}: line {lines[1:][dt <= 0][0]}: {what} epoch repeated")
    step = float(dt.min())
    span = (t[-1] - t[0]).astype(np.int64) * 1e-9
    if step < MIN_STEP_S or span > MAX_SPAN_S:
        raise InputError(f"{path}: {what} epochs {step:g} s apart over {span:g} s "
                         f"(expected at least {MIN_STEP_S:g} s apart over at most {MAX_SPAN_S:g} s)")
    u = (t - t[0]).astype(np.int64) * 1e-9 / step
    index = np.round(u).astype(int)
    off = np.abs(u - index) > 1e-3
    if np.any(off):
        raise InputError(f"{path}: line {lines[off][0]}: {what} epoch off the {step:g} s record grid")
    return t, np.timedelta64(round(step * 1e9), "ns"), index, order


def _sp3_coordinate(line, axis, path, lineno):
    """Coordinate ``axis`` (0 = X) [km] of an SP3 position record; InputError names the satellite and field."""
    text = line[4 + 14 * axis:18 + 14 * axis].strip()
    try:
        return float(text)
    except ValueError:
        shown = f"{text!r} is not a number" if text else "is missing"
        raise InputError(f"{path}: line {lineno}: position record {line[:4]}: {'XYZ'[axis]} coordinate [km] "
                         f"{shown}") from None


def read_sp3(path, *, systems="GE", ref_gps=None):
    """Read an SP3-c or SP3-d orbit file (plain or gzip).

    Parameters
    ----------
    systems : str
        System letters to keep.
    ref_gps : datetime64, optional
        Epoch of ``t_s``; default the first record.

    Returns
    -------
    Orbits
    """
    lines = read_text(path)
    path = str(path)
    if not lines or lines[0][:1] != "#" or lines[0][1:2] not in "cd" or not lines[0][1:2]:
        raise InputError(f"{path}: line 1: not an SP3-c/d orbit file")
    if lines[0][2:3] not in ("P", "V"):
        raise InputError(f"{path}: line 1: unknown SP3 position/velocity flag {lines[0][2:3]!r}")
    epochs, epoch_lines, recs = [], [], []
    for i, line in enumerate(lines):
        if line[:1] == "*":
            epochs.append(_epoch_fields(line, 1, path, i + 1))
            epoch_lines.append(i + 1)
        elif line[:1] == "P" and epochs:
            s = line[1:2]
            if s not in systems:
                continue
            x, y, z = (_sp3_coordinate(line, axis, path, i + 1) for axis in range(3))
            recs.append((len(epochs) - 1, line[1:4].replace(" ", "0"), x, y, z))
        elif line.startswith("EOF"):
            break
    if not recs:
        raise InputError(f"{path}: no position records for systems {systems!r}")
    t, step, _, order = _grid(epochs_gps(epochs, epoch_lines, path), epoch_lines, path, "SP3")
    if np.any(order != np.arange(len(order))):
        raise InputError(f"{path}: line {epoch_lines[np.flatnonzero(order != np.arange(len(order)))[0]]}: "
                         "SP3 epochs not in time order")
    if np.any(np.diff(t) != step):
        raise InputError(f"{path}: SP3 epochs are not evenly spaced")
    sv = sorted({r[1] for r in recs})
    col = {s: k for k, s in enumerate(sv)}
    pos = np.full((len(t), len(sv), 3), np.nan)
    for e, s, x, y, z in recs:
        if not (x == 0.0 and y == 0.0 and z == 0.0):
            pos[e, col[s]] = (x * 1e3, y * 1e3, z * 1e3)
    ref = t[0] if ref_gps is None else np.datetime64(ref_gps, "ns")
    return Orbits(path=path, ref_gps=ref, t_s=seconds_gps(t, ref), sv=sv, pos_ecef_m=pos)


def read_clk(path, *, systems="GE", ref_gps=None):
    """Read the satellite (``AS``) records of a RINEX clock file (plain or gzip).

    Returns
    -------
    Clocks
    """
    lines = read_text(path)
    path = str(path)
    if not lines or lines[0][60:].strip() != "RINEX VERSION / TYPE" or lines[0][20:21] != "C":
        raise InputError(f"{path}: line 1: not a RINEX clock file")
    end = next((i for i, line in enumerate(lines) if line[60:].strip() == "END OF HEADER"), None)
    if end is None:
        raise InputError(f"{path}: line {len(lines)}: no END OF HEADER (truncated file?)")
    keys, svs, vals = {}, [], []
    for i in range(end + 1, len(lines)):
        line = lines[i]
        if line[:2] != "AS" or line[3:4] not in systems:
            continue
        f = line[3:].split()
        try:
            key = tuple(float(v) for v in f[1:7])
            val = float(f[8])
        except (ValueError, IndexError):
            raise InputError(f"{path}: line {i + 1}: unreadable AS clock record") from None
        keys.setdefault(key, (len(keys), i + 1))
        svs.append((keys[key][0], f[0]))
        vals.append(val)
    if not vals:
        raise InputError(f"{path}: no satellite clock records for systems {systems!r}")
    fields = np.array(list(keys), float)
    key_lines = [ln for _, ln in keys.values()]
    t, step, idx, order = _grid(epochs_gps(fields, key_lines, path), key_lines, path, "clock")
    rank = np.empty(len(order), int)
    rank[order] = np.arange(len(order))
    # Records on a regular grid (gaps become NaN rows).
    grid = t[0] + np.arange(idx[-1] + 1) * step
    sv = sorted({s for _, s in svs})
    col = {s: k for k, s in enumerate(sv)}
    bias = np.full((len(grid), len(sv)), np.nan)
    e = idx[rank[np.fromiter((k for k, _ in svs), int, len(svs))]]
    bias[e, np.fromiter((col[s] for _, s in svs), int, len(svs))] = vals
    ref = grid[0] if ref_gps is None else np.datetime64(ref_gps, "ns")
    wsb, pcvs = _clk_header(lines[:end], path)
    return Clocks(path=path, ref_gps=ref, t_s=seconds_gps(grid, ref), sv=sv, bias_s=bias, wl_bias_cyc=wsb,
                  pcvs_applied=pcvs)



def read_wl_biases(path):
    """Satellite wide-lane biases [cycles] from the header of a CNES (GRG) RINEX clock file.

    The GRG integer-recovery clocks ([Laurichesse 2009]) carry the wide-lane
    satellite biases they were computed with as header ``COMMENT`` records::

        WL G01  2020  6 25 12  0  0.000000  1   -0.110300E+01  0102 COMMENT

    (satellite, epoch, count, value, flags). With them the Melbourne-
    Wuebbena combination ``MW + wsb`` of every satellite has the same
    fractional part (the receiver's): on ESBC00DNK 2020-06-25 the arc means
    scatter by 0.05 cycles around it (``tools/bench_ppp_ar.py``).

    Returns
    -------
    dict of str -> float
        Empty when the file has none.
    """
    return _clk_header(read_text(path), path)[0]


def _clk_header(lines, path):
    """Wide-lane biases (dict) and the ``SYS / PCVS APPLIED`` ANTEX name of a clock header."""
    out, pcvs = {}, ""
    for i, line in enumerate(lines):
        label = line[60:].strip()
        if label == "END OF HEADER":
            break
        if label == "SYS / PCVS APPLIED" and not pcvs:
            pcvs = line[20:60].strip()
        if label == "COMMENT" and line.startswith("WL "):
            f = line[:60].split()
            try:
                out[f[1]] = float(f[9])
            except (IndexError, ValueError):
                raise InputError(f"{path}: line {i + 1}: unreadable wide-lane bias comment") from None
    return out, pcvs
