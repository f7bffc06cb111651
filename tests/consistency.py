"""The filter-consistency claims of issue 6, asserted one way for every filter test."""

import numpy as np
from scipy import stats


def assert_filter_consistent(nees_pos_vel, nis_sum, nis_dof, lag_a, lag_b):
    """NEES, NIS and whiteness of a filter over seeded runs.

    Parameters
    ----------
    nees_pos_vel : array_like
        NEES of position and velocity (6 dof) at every epoch of every run.
    nis_sum, nis_dof : float, int
        Sum of all normalised innovation squares and their total dof.
    lag_a, lag_b : array_like
        Whitened innovations and their successors one epoch later.

    Mean NEES within [0.5, 2] of its dimension (issue 6); the NIS sum inside
    the 99.9 % two-sided chi-square interval; the lag-1 correlation, ~N(0, 1/n)
    for n white pairs under the null, below 4/sqrt(n).
    """
    nees = np.asarray(nees_pos_vel, dtype=float)
    assert 0.5 * 6 <= nees.mean() <= 2.0 * 6, nees.mean() / 6
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], nis_dof)
    assert lo <= nis_sum <= hi, (nis_sum / nis_dof, lo / nis_dof, hi / nis_dof)
    a, b = np.ravel(lag_a), np.ravel(lag_b)
    assert abs(np.corrcoef(a, b)[0, 1]) < 4.0 / np.sqrt(a.size)
