"""The visibility screen: which (satellite, epoch) pairs can be above the mask, coarse to fine.

Every satellite is propagated on the coarsest grid of :data:`SCREEN_STEPS_S`.
Between two samples of a satellite an epoch can be visible only if the
elevation test can climb to 0 from both samples in the time between
(:func:`climb_epochs`, with :func:`speed_bound_mps`): a window of epochs. The
windows are sampled on the next grid, and so on; the epochs in the last
windows are the candidates, which :func:`evaluate_pairs` propagates and tests
exactly as a brute-force run does. The windows only leave out epochs that
cannot be visible, so the screened result is the brute-force one.
"""

import numpy as np

from ..constants import OMEGA_E_RAD_PER_S
from ..frames import teme_to_ecef

__all__ = ["SCREEN_STEPS_S", "CHUNK_POINTS", "climb_epochs", "evaluate_pairs", "propagated_geometry",
           "propagate_pairs", "screen_candidates", "speed_bound_mps"]

#: Screening grid steps [s], coarse to fine: every satellite is propagated on
#: the first, then only the stretches that can hold a visible epoch.
SCREEN_STEPS_S = (600.0, 60.0, 10.0)
#: Propagated points per SatrecArray call over many satellites (memory ~ 50 bytes per point).
CHUNK_POINTS = 4_000_000
# Radius of curvature of the WGS84 ellipsoid never falls below this [m]; it
# bounds how fast the local vertical turns for a moving receiver.
_MIN_CURVATURE_RADIUS_M = 6.33e6
# Rounding allowance of the screening windows' bounds [epochs] (the margins themselves hold ~10 % slack).
_EPOCH_SLACK = 1e-6


def _geometry(pos_sv, pos_rx, up_e):
    """Line of sight components: up projection and range, arrays (...)."""
    los = pos_sv - pos_rx
    return np.sum(los * up_e, axis=-1), np.linalg.norm(los, axis=-1), los


def propagated_geometry(r_km, v_kmps, err, ep, geometry):
    """ECEF states and the elevation test's terms of propagated points, any leading shape.

    Returns
    -------
    pos_sv, vel_sv : ndarray, (..., 3)
        NaN position where SGP4 failed (``err != 0``).
    up, range_m : ndarray, (...)
        Line of sight on the local vertical and its length [m]: visible
        where ``up >= sin(mask) * range_m``.
    """
    jd, fr, ujd, ufr, pos_rx, up_e, sin_mask = geometry
    r_km[err != 0] = np.nan
    pos, vel = teme_to_ecef(r_km * 1e3, v_kmps * 1e3, ujd[ep], ufr[ep])
    up, rng, _ = _geometry(pos, pos_rx[ep], up_e[ep])
    return pos, vel, up, rng


def propagate_pairs(constellation, sat, ep, geometry):
    """SGP4 at (satellite, epoch) pairs, one vectorised call per satellite.

    Parameters
    ----------
    sat, ep : ndarray of int, (m,)
        Sorted by satellite.

    Returns
    -------
    pos_sv, vel_sv : ndarray, (m, 3)
        ECEF; NaN position where SGP4 failed.
    up, range_m : ndarray, (m,)
        See :func:`propagated_geometry`.
    """
    jd, fr = geometry[0][ep], geometry[1][ep]
    err = np.empty(len(ep), np.int8)
    r_km, v_kmps = np.empty((len(ep), 3)), np.empty((len(ep), 3))
    bounds = np.searchsorted(sat, np.arange(len(constellation) + 1))
    for k in np.flatnonzero(np.diff(bounds)):
        a, b = bounds[k], bounds[k + 1]
        err[a:b], r_km[a:b], v_kmps[a:b] = constellation.satrecs[k].sgp4_array(jd[a:b], fr[a:b])
    return propagated_geometry(r_km, v_kmps, err, ep, geometry)


def evaluate_pairs(constellation, cand_sat, cand_ep, geometry):
    """Exact test of candidate pairs: the visible ones.

    Parameters
    ----------
    cand_sat, cand_ep : ndarray of int32, (n_cand,)
        Sorted by satellite.

    Returns
    -------
    sat_i, ep_i : ndarray of int32, (m,)
    pos_sv, vel_sv : ndarray, (m, 3)
    """
    pos, vel, up, rng = propagate_pairs(constellation, cand_sat, cand_ep, geometry)
    vis = up >= geometry[-1] * rng
    return cand_sat[vis], cand_ep[vis], pos[vis], vel[vis]


def speed_bound_mps(constellation):
    """An upper bound of each satellite's ECEF speed [m/s], (n_sats,).

    Vis-viva at perigee (the highest inertial speed of the mean orbit) plus
    the frame's rotation at apogee, ``|v_e| <= |v_i| + omega |r|``; 10 %
    headroom covers the osculating orbit's departure from the mean one (J2
    short-period terms, a day's drag: well under 1 %) and the sidereal rate's
    difference from ``omega``.
    """
    a_km = np.array([s.a * s.radiusearthkm for s in constellation.satrecs])
    e = np.array([s.ecco for s in constellation.satrecs])
    mu_km3_s2 = np.array([s.mu for s in constellation.satrecs])
    v_perigee_kmps = np.sqrt(mu_km3_s2 / a_km * (1.0 + e) / (1.0 - e))
    return 1.1e3 * (v_perigee_kmps + OMEGA_E_RAD_PER_S * a_km * (1.0 + e))


