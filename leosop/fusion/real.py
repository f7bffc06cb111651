"""Fusion of a real IMU log with an RTKLIB GNSS solution: aids, start, outages and their errors.

The pieces ``leosop fuse`` (DESIGN 4.1, 4.5) and ``tools/bench_fuse.py`` share:

* :class:`ImuSpec` (:mod:`leosop.fusion.imu_noise`): the IMU noise model, by grade or from a JSON file;
* :func:`fuse`: GNSS position and velocity aids (with lever arm, the
  epochs of the simulated outages withheld), optional ZUPT/zero-rate and NHC
  aids (at rest where :func:`leosop.ins.stationary.stationary_windows`
  says), the start from the first GNSS epoch (levelled from the
  accelerometers, yaw from the course over ground once moving), and the
  engine run (:mod:`leosop.fusion.engine`);
* :func:`outage_errors`: horizontal errors of the antenna track against the
  withheld fixes (Q = 1, or all withheld epochs when none is a fix).

Time inside a run is seconds since the first epoch of the GNSS file (the
clock of ``--outage START_S,DURATION_S``); the IMU log and the GNSS file
meet in Unix-style GPST seconds.
"""

import dataclasses
import math

import numpy as np
import scipy.stats

from .. import earth, frames
from ..errors import InputError
from ..gnss.rtklib_pos import Q_DR, Q_FIX, Q_FLOAT, Q_SINGLE
from ..ins import gaps
from ..ins.error_model import DPOS, DV, EPS, NABLA, PHI
from ..ins.stationary import stationary_windows
from ..ins.strapdown import NavState
from ..rotations import dcm_to_euler, euler_to_dcm, quat_to_dcm
from . import aids as aid_models
from . import engine
from .imu_noise import GRADES, ImuSpec, imu_spec
from .common import N_INS, pos_jacobian

__all__ = [
    "GRADES",
    "INSIDE_3SIGMA_CHI2",
    "FuseOptions",
    "FuseRun",
    "ImuSpec",
    "fuse",
    "imu_spec",
    "outage_errors",
]

#: Chi-square (2 degrees of freedom) of the probability of a 1-D 3-sigma interval, 0.9973: a horizontal
#: error inside the filter's 3-sigma ellipse.
INSIDE_3SIGMA_CHI2 = float(scipy.stats.chi2.ppf(scipy.stats.chi2.cdf(9.0, 1), 2))
#: Measurement noise of float and single GNSS epochs relative to their stated sigmas (RTKLIB's sigmas of
#: unfixed solutions are optimistic; the factors of rtklibexplorer/GNSS_IMU's configurations).
_Q_GAIN = {Q_FIX: 1.0, Q_FLOAT: 2.0, Q_SINGLE: 5.0}
#: The yaw bank's motion starts where the GNSS speed stays over 1 m/s this long [s].
_SUSTAINED_S = 3.0
#: An output epoch is dead reckoning (Q = 7) when the last GNSS epoch used is older than this [s].
_DR_AFTER_S = 1.0
#: A walker's pace is the median GNSS speed over this long [s] before a gap.
_PACE_S = 5.0


