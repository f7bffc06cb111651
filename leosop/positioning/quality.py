"""The status of a fix a user can filter on: ``ok`` only when the toolkit can vouch for it.

The solvers report how the numerics ended
(:class:`~leosop.positioning.robust_ls.FixStatus`); a converged solution can
still be one nobody should use. :func:`fix_status` labels each fix with the
first of these that applies, in this order:

``not_converged``, ``singular``, ``too_few``
    The solver's outcome: no solution.
``no_redundancy``
    As many measurements as unknowns (``dof`` 0): the solution fits any
    data exactly (residuals ~1e-10 Hz), so nothing tests it; its sigma
    is that of the geometry alone.
``inconsistent``
    The weighted residual sum fails the chi-square test against the
    measurement sigmas (``chi2_p`` below the significance). The covariance
    of such a fix is scaled by the variance factor ``chi2 / dof``
    (:func:`~leosop.positioning.robust_ls.solve_robust`).
``implausible_height``
    Outside :data:`ALT_MIN_M` .. :data:`ALT_MAX_M` above the ellipsoid: no
    ground or air receiver is there.
``implausible_velocity``
    A snapshot fix faster than :data:`SPEED_MAX_MPS`.
``ambiguous``
    A static fix with another solution (a single pass's mirror image across
    the ground track) that fits the data as well.
``single_pass``
    A static fix from one pass (one satellite's rows, or one ``pass_id``):
    its position rests on that one element set, whose along-track error
    (km for a day old element set) moves the fix by as much without showing
    in any residual, and on a side of the ground track chosen by the
    Earth's rotation alone. On the 98 DopTrack passes such fixes pass every
    residual test yet land tens to thousands of km off (their sigmas,
    even scaled for the residuals' correlation, cover few of them); the
    FOX-1D pass lands 12 km off at sigma 2.2 / 0.9 km.
``few_passes``
    A static fix from fewer than :data:`MIN_PASSES` passes (or satellites):
    each pass's element-set error shifts the fix, and only the passes'
    disagreement shows it (the multi-pass fix's variance factor and offsets,
    :mod:`~leosop.positioning.static_passes`); two passes leave that test 4
    degrees of freedom, too few to measure it. On DopTrack three of the
    five two-pass days put the station 3.8-7.5 sigma off along one axis,
    against one of 23 days of 3-6 passes (3.05 sigma).
``ok``
    None of the above.
"""

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .robust_ls import FixStatus

__all__ = ["fix_status", "ALT_MIN_M", "ALT_MAX_M", "SPEED_MAX_MPS", "MIN_PASSES", "STATUS_ALPHA", "STATUSES"]

#: Lowest plausible receiver height above the ellipsoid [m]: the Dead Sea shore is at -430 m
#: above sea level and the geoid lies within about -106 .. +85 m of the ellipsoid.
ALT_MIN_M = -500.0
#: Highest plausible receiver height [m]: the Karman line; above it the receiver is a spacecraft,
#: which a ground or air receiver's fix is not.
ALT_MAX_M = 100e3
#: Highest plausible receiver speed [m/s]: above the fastest aircraft in service (~1 km/s); a
#: snapshot fix faster than this has converged to a wrong solution.
SPEED_MAX_MPS = 1000.0
#: Fewest passes (satellites) of a static fix that can be ok (module docstring, ``few_passes``).
MIN_PASSES = 3
#: Significance of the residual chi-square test of the status when the caller gives none.
STATUS_ALPHA = 1e-3
#: Every status, ``ok`` first.
STATUSES = ("ok", "not_converged", "singular", "too_few", "no_redundancy", "inconsistent", "implausible_height",
            "implausible_velocity", "ambiguous", "single_pass", "few_passes")


def fix_status(solver_status, dof, chi2, alt_m, speed_mps=None, *, ambiguous=False, n_passes=None,
               alpha=STATUS_ALPHA):
    """Status label of each fix (module docstring) and the p-value of its residual test.

    Parameters
    ----------
    solver_status : array_like of int, (n,)
        :class:`~leosop.positioning.robust_ls.FixStatus` values.
    dof : array_like of int, (n,)
        Used measurements (and prior pseudo-measurements) minus states.
    chi2 : array_like, (n,)
        Weighted residual sum of squares of each fix.
    alt_m : array_like, (n,)
        Height above the ellipsoid [m] (NaN for an unsolved fix).
    speed_mps : array_like, (n,), optional
        Receiver speed of a snapshot fix [m/s]; None for a static fix.
    ambiguous : bool or array_like of bool, (n,)
        Static fixes: a mirror solution fits as well.
    n_passes : int or array_like of int, (n,), optional
        Static fixes: the passes (or satellites) of each; None for snapshot fixes.
    alpha : float or None
        Significance of the chi-square test; None or 0 take :data:`STATUS_ALPHA`.

    Returns
    -------
    status : ndarray of str, (n,)
    chi2_p : ndarray, (n,)
        Probability of a chi-square at least ``chi2`` with ``dof`` degrees
        of freedom; NaN where ``dof < 1``.
    """
    solver_status = np.atleast_1d(np.asarray(solver_status, dtype=int))
    n = solver_status.size
    dof = np.broadcast_to(np.asarray(dof, dtype=int), (n,))
    chi2 = np.broadcast_to(np.asarray(chi2, dtype=float), (n,))
    alt = np.broadcast_to(np.asarray(alt_m, dtype=float), (n,))
    speed = np.zeros(n) if speed_mps is None else np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))
    passes = np.full(n, MIN_PASSES) if n_passes is None else np.broadcast_to(np.asarray(n_passes), (n,))
    with np.errstate(invalid="ignore"):
        chi2_p = np.where(dof >= 1, chi2_dist.sf(chi2, np.maximum(dof, 1)), np.nan)
    alpha = alpha or STATUS_ALPHA
    # First match wins (np.select): the solver's failures, then the tests in the module docstring's order.
    conditions = [
        solver_status == FixStatus.NOT_CONVERGED,
        solver_status == FixStatus.SINGULAR,
        solver_status == FixStatus.TOO_FEW,
        dof < 1,
        (solver_status == FixStatus.INCONSISTENT) | (chi2_p < alpha),
        ~((alt >= ALT_MIN_M) & (alt <= ALT_MAX_M)),
        ~(speed <= SPEED_MAX_MPS),
        np.broadcast_to(ambiguous, (n,)),
        passes == 1,
        passes < MIN_PASSES,
    ]
    choices = ["not_converged", "singular", "too_few", "no_redundancy", "inconsistent", "implausible_height",
               "implausible_velocity", "ambiguous", "single_pass", "few_passes"]
    return np.select(conditions, choices, default="ok"), chi2_p
