"""Differential replay: a base recording at a known site corrects a rover's (issue 23).

Both recordings are replayed alike (:func:`~leosop.replay.pipeline.replay`:
combs found, tracked and identified); the identified tracks of each become
measurement rows (:func:`~leosop.replay.pipeline.track_measurements`, with
no satellite-offset model sigma: the satellite's offset is in both rows and
cancels), each with the element-set states for its own receiver (light time
from the base's known site, and from the rover's own identification), and
:func:`~leosop.positioning.differential.solve_differential` matches the rows
by satellite identity, interpolates the base to the rover's epochs and fits
the rover. A static rover gets one fix with a rover-minus-base frequency
offset and drift; otherwise one fix per ``block_s`` (at rest within it) with
a constant offset.

:func:`check_pair` refuses a pair that cannot be differenced before any
work: recordings of different bands (``core:frequency``) or days.
"""

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..positioning.differential import DifferentialFix, solve_differential
from ..positioning.measurements import Measurements, sv_states_from_tle
from ..timebase import format_utc, seconds_since
from .pipeline import track_measurements

__all__ = ["BASE_PRIOR_RADIUS_M", "DifferentialReplay", "block_times", "check_pair", "differential_fix"]

#: Radius of the base's identification search around its known site [m]: the site is exact, the search's
#: first cells are a fifth of this, so a few km is one round of votes (150 km, a rover's ``--init``, is four).
BASE_PRIOR_RADIUS_M = 5e3
#: Two recordings' nominal frequencies closer than this are the same band [Hz] (a float written as text).
_SAME_BAND_HZ = 1.0


@dataclass(frozen=True, eq=False)
class DifferentialReplay:
    """A differential fix from two replays.

    Attributes
    ----------
    fix : DifferentialFix
    rover, base : Measurements
        The identified tracks' rows with their satellite states.
    epoch_utc : datetime64[ns]
        Origin of ``fix.t_ref_s``: the earlier of the two first rows.
    common_sats : tuple of str
        Satellites identified in both recordings.
    """

    fix: DifferentialFix
    rover: Measurements
    base: Measurements
    epoch_utc: np.datetime64
    common_sats: tuple


def check_pair(rover_rec, base_rec):
    """Refuse a base and rover that cannot be differenced: another band, or another day.

    Parameters
    ----------
    rover_rec, base_rec : Recording
        With ``center_hz`` and ``start_utc`` (:func:`~leosop.signal.iq.open_sigmf`).
    """
    names = (rover_rec.data_path, base_rec.data_path)
    f_r, f_b = rover_rec.center_hz, base_rec.center_hz
    if (f_r is None) != (f_b is None) or (f_r is not None and abs(f_r - f_b) > _SAME_BAND_HZ):
        raise InputError(f"{names[1]}: the base records {f_b} Hz, the rover ({names[0]}) {f_r} Hz: different bands "
                         "cannot be differenced")
    if rover_rec.start_utc is None or base_rec.start_utc is None:
        return  # the pipeline refuses a recording without core:datetime
    days = [np.datetime64(r.start_utc, "D") for r in (rover_rec, base_rec)]
    if days[0] != days[1]:
        raise InputError(f"{names[1]}: the base starts {format_utc(base_rec.start_utc)}, the rover "
                         f"{format_utc(rover_rec.start_utc)}: recordings of different days share no satellite pass")


def _with_states(meas, constellation, pos_rx_ecef_m, name):
    """Rows with the element-set states seen from ``pos_rx_ecef_m``; rows without a state dropped."""
    pos, vel, reason = sv_states_from_tle(constellation, meas.sat_id, meas.time_utc, pos_rx_ecef_m)
    meas = replace(meas, pos_sv_ecef_m=pos, vel_sv_ecef_mps=vel, source=name)
    return meas.take(np.flatnonzero(reason == ""))


def differential_fix(rover_res, base_res, constellation, base_pos_ecef_m, *, carrier_hz, static=True, block_s=None):
    """The rover's differential fix from two replays.

    Parameters
    ----------
    rover_res, base_res : ReplayResult
        :func:`~leosop.replay.pipeline.replay` of each recording.
    constellation : Constellation
        The element sets both were identified against.
    base_pos_ecef_m : array_like, (3,)
        The base's known site.
    carrier_hz : float
        Nominal frequency of the pilot comb's central tone (the recordings').
    static : bool
        One fix of a rover at rest; else one per ``block_s``.
    block_s : float, optional
        Block of a moving rover's fixes [s] (required without ``static``).

    Returns
    -------
    DifferentialReplay
    """
    base_pos = np.asarray(base_pos_ecef_m, dtype=float).reshape(3)
    rover = track_measurements(rover_res.tracks, carrier_hz)
    base = track_measurements(base_res.tracks, carrier_hz)
    for meas, name in ((rover, "rover"), (base, "base")):
        if meas is None:
            raise InputError(f"the {name} recording has no identified satellite: nothing to difference")
    common = tuple(np.intersect1d(rover.sat_id, base.sat_id).tolist())
    if not common:
        raise InputError(f"no satellite in common: the rover identified {', '.join(np.unique(rover.sat_id))}, "
                         f"the base {', '.join(np.unique(base.sat_id))}")
    # The rover's light time from its own identification (good to a few km: ~1e-5 s of light time, mm of
    # satellite motion), else from the base's site.
    guess = getattr(rover_res.identification, "pos_ecef_m", None)
    pos0 = base_pos if guess is None or not np.all(np.isfinite(guess)) else np.asarray(guess, dtype=float)
    rover = _with_states(rover, constellation, pos0, "rover")
    base = _with_states(base, constellation, base_pos, "base")
    fix = solve_differential(rover, base, base_pos, pos0_ecef_m=pos0, block_s=None if static else block_s,
                             clock_degree=1)
    epoch = min(rover.time_utc.min(), base.time_utc.min())
    return DifferentialReplay(fix, rover, base, epoch, common)


def block_times(result):
    """Each block's mid-time in UTC and in seconds from the rover's first row, ((n_b,), (n_b,))."""
    t_ref_ns = np.round(result.fix.t_ref_s * 1e9).astype("timedelta64[ns]")
    time_utc = result.epoch_utc + t_ref_ns
    return time_utc, seconds_since(time_utc, result.rover.time_utc.min())