def climb_epochs(test_m, range_m, speed_sv_mps, speed_rx_mps, sin_mask, step_s):
    """Epochs the elevation test ``los.up - sin(mask)|los|`` needs to climb from ``test_m`` to 0, at least.

    Over ``tau`` seconds the satellite-receiver vector moves at most
    ``d = (v_sv + v_rx) tau`` and the local vertical turns by at most
    ``v_rx tau / R_min`` rad, so by the triangle inequality the test value
    changes by at most ``M(tau) = d (1 + sin mask) + (|los| + d) v_rx tau / R_min``.
    A sample whose test value is ``test_m < 0`` therefore has no visible
    epoch closer than the root of ``M(tau) = -test_m``; returned in epochs,
    0 where the test passes or is NaN (SGP4 failed). Arrays broadcast.
    """
    d_rate = speed_sv_mps + speed_rx_mps
    a = d_rate * speed_rx_mps / _MIN_CURVATURE_RADIUS_M
    b = d_rate * (1.0 + sin_mask) + range_m * speed_rx_mps / _MIN_CURVATURE_RADIUS_M
    c = np.maximum(-test_m, 0.0)
    tau = 2.0 * c / (b + np.sqrt(b * b + 4.0 * a * c)) / step_s
    return np.where(np.isnan(tau), 0.0, tau)  # a failed propagation (NaN) keeps its neighbourhood


def screen_candidates(constellation, e0, e1, n_t, strides, geometry, rates):
    """Candidate (satellite, epoch) pairs of epochs ``e0 .. e1 - 1`` (and ``e1`` if it is the last), coarse to fine.

    Every satellite is propagated at ``e0, e0 + strides[0], ..., e1``. Between
    two samples ``a < b`` of a satellite, an epoch ``t`` can be visible only if
    it lies in the window ``[a + tau_a, b - tau_b]``, ``tau`` the least time the
    elevation test needs to climb to 0 from each sample
    (:func:`climb_epochs`). The sub-intervals of the next stride that meet a
    window are sampled in turn, and so on; the epochs in the windows of the
    finest intervals are the candidates. The windows only drop epochs that
    cannot be visible, so the screened result is the brute-force one.

    Parameters
    ----------
    e0, e1 : int
        The block's first and last sample (``e1`` is the next block's first).
    n_t : int
        Number of epochs.
    strides : list of int
        Screening strides in epochs, decreasing, each >= 2.
    rates : tuple
        Satellite speed bounds [m/s] (n_sats,), receiver speed bound [m/s],
        epoch step [s].

    Returns
    -------
    cand_sat, cand_ep : ndarray of int32, (n_cand,)
        Sorted by satellite, then epoch.
    """
    jd, fr, ujd, ufr, pos_rx, up_e, sin_mask = geometry
    speed_sv, speed_rx, step_s = rates
    ce = np.r_[np.arange(e0, e1, strides[0]), e1]
    chunk = max(1, CHUNK_POINTS // len(ce))
    tau = np.empty((len(constellation), len(ce)))
    for c0 in range(0, len(constellation), chunk):
        # The whole constellation's propagator is built once and kept; a part's, for each block.
        sub = constellation if chunk >= len(constellation) else constellation.subset(slice(c0, c0 + chunk))
        err, r_km, v_kmps = sub.satrec_array.sgp4(jd[ce], fr[ce])
        _, _, up, rng = propagated_geometry(r_km, v_kmps, err, ce, geometry)
        tau[c0:c0 + chunk] = climb_epochs(up - sin_mask * rng, rng, speed_sv[c0:c0 + chunk, None], speed_rx,
                                           sin_mask, step_s)
    lo, hi = ce[:-1] + tau[:, :-1], ce[1:] - tau[:, 1:]
    sat, seg = np.nonzero(lo <= hi + _EPOCH_SLACK)
    a, b, lo, hi = ce[seg], ce[seg + 1], lo[sat, seg], hi[sat, seg]
    for stride in strides[1:]:
        sat, a, b, lo, hi = _refine(constellation, sat, a, b, lo, hi, stride, n_t, geometry, rates)
    # Epochs of each window; an interval's end is the next interval's start, but for the grid's last epoch.
    first = np.ceil(lo - _EPOCH_SLACK).astype(np.int64)
    n = np.maximum(np.minimum(np.floor(hi + _EPOCH_SLACK).astype(np.int64), b - (b < n_t - 1)) - first + 1, 0)
    offsets = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    return np.repeat(sat.astype(np.int32), n), (np.repeat(first, n) + offsets).astype(np.int32)


def _refine(constellation, sat, a, b, lo, hi, stride, n_t, geometry, rates):
    """The sub-intervals of ``stride`` epochs that meet the windows ``[lo, hi]`` of intervals ``[a, b]``, with
    their own windows; those that cannot hold a visible epoch left out. Arrays (n_intervals,), sorted by
    satellite then ``a``."""
    n_sub = -(-(b - a) // stride)
    j0 = np.maximum(np.ceil((lo - a - _EPOCH_SLACK) / stride).astype(np.int64) - 1, 0)
    j1 = np.minimum(np.floor((hi - a + _EPOCH_SLACK) / stride).astype(np.int64), n_sub - 1)
    n = np.maximum(j1 - j0 + 1, 0)
    j = np.repeat(j0, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    sat, a, b = np.repeat(sat, n), np.repeat(a, n) + j * stride, np.repeat(b, n)
    b = np.minimum(a + stride, b)
    key, where = np.unique(np.r_[sat * n_t + a, sat * n_t + b], return_inverse=True)
    _, _, up, rng = propagate_pairs(constellation, key // n_t, key % n_t, geometry)
    speed_sv, speed_rx, step_s = rates
    tau = climb_epochs(up - geometry[-1] * rng, rng, speed_sv[key // n_t], speed_rx, geometry[-1], step_s)
    lo, hi = a + tau[where[:len(a)]], b - tau[where[len(a):]]
    keep = lo <= hi + _EPOCH_SLACK
    return sat[keep], a[keep], b[keep], lo[keep], hi[keep]