@dataclasses.dataclass(frozen=True)
class FuseOptions:
    """What to fuse and how.

    ``outages``: ``(start_s, duration_s)`` after the first GNSS epoch;
    ``lever_arm_b_m``: antenna minus IMU in the body frame (Right-Forward-Up);
    ``zupt``/``nhc``: add those aids; sigmas in the units of their names.
    ``gnss_vel_sigma_floor_mps`` is added (in quadrature) to the stated GNSS
    velocity sigmas: RTKLIB's Doppler velocity sigmas (0.06 m/s on the drive)
    left a quarter of the velocity innovations beyond their 99 % quantile.
    ``gnss_vel_accel_sigma_s``: the GNSS velocity's sigma per axis grows by
    this times the acceleration (:class:`leosop.fusion.aids.GnssVelocity`):
    against the velocity of the Q = 1 fixes (0.25 s differences), outside
    the bench outages, RTKLIB's Doppler velocities err by 0.04 m/s RMS at
    under 0.5 m/s^2, 0.1 at 0.5-1, 0.2 at 1-2, 0.3 m/s at 2-4 m/s^2 on the
    drive, alike on the walk (docs/fusion-real.md).
    ``nhc_slip_s``, ``nhc_offset_m``: the NHC's lateral sigma grows with the
    lateral acceleration and the yaw rate (:class:`leosop.fusion.aids.NonHolonomic`):
    fitted, outside the bench outages, to the drive's lateral body velocity
    (GNSS velocity in the filter's attitude) as ``-0.10 w_up + 0.115 w_up v``
    (residual 0.09 m/s with the GNSS velocity noise).
    ``time_offset_sigma_s``: the IMU time offset is a filter state with this
    prior sigma around the given offset (None: taken as known);
    ``scale_sigma``: gyro and accelerometer scale-factor states with these
    prior sigmas (None: none). ``gyro_cross_sigma``: the six gyro cross-axis
    (misalignment) terms as states with this prior sigma (None: none); with
    ``scale_sigma`` the full 3 x 3 gyro error matrix.
    ``yaw_hypotheses``, ``yaw_bank_s``: a start at rest without NHC (a
    hand-held IMU, whose Forward axis need not point along the motion) runs
    this many filters with yaws spread over the circle, each with the yaw
    sigma of half their spacing, and keeps the one whose GNSS innovations
    fit best (least negative log-likelihood) at the decision time:
    ``yaw_bank_s`` after the GNSS speed first stays over 1 m/s for 3 s, or the first
    outage start after it when earlier (:func:`_yaw_bank`). 0: the yaw from
    the course over ground, as for a car.
    ``course_yaw``: ``(min_speed_mps, sigma_deg)``: the yaw from the course
    over ground at the first GNSS velocity of at least ``min_speed_mps``,
    whatever the other options (no yaw bank), its sigma that of the course
    (the velocity's sigma across the track over the speed, at that epoch)
    and ``sigma_deg`` in quadrature: a vehicle whose nose points along its
    motion once fast, up to a sideslip or wind crab of ``sigma_deg``, e.g.
    an aircraft handled on the ground before its launch. None: 1 m/s and no
    sideslip (a car, :class:`leosop.fusion.engine.CourseAlignment`; the yaw
    bank without NHC).
    ``bridge_gaps``: the increments over gaps in the log bridged by the
    trapezoid rule and their error variance added to the process noise
    (:func:`leosop.ins.gaps.bridge`; a log without gaps is unchanged).
    ``walking_speed``: a pedestrian's pace where GNSS is missing
    (:func:`_walking_aids`), ``walking_speed_sigma_mps`` its scatter.
    """

    spec: ImuSpec
    outages: tuple = ()
    lever_arm_b_m: tuple = (0.0, 0.0, 0.0)
    zupt: bool = False
    nhc: bool = False
    zupt_sigma_mps: float = 0.01
    zero_rate_sigma_deg_per_s: float = 0.01
    nhc_sigma_mps: float = 0.1
    nhc_rate_hz: float = 10.0
    nhc_slip_s: float = 0.12
    nhc_offset_m: float = 0.1
    gnss_vel_sigma_floor_mps: float = 0.1
    gnss_vel_accel_sigma_s: float = 0.1
    time_offset_sigma_s: float | None = 0.1
    scale_sigma: tuple | None = None
    gyro_cross_sigma: float | None = None
    yaw_hypotheses: int = 12
    yaw_bank_s: float = 20.0
    course_yaw: tuple | None = None
    bridge_gaps: bool = True
    walking_speed: bool = False
    walking_speed_sigma_mps: float = 0.2

    def course_alignment(self):
        """The :class:`leosop.fusion.engine.CourseAlignment` of a start whose yaw is not known."""
        if self.course_yaw is None:
            return engine.CourseAlignment()
        speed, sigma_deg = self.course_yaw
        return engine.CourseAlignment(min_speed_mps=speed, sigma_rad=math.radians(sigma_deg))


@dataclasses.dataclass(frozen=True)
class FuseRun:
    """A fused log.

    Attributes
    ----------
    result : leosop.fusion.engine.EngineResult
        The INS (at the IMU) after every update; ``t_s`` since the first GNSS epoch.
    t0_gpst_s : float
        Unix-style GPST of ``t_s = 0``.
    lat_deg, lon_deg, alt_m : ndarray, (n,)
        The antenna (IMU plus the lever arm).
    q : ndarray of int, (n,)
        RTKLIB quality of each output epoch: that of the last GNSS epoch used
        when within 1 s, else 7 (dead reckoning).
    withheld : ndarray of bool, (n_gnss,)
        GNSS epochs inside an outage.
    gnss_t_s : ndarray, (n_gnss,)
        GNSS epochs on the run's clock.
    n_aids : dict of str to int
        Aids offered per kind.
    """

    result: engine.EngineResult
    t0_gpst_s: float
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    q: np.ndarray
    withheld: np.ndarray
    gnss_t_s: np.ndarray
    n_aids: dict


