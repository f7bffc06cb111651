"""Are the element sets close enough in time to the recording to identify its satellites?"""

import sys

import numpy as np

from ..errors import InputError
from ..positioning.measurements import MAX_TLE_AGE_DAYS

__all__ = ["TLE_AGE_WARN_DAYS", "check_snapshot_age"]


#: Element sets older or newer than this against the recording are warned about [days]
#: (along-track errors grow by ~km per day); beyond MAX_TLE_AGE_DAYS none is used.
TLE_AGE_WARN_DAYS = 3.0


def check_snapshot_age(rec, constellation):
    """Warn when the element sets are far from the recording's date; refuse when none can be used.

    Returns
    -------
    float
        Median age of the element sets at the recording's start [days] (positive: older).
    """
    age_days = (rec.start_utc - constellation.epochs_utc) / np.timedelta64(1, "D")
    usable = np.abs(age_days) <= MAX_TLE_AGE_DAYS
    median = float(np.median(age_days))
    name = getattr(constellation, "source", "") or "the element sets"
    if not usable.any():
        raise InputError(f"{name}: no element set within {MAX_TLE_AGE_DAYS:g} days of the recording "
                         f"({np.datetime_as_string(rec.start_utc, unit='s')}Z; median age {median:+.1f} days): "
                         "no satellite can be propagated to it")
    if abs(median) > TLE_AGE_WARN_DAYS:
        print(f"leosop replay: warning: {name}: the element sets are {median:+.1f} days from the recording "
              f"(median); along-track errors of km per day make identification and fixes worse", file=sys.stderr)
    return median
