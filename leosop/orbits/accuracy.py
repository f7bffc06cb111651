"""How far an element set's SGP4 position is from the satellite: a prior for the fixes that use it.

Published figures for low-Earth-orbit objects propagated by SGP4 from a
catalogue element set: radial and cross-track errors of 0.1-0.3 km near the
element set's epoch, along-track errors several times larger that grow
fastest (Flohrer et al. 2008, AMOS, "Assessment and categorization of TLE
orbit errors for the US SSN catalogue"); about 1 km within a few days of
the epoch (Kelso 2007, AAS 07-127). The along-track error is a time offset
of the satellite's states to first order, which the static fixes estimate
(:mod:`~leosop.positioning.static_passes`); the radial and cross-track
errors are not estimated by a single receiver (they show only as
disagreement between passes) and enter a fix's covariance from
:func:`element_set_sigma_rc_m`.
"""

import numpy as np

__all__ = ["SIGMA_RC_AT_EPOCH_M", "SIGMA_RC_GROWTH_M_PER_DAY", "element_set_sigma_rc_m"]

#: Standard deviation of an element set's radial and cross-track error at its epoch [m]: the low end
#: of the 0.1-0.3 km of Flohrer et al. (2008) radially, its middle cross-track.
SIGMA_RC_AT_EPOCH_M = (100.0, 200.0)
#: Growth of those standard deviations per day of element-set age [m/day] (assumed: a tenth of the
#: along-track growth of 1-3 km/day, reaching Kelso's (2007) ~1 km after a few days).
SIGMA_RC_GROWTH_M_PER_DAY = (100.0, 200.0)


def element_set_sigma_rc_m(age_days):
    """Radial and cross-track standard deviations of an element set's SGP4 position at an age.

    Parameters
    ----------
    age_days : array_like, (...)
        Time from the element set's epoch [days]; before the epoch counts
        alike (|age|).

    Returns
    -------
    ndarray, (..., 2)
        Radial and cross-track sigma [m].
    """
    age = np.abs(np.asarray(age_days, dtype=float))[..., None]
    return np.asarray(SIGMA_RC_AT_EPOCH_M) + np.asarray(SIGMA_RC_GROWTH_M_PER_DAY) * age