def _gnss_aids(sol, t_g, use, lever, vel_floor_mps, vel_accel_sigma_s):
    out = []
    for k in np.flatnonzero(use):
        gain2 = _Q_GAIN.get(int(sol.q[k]), 5.0) ** 2
        out.append(aid_models.GnssPosition(t_g[k], math.radians(sol.lat_deg[k]), math.radians(sol.lon_deg[k]),
                                           sol.alt_m[k], sol.cov_enu_m2[k] * gain2, lever))
        if sol.vel_enu_mps is not None:
            cov = sol.cov_vel_enu_m2ps2[k] * gain2 + np.eye(3) * vel_floor_mps**2
            out.append(aid_models.GnssVelocity(t_g[k], sol.vel_enu_mps[k], cov, lever, accel_sigma_s=vel_accel_sigma_s))
    return out


def _walking_aids(t_g, vel_enu_mps, t_imu, rest_ends, sigma_mps):
    """:class:`~leosop.fusion.aids.WalkingSpeed` aids, one a second, where no GNSS epoch came for 1 s.

    The pace is the median horizontal GNSS speed over the last
    ``_PACE_S`` before the gap (at least 0.5 m/s: walking); none in a window
    at rest (``rest_ends``, each window's last sample, 1 s long).
    """
    t = np.arange(t_imu[0], t_imu[-1], 1.0)
    last = np.searchsorted(t_g, t, side="right") - 1
    t_last = t_g[np.maximum(last, 0)]
    i = np.searchsorted(rest_ends, t)
    at_rest = (i < rest_ends.size) & (rest_ends[np.minimum(i, rest_ends.size - 1)] - t < 1.0)
    speed = np.hypot(vel_enu_mps[:, 0], vel_enu_mps[:, 1])
    out = []
    for tk, tl, ok in zip(t, t_last, (last >= 0) & ~at_rest):
        pace = np.median(speed[(t_g > tl - _PACE_S) & (t_g <= tl)])
        if ok and tk - tl > _DR_AFTER_S and pace >= 0.5:
            out.append(aid_models.WalkingSpeed(tk, pace, sigma_mps))
    return out


def _initial(sol, k, t_g, t_start, f_b_mps2, spec, course):
    """State and covariance at ``t_start`` from GNSS epoch k (moved along its velocity) and levelling.

    The yaw is that of the course when epoch k is at least ``course.min_speed_mps`` fast (its sigma
    that of the course, :func:`leosop.fusion.engine.course_sigma_rad`, and ``course.sigma_rad`` in
    quadrature); else unknown, and ``course`` is returned for the engine to set it later.
    """
    lat, lon, alt = math.radians(sol.lat_deg[k]), math.radians(sol.lon_deg[k]), float(sol.alt_m[k])
    v = np.zeros(3) if sol.vel_enu_mps is None else sol.vel_enu_mps[k]
    R_M, R_N = earth.radii_m(lat)
    dt = t_start - t_g[k]
    lat, lon, alt = lat + v[1] * dt / (R_M + alt), lon + v[0] * dt / ((R_N + alt) * math.cos(lat)), alt + v[2] * dt
    f = f_b_mps2 / np.linalg.norm(f_b_mps2)
    pitch, roll = math.asin(f[1]), math.atan2(-f[0], f[2])  # f_b = C_n_b^T [0, 0, g]
    moving = math.hypot(v[0], v[1]) >= course.min_speed_mps
    yaw = math.atan2(-v[0], v[1]) if moving else 0.0
    state = NavState.from_dcm(lat, lon, alt, v, euler_to_dcm(pitch, roll, yaw))
    P = np.zeros((N_INS, N_INS))
    P[DV, DV] = (np.eye(3) * 0.1**2 if sol.cov_vel_enu_m2ps2 is None else sol.cov_vel_enu_m2ps2[k]) + np.eye(3) * 1e-4
    sigma_yaw_rad = (math.hypot(course.sigma_rad, engine.course_sigma_rad(v, P[DV, DV])) if moving
                     else math.radians(30.0))
    P[PHI, PHI] = np.diag([math.radians(2.0), math.radians(2.0), sigma_yaw_rad]) ** 2
    J_inv = np.linalg.inv(pos_jacobian(lat, alt))
    P[DPOS, DPOS] = J_inv @ (sol.cov_enu_m2[k] + np.eye(3) * 0.01) @ J_inv.T
    P[EPS, EPS] = np.eye(3) * math.radians(spec.gyro_bias_sigma_deg_per_s) ** 2
    P[NABLA, NABLA] = np.eye(3) * spec.accel_bias_sigma_mps2**2
    return state, P, None if moving else course


