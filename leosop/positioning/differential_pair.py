"""A differential fix from two measurement tables: the rover's and a base's at a known site.

What ``leosop position ROVER.csv --base BASE.csv --base-site ...`` does
before and after :func:`~leosop.positioning.differential.solve_differential`:
refuse a pair that cannot be differenced (no satellite in common, tables
that do not overlap in time, e.g. of different days, one with time tags and
one without), give each table's rows
their satellite states (its columns, else the element sets with light time
from the receiver: the base's known site, the rover's start) and a sigma,
and set the fix's block times back on the rows' clock.
"""

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import InputError
from ..orbits.constellation import Constellation
from ..timebase import format_utc, seconds_since
from .differential import DifferentialFix, solve_differential
from .measurements import Measurements
from .solve import satellite_states

__all__ = ["DifferentialPair", "solve_pair"]

#: Tables whose starts are further apart than this are called "of different days" in the error [s].
_DAY_APART_S = 12 * 3600.0


@dataclass(frozen=True, eq=False)
class DifferentialPair:
    """A differential fix of two tables.

    Attributes
    ----------
    fix : DifferentialFix
    rover, base : Measurements
        The rows used (with satellite states and sigmas).
    time_utc : ndarray of datetime64[ns], (n_b,), or None
        Each block's ``t_ref_s`` in UTC (None for tables with ``t_s`` only).
    t_s : ndarray, (n_b,)
        Each block's ``t_ref_s`` in seconds after the rover's first row (its
        ``t_s`` for tables without time tags).
    common_sats : tuple of str
    rejected : list of (str, int, str)
        File, line and reason of every row set aside.
    sv_states : str
        Where the rover's states came from: ``"csv"`` or ``"tle"``.
    """

    fix: DifferentialFix
    rover: object
    base: object
    time_utc: np.ndarray | None
    t_s: np.ndarray
    common_sats: tuple
    rejected: list
    sv_states: str


def _prepared(meas, constellation, pos_rx_ecef_m, sigma_hz):
    """Rows with states and sigmas; the rejected rows as (line, reason)."""
    pos, vel, reason, source = satellite_states(meas, constellation, pos_rx_ecef_m)
    sigma = np.asarray(meas.sigma_hz, float)
    if sigma_hz is not None:
        sigma = np.where(np.isfinite(sigma), sigma, sigma_hz)
    elif not np.isfinite(sigma).all():
        line = int(meas.line[np.flatnonzero(~np.isfinite(sigma))[0]])
        raise InputError(f"{meas.source}:{line}: give sigma_hz or a sigma_hz column: a differential fix weighs "
                         "the two receivers' rows by it, and this row has none", param="sigma_hz")
    meas = replace(meas, pos_sv_ecef_m=pos, vel_sv_ecef_mps=vel, sigma_hz=sigma)
    rejected = list(meas.rejected) + [(int(meas.line[k]), str(reason[k])) for k in np.flatnonzero(reason != "")]
    return meas.take(np.flatnonzero(reason == "")), rejected, source


def _check_pair(rover, base):
    """Refuse tables that cannot be differenced: no common satellite, no common time, mixed time tags."""
    if (rover.time_utc is None) != (base.time_utc is None):
        with_t = base.source if rover.time_utc is None else rover.source
        raise InputError(f"{with_t} has time_utc, the other table only t_s: give both the same time column")
    if rover.time_utc is not None:
        span_r, span_b = (format_utc(m.time_utc[[np.argmin(m.time_utc), np.argmax(m.time_utc)]])
                          for m in (rover, base))
        apart_s = abs(seconds_since(base.time_utc.min(), rover.time_utc.min()))
        if base.time_utc.max() < rover.time_utc.min() or rover.time_utc.max() < base.time_utc.min():
            why = "tables of different days" if apart_s > _DAY_APART_S else "tables that do not overlap in time"
            raise InputError(f"{base.source}: the base spans {span_b[0]} .. {span_b[1]}, the rover {span_r[0]} .. "
                             f"{span_r[1]}: {why} share no satellite pass")
    common = tuple(np.intersect1d(rover.sat_id, base.sat_id).tolist())
    if not common:
        raise InputError(f"{base.source}: no satellite in common with {rover.source} (rover "
                         f"{', '.join(np.unique(rover.sat_id)[:10])}; base {', '.join(np.unique(base.sat_id)[:10])})")
    return common


def solve_pair(rover: Measurements, base: Measurements, base_pos_ecef_m: npt.ArrayLike, *,
               constellation: Constellation | None = None, pos0_ecef_m: npt.ArrayLike | None = None,
               sigma_hz: float | None = None, **kwargs: Any) -> DifferentialPair:
    """The rover's differential fix from two measurement tables.

    Parameters
    ----------
    rover, base : Measurements
        As read from DESIGN 4.3 tables (:func:`~leosop.positioning.measurements.read_measurements`).
    base_pos_ecef_m : array_like, (3,)
        The base's known site.
    constellation : Constellation, optional
        Element sets for tables without state columns.
    pos0_ecef_m : array_like, (3,), optional
        Start of the rover (and its light time); default the base's site.
    sigma_hz : float, optional
        Sigma of rows without ``sigma_hz`` (else such a row is an error).
    **kwargs
        Passed to :func:`~leosop.positioning.differential.solve_differential`
        (``block_s``, ``motion``, ``clock_degree``, ``sat_clock_degree``, ``alpha``).

    Returns
    -------
    DifferentialPair
    """
    base_pos = np.asarray(base_pos_ecef_m, float).reshape(3)
    pos0 = base_pos if pos0_ecef_m is None else np.asarray(pos0_ecef_m, float).reshape(3)
    _check_pair(rover, base)
    rover, rej_r, source = _prepared(rover, constellation, pos0, sigma_hz)
    base, rej_b, _ = _prepared(base, constellation, base_pos, sigma_hz)
    common = _check_pair(rover, base)
    fix = solve_differential(rover, base, base_pos, pos0_ecef_m=pos0, **kwargs)
    if rover.time_utc is not None and base.time_utc is not None:  # both or neither (_check_pair)
        epoch = min(rover.time_utc.min(), base.time_utc.min())
        time_utc = epoch + np.round(np.nan_to_num(fix.t_ref_s) * 1e9).astype("timedelta64[ns]")
        t_s = seconds_since(time_utc, rover.time_utc.min())
    else:
        time_utc, t_s = None, fix.t_ref_s
    rejected = [(rover.source, line, why) for line, why in rej_r] + [(base.source, line, why) for line, why in rej_b]
    return DifferentialPair(fix, rover, base, time_utc, t_s, common, rejected, source)