def _yaw_bank(state0, P0, t_imu, dt, dth, dvl, var, aids, settings, t_g, sol, withheld, options):
    """The best of ``options.yaw_hypotheses`` starting yaws, and its yaw sigma; None when undecidable.

    Each hypothesis runs the engine from the start to the decision time on
    the aids offered; the one with the least negative log-likelihood of its
    GNSS innovations wins. It is the member a bank of filters keeps at the
    decision time, so the outages after it are scored on a causal filter;
    the output before it is that member's (a fixed-lag choice over the
    first seconds).
    """
    if sol.vel_enu_mps is None:
        return None
    fast = (np.hypot(sol.vel_enu_mps[:, 0], sol.vel_enu_mps[:, 1]) >= engine.CourseAlignment().min_speed_mps)
    # Motion begins at the first GNSS epoch after which the speed stays up for _SUSTAINED_S (not a noisy fix).
    slow_t = t_g[~fast]
    nxt = np.searchsorted(slow_t, t_g, side="right")
    next_slow = np.where(nxt < slow_t.size, slow_t[np.minimum(nxt, slow_t.size - 1)], np.inf)
    start = np.flatnonzero(fast & ~withheld & (t_g > t_imu[0]) & (next_slow - t_g >= _SUSTAINED_S))
    if start.size == 0:
        return None
    t_move = t_g[start[0]]
    t_decide = min([t_move + options.yaw_bank_s] + [s for s, _ in options.outages if s > t_move])
    n = int(np.searchsorted(t_imu, t_decide))
    if n < 4 or t_decide - t_move < 2.0:
        return None
    pitch, roll, _ = dcm_to_euler(state0.C_n_b)
    sigma = math.pi / options.yaw_hypotheses
    P = P0.copy()
    P[PHI.start + 2, PHI.start + 2] = sigma**2
    best = None
    # Only the log-likelihoods are compared: each hypothesis records its start alone.
    quiet = dataclasses.replace(settings, record_every=n)
    for yaw in 2.0 * math.pi * np.arange(options.yaw_hypotheses) / options.yaw_hypotheses:
        state = NavState.from_dcm(state0.lat_rad, state0.lon_rad, state0.alt_m, state0.vel_enu_mps,
                                  euler_to_dcm(pitch, roll, yaw))
        res = engine.run(state, P, t_imu[:n], dt[:n], dth[:n], dvl[:n], aids, quiet, increment_var=var[:n])
        nll = res.nll.get("gnss_position", 0.0) + res.nll.get("gnss_velocity", 0.0)
        if best is None or nll < best[0]:
            best = (nll, state)
    return best[1], P


def fuse(log, sol, options, *, imu_time_offset_s=0.0, extra_aids=(), progress=None):
    """Fuse an IMU log with an RTKLIB solution.

    Parameters
    ----------
    log : leosop.ins.imu_io.ImuLog
        In the vehicle's body frame (mounting applied), with a GPST epoch.
    sol : leosop.gnss.rtklib_pos.PosSolution
    options : FuseOptions
    imu_time_offset_s : float
        Added to the IMU time tags.
    extra_aids : sequence of leosop.fusion.aids.Aid
        More aids on the run's clock, e.g. LEO Doppler (:mod:`leosop.apps.fuse_leo`);
        not withheld in the outages.
    progress : callable, optional
        Wraps the iterator over INS updates.

    Returns
    -------
    FuseRun
    """
    if log.epoch_gpst_s is None:
        raise InputError(f"{log.source}: the IMU log has no GPST time (needed to meet the GNSS file)")
    t0 = float(sol.t_gpst_s[0])
    t_imu = log.epoch_gpst_s - t0 + log.t_s + imu_time_offset_s
    t_g = sol.t_gpst_s - t0
    withheld = np.zeros(t_g.size, dtype=bool)
    for start, duration in options.outages:
        withheld |= (t_g >= start) & (t_g < start + duration)
    first = np.flatnonzero((t_g >= t_imu[0] - log.dt_s[0]) & ~withheld)
    if first.size == 0 or t_g[first[0]] >= t_imu[-1] - 1.0:
        raise InputError(f"{sol.source}: no GNSS epoch outside the outages during the IMU log "
                         f"{log.source} (GPST times do not overlap)")
    k0 = int(first[0])
    i0 = int(np.searchsorted(t_imu - log.dt_s, t_g[k0]))
    t_imu, dt = t_imu[i0:], log.dt_s[i0:]
    if options.bridge_gaps:
        dth, dvl, var = gaps.bridge(log)
    else:
        dth, dvl, var = log.dtheta_b_rad, log.dvel_b_mps, np.zeros((log.t_s.size, 6))
    dth, dvl, var = dth[i0:], dvl[i0:], var[i0:]
    n_level = max(2, int(np.searchsorted(t_imu, t_imu[0] + 1.0)))
    state0, P0, course = _initial(sol, k0, t_g, t_imu[0] - dt[0], dvl[:n_level].sum(0) / dt[:n_level].sum(),
                                  options.spec, options.course_alignment())
    lever = np.asarray(options.lever_arm_b_m, dtype=float)
    aid_list = _gnss_aids(sol, t_g, ~withheld & (t_g > t_imu[0] - dt[0]), lever, options.gnss_vel_sigma_floor_mps,
                          options.gnss_vel_accel_sigma_s)
    aid_list += [a for a in extra_aids if a.t_s > t_imu[0] - dt[0]]
    if options.zupt or options.walking_speed:
        ends, w = stationary_windows(t_imu, dvl / dt[:, None], dth / dt[:, None])
    if options.walking_speed and sol.vel_enu_mps is not None:
        aid_list += _walking_aids(t_g[~withheld], sol.vel_enu_mps[~withheld], t_imu, ends,
                                  options.walking_speed_sigma_mps)
    if options.zupt:
        zr_sigma = math.radians(options.zero_rate_sigma_deg_per_s)
        for te, wm in zip(ends, w):
            aid_list += [aid_models.ZeroVelocity(te, options.zupt_sigma_mps), aid_models.ZeroRate(te, wm, zr_sigma)]
    if options.nhc:
        aid_list += [aid_models.NonHolonomic(t, options.nhc_sigma_mps, slip_s=options.nhc_slip_s,
                                             offset_m=options.nhc_offset_m)
                     for t in np.arange(t_imu[0], t_imu[-1], 1.0 / options.nhc_rate_hz)]
    aid_list.sort(key=lambda a: a.t_s)
    n_aids = {}
    for a in aid_list:
        n_aids[a.name] = n_aids.get(a.name, 0) + 1
    settings = dataclasses.replace(options.spec.settings(), time_offset_sigma_s=options.time_offset_sigma_s,
                                   scale_sigma=options.scale_sigma, gyro_cross_sigma=options.gyro_cross_sigma)
    if course is not None and options.yaw_hypotheses and not options.nhc and options.course_yaw is None:
        chosen = _yaw_bank(state0, P0, t_imu, dt, dth, dvl, var, aid_list, settings, t_g, sol, withheld, options)
        if chosen is not None:
            (state0, P0), course = chosen, None
    res = engine.run(state0, P0, t_imu, dt, dth, dvl, aid_list, settings, course_alignment=course,
                     progress=progress, increment_var=var)
    res = _on_gnss_clock(res)
    lat, lon, alt = _antenna(res, lever)
    used = np.flatnonzero(~withheld)
    last = np.searchsorted(t_g[used], res.t_s, side="right") - 1
    age = res.t_s - t_g[used][np.maximum(last, 0)]
    q = np.where((last >= 0) & (age <= _DR_AFTER_S), sol.q[used][np.maximum(last, 0)], Q_DR)
    return FuseRun(res, t0, lat, lon, alt, q.astype(int), withheld, t_g, n_aids)


def _on_gnss_clock(res):
    """The result with its times moved to the GNSS clock by the running offset estimate.

    An epoch whose moved time is not half an INS update after all earlier
    ones (the estimate jumped, early in a run) is dropped: the outputs keep
    strictly increasing times at the 1 ms of an RTKLIB solution file.
    """
    t = res.t_s - res.time_offset_s
    keep = np.r_[True, t[1:] > np.maximum.accumulate(t)[:-1] + 0.5 * np.median(np.diff(res.t_s))]
    n = t.size
    cut = {f.name: getattr(res, f.name)[keep] for f in dataclasses.fields(res)
           if isinstance(getattr(res, f.name), np.ndarray) and getattr(res, f.name).shape[:1] == (n,)}
    return dataclasses.replace(res, **{**cut, "t_s": t[keep]})


def _antenna(res, lever):
    """Geodetic antenna position [deg, deg, m] of every epoch: the IMU plus ``C_n_b @ lever``."""
    off = quat_to_dcm(res.q_n_b) @ lever
    R_M, R_N = earth.radii_m(res.lat_rad)
    lat = res.lat_rad + off[:, 1] / (R_M + res.alt_m)
    lon = res.lon_rad + off[:, 0] / ((R_N + res.alt_m) * np.cos(res.lat_rad))
    return np.degrees(lat), np.degrees(lon), res.alt_m + off[:, 2]


def outage_errors(run, sol, options):
    """Horizontal errors of the antenna track at the withheld GNSS epochs, per outage.

    Returns
    -------
    outages : list of dict
        Per outage: ``start_s``, ``duration_s``, ``max_horiz_err_m``,
        ``end_horiz_err_m`` (at its last reference epoch), ``n_ref``,
        ``n_inside_3sigma``, and the series ``t_s``, ``horiz_err_m``,
        ``horiz_sigma_m`` (sqrt of the trace of the filter's horizontal
        covariance) for the figures.
    reference : str
        ``"Q=1"``, or ``"all withheld"`` when no withheld epoch is a fix.
    """
    res = run.result
    ref = run.withheld & (sol.q == Q_FIX)
    reference = "Q=1"
    if run.withheld.any() and not ref.any():
        ref, reference = run.withheld.copy(), "all withheld"
    pos = frames.geodetic_to_ecef(np.radians(run.lat_deg), np.radians(run.lon_deg), run.alt_m)
    out = []
    for start, duration in options.outages:
        k = np.flatnonzero(ref & (run.gnss_t_s >= start) & (run.gnss_t_s < start + duration)
                           & (run.gnss_t_s >= res.t_s[0]) & (run.gnss_t_s <= res.t_s[-1]))
        row = {"start_s": float(start), "duration_s": float(duration), "n_ref": int(k.size)}
        if k.size == 0:
            out.append({**row, "max_horiz_err_m": None, "end_horiz_err_m": None, "n_inside_3sigma": 0,
                        "t_s": [], "horiz_err_m": [], "horiz_sigma_m": []})
            continue
        t = run.gnss_t_s[k]
        est = np.stack([np.interp(t, res.t_s, pos[:, c]) for c in range(3)], axis=-1)
        lat_r, lon_r = np.radians(sol.lat_deg[k]), np.radians(sol.lon_deg[k])
        truth = frames.geodetic_to_ecef(lat_r, lon_r, sol.alt_m[k])
        e = frames.ecef_to_enu(est - truth, lat_r, lon_r)[:, :2]
        i = np.clip(np.searchsorted(res.t_s, t), 0, res.t_s.size - 1)
        cov = res.cov_pos_enu_m2[i, :2, :2] + sol.cov_enu_m2[k, :2, :2]
        d2 = np.einsum("ki,ki->k", e, np.linalg.solve(cov, e[..., None])[..., 0])
        err = np.hypot(e[:, 0], e[:, 1])
        out.append({**row, "max_horiz_err_m": float(err.max()), "end_horiz_err_m": float(err[-1]),
                    "n_inside_3sigma": int((d2 <= INSIDE_3SIGMA_CHI2).sum()), "t_s": t.tolist(),
                    "horiz_err_m": err.tolist(), "horiz_sigma_m": np.sqrt(np.trace(cov, axis1=1, axis2=2)).tolist()})
    return out, reference
