"""The end-to-end run of a scenario: truth and IMU, the INS alone, the LEO fixes, and the loose or tight EKF."""

import time
import warnings

import numpy as np

from ... import earth, frames
from ...constants import DAY_S
from ...errors import InputError
from ...fusion import aids_fix, common
from ...ins import imu, strapdown, trajectory
from ...timebase import format_utc, seconds_since
from ..scenarios import scenario_tle
from . import measure, sky, tight
from .result import SimulationResult

__all__ = ["COUPLINGS", "LEVELS", "run_scenario"]

LEVELS = ("signal", "measurement")
COUPLINGS = ("loose", "tight")
#: Initial attitude uncertainty of the filter (E, N, U) [deg]: the paper
#: gives none; the truth starts without attitude error, these are the
#: figures of a fine-aligned navigation-grade INS.
ATT_SIGMA_DEG = (0.01, 0.01, 0.05)
#: Element sets further than this from the start earn a warning.
STALE_TLE_DAYS = 14.0
#: Fix epochs of IMU increments made at a time (10,000 at 100 Hz and 1 Hz fixes):
#: memory then stays flat in the run's duration.
IMU_BLOCK_STEPS = 100


def _check_options(level, coupling, correction_period_s, orbit_error_m):
    if level not in LEVELS:
        raise InputError(f"level {level!r}: expected one of {', '.join(LEVELS)}", param="level")
    if coupling not in COUPLINGS:
        raise InputError(f"coupling {coupling!r}: expected one of {', '.join(COUPLINGS)}", param="coupling")
    if not (np.isfinite(correction_period_s) and correction_period_s > 0):
        raise InputError(f"correction_period_s {correction_period_s:g}: must be a positive number of seconds",
                         param="correction_period_s")
    if orbit_error_m is not None and not (np.isfinite(orbit_error_m) and orbit_error_m >= 0):
        raise InputError(f"orbit_error_m {orbit_error_m:g}: must be a number >= 0", param="orbit_error_m")


def _imu_errors(spec, rng):
    """[Shen 2024] Table 1 errors with the constant biases' signs drawn per axis."""
    signs_g, signs_a = rng.choice([-1.0, 1.0], size=(2, 3))
    return imu.ImuErrors.from_quoted(
        gyro_bias_deg_per_h=signs_g * spec.gyro_bias_deg_per_h, gyro_arw_deg_per_rt_h=spec.gyro_arw_deg_per_rt_h,
        accel_bias_g=signs_a * spec.accel_bias_g, accel_vrw_g_per_rt_hz=spec.accel_vrw_g_per_rt_hz)


def _filter_settings(scenario, errors, correction_period_s):
    init = scenario.init_error
    return common.FilterSettings(
        pos_sigma_m=tuple(max(abs(v), 1.0) for v in init.pos_m),
        vel_sigma_mps=tuple(max(abs(v), 0.01) for v in init.vel_mps),
        att_sigma_rad=tuple(np.radians(ATT_SIGMA_DEG)),
        gyro_bias_sigma_rad_per_s=max(float(np.abs(errors.gyro_bias_rad_per_s).max()), 1e-9),
        accel_bias_sigma_mps2=max(float(np.abs(errors.accel_bias_mps2).max()), 1e-7),
        gyro_arw_rad_per_rt_s=float(errors.gyro_arw_rad_per_rt_s.max()),
        accel_vrw_mps2_per_rt_hz=float(errors.accel_vrw_mps_per_rt_s.max()),
        correction_period_s=correction_period_s, step_s=1.0 / scenario.leo.fix_rate_hz)


def _initial_state(truth, init):
    """Truth at t = 0 plus the scenario's ENU position and velocity errors."""
    lat, alt = truth.lat_rad[0], truth.alt_m[0]
    R_M, R_N = earth.radii_m(lat)
    de, dn, du = init.pos_m
    return strapdown.NavState.from_dcm(lat + dn / (R_M + alt), truth.lon_rad[0] + de / ((R_N + alt) * np.cos(lat)),
                                       alt + du, truth.vel_enu_mps[0] + np.asarray(init.vel_mps), truth.C_n_b[0])


def _fly(scenario, errors, rng_imu):
    """The truth flight at the fix rate and its corrupted IMU increments, made a block at a time.

    Returns
    -------
    truth : leosop.ins.trajectory.Track
        The truth at the fix epochs (n_epochs,).
    measured : leosop.ins.imu.MeasuredIncrements
        The IMU increments with ``errors`` (noise drawn from ``rng_imu``), :data:`IMU_BLOCK_STEPS` fix
        epochs at a time.
    dt_s : float
        IMU sample interval.
    per_step : int
        IMU samples per fix epoch (even: the two-sample strapdown grid).
    """
    flight = trajectory.plan_flight(np.asarray(scenario.waypoints), speed_mps=scenario.speed_mps,
                                    rate_hz=scenario.imu.rate_hz, duration_s=scenario.duration_s)
    # Fixes and fusion at leo.fix_rate_hz ([Shen 2024]: 1 Hz), on the IMU's two-sample grid.
    per_step = int(round(scenario.imu.rate_hz / scenario.leo.fix_rate_hz))
    if per_step < 2 or per_step % 2 or abs(per_step * scenario.leo.fix_rate_hz - scenario.imu.rate_hz) > 1e-6:
        raise InputError(f"{scenario.name}: leo.fix_rate_hz={scenario.leo.fix_rate_hz:g} must divide "
                         f"imu.rate_hz={scenario.imu.rate_hz:g} into an even number of IMU samples")
    measured = imu.MeasuredIncrements(flight.increments,
                                      imu.Corruption(errors, flight.dt_s, flight.n_samples - 1, rng_imu),
                                      IMU_BLOCK_STEPS * per_step)
    return flight.track(every=per_step), measured, flight.dt_s, per_step


def _transmitters(scenario, tle, times_utc):
    """The transmitting satellites over the run, their families, and the element sets' age [days].

    Warns when the nearest element-set epoch is more than :data:`STALE_TLE_DAYS` from the start.
    """
    constellation, family_sat = sky.transmitters(scenario.leo.constellations, tle, times_utc[[0, -1]])
    tle_age_days = float(np.abs(seconds_since(constellation.epochs_utc, scenario.start_utc)).min() / DAY_S)
    if tle_age_days > STALE_TLE_DAYS:
        warnings.warn(f"scenario start {format_utc(scenario.start_utc)} is {tle_age_days:.0f} days from the "
                      "nearest element-set epoch; satellite positions will be off by many kilometres",
                      stacklevel=3)  # the caller of run_scenario
    return constellation, family_sat, tle_age_days


def _fuse(coupling, state0, measured, dt_s, per_epoch, per_pair, settings, offset_max_sat_hz, orbit_error_m,
          orbit_error_model, progress):
    """The EKF over the LEO fixes (loose) or their Doppler (tight) -> ``leosop.fusion.common.FusionResult``.

    ``per_epoch`` and ``per_pair`` are :func:`leosop.apps.simulate.measure.leo_fixes`'s (one row per fix epoch,
    one per satellite-epoch pair); ``offset_max_sat_hz`` (n_sats,) bounds each satellite's Doppler offset.
    """
    if coupling == "tight":
        return tight.run(state0, measured, dt_s, per_pair, settings, len(per_epoch["checked"]),
                         offset_max_sat_hz=offset_max_sat_hz, orbit_sigma_m=orbit_error_m,
                         orbit_model=orbit_error_model, progress=progress)
    fix_errors = aids_fix.FixErrorModel(**per_pair, fix_clock_hz=per_epoch["fix_clock_hz"],
                                        offset_sigma_hz=offset_max_sat_hz / np.sqrt(12.0),
                                        orbit_sigma_m=orbit_error_m, orbit_model=orbit_error_model)
    fixes = (np.where(per_epoch["checked"][:, None], per_epoch["fix_pos_ecef_m"], np.nan),
             per_epoch["fix_vel_ecef_mps"], per_epoch["fix_cov"][:, :6, :6])
    return aids_fix.fuse(state0, measured.dtheta_b_rad, measured.dvel_b_mps, dt_s, fixes, settings,
                         fix_errors=fix_errors, progress=progress)


def run_scenario(scenario, *, level="signal", correction_period_s=1.0, orbit_error_m=None, orbit_error_model=None,
                 seed=0, tle=None, coupling="loose", progress=None):
    """Simulate one flight end to end.

    Parameters
    ----------
    scenario : leosop.apps.scenarios.Scenario
    level : {"signal", "measurement"}
    correction_period_s : float
        Seconds between EKF corrections of the INS (Table 5: 1, 30, 60, 100).
    orbit_error_m : float, optional
        Satellite orbit error per ECEF axis (standard deviation, constant per
        satellite); default the scenario's.
    orbit_error_model : {"independent", "common"}, optional
        Default the scenario's (``leo.orbit_error_model``).
    seed : int
    tle : path, optional
        Element-set file; default the scenario's (:func:`leosop.apps.scenarios.scenario_tle`:
        a file of the data folder from ``$LEOSOP_DATA``), else the bundled constellation.
    coupling : {"loose", "tight"}
        Loose: the EKF on the snapshot fixes; tight: on each Doppler.
    progress : callable, optional
        Wraps long loops (e.g. :func:`leosop.progress.progress`).

    Returns
    -------
    SimulationResult
    """
    tic = time.perf_counter()
    _check_options(level, coupling, correction_period_s, orbit_error_m)
    orbit_error_m = scenario.leo.orbit_error_m if orbit_error_m is None else float(orbit_error_m)
    orbit_error_model = scenario.leo.orbit_error_model if orbit_error_model is None else orbit_error_model
    if orbit_error_model not in common.ORBIT_MODELS:
        raise InputError(f"orbit error model {orbit_error_model!r}: expected one of {', '.join(common.ORBIT_MODELS)}")
    rng_imu, rng_sat, rng_meas = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    tle = tle if tle is not None else scenario_tle(scenario)
    models = sky.family_models(scenario.leo)

    # 1. Truth and IMU, made a block at a time (never the whole run at the IMU rate).
    errors = _imu_errors(scenario.imu, rng_imu)
    truth1, measured, dt_s, per_step = _fly(scenario, errors, rng_imu)
    t_s = truth1.t_s
    times_utc = scenario.start_utc + (t_s * 1e9).round().astype("timedelta64[ns]")
    constellation, family_sat, tle_age_days = _transmitters(scenario, tle, times_utc)
    pos_rx = truth1.pos_ecef_m
    C_e_n = frames.C_e_n(truth1.lat_rad, truth1.lon_rad)
    vel_rx = np.einsum("kij,kj->ki", C_e_n, truth1.vel_enu_mps)

    # 2. INS alone.
    state0 = _initial_state(truth1, scenario.init_error)
    ins = strapdown.integrate_blocks(state0, measured.blocks((t_s.size - 1) * per_step), dt_s,
                                     out_every=per_step // 2)
    ins_pos = frames.geodetic_to_ecef(ins.lat_rad, ins.lon_rad, ins.alt_m)
    ins_vel_ecef = np.einsum("kij,kj->ki", frames.C_e_n(ins.lat_rad, ins.lon_rad), ins.vel_enu_mps)

    # 3-4. Visibility, Doppler and snapshot fixes; satellite offsets and orbit errors drawn per satellite.
    offset_max_sat = scenario.leo.sat_doppler_offset_max_hz * models["clock_scale"][family_sat]
    sat_offset_hz = offset_max_sat * rng_sat.uniform(0.0, 1.0, len(constellation))
    orbit_err = orbit_error_m * rng_sat.standard_normal((len(constellation), 3))
    if orbit_error_model == "common":
        orbit_err = np.full((len(constellation), 3), orbit_error_m)
    per_epoch, per_pair = measure.leo_fixes(
        scenario, constellation, family_sat, models, times_utc, t_s, pos_rx, vel_rx, ins_pos, ins_vel_ecef,
        sat_offset_hz, offset_max_sat, orbit_err, level=level, coupling=coupling, orbit_error_m=orbit_error_m,
        orbit_error_model=orbit_error_model, rng_meas=rng_meas, progress=progress)

    # 5. EKF.
    settings = _filter_settings(scenario, errors, correction_period_s)
    fused = _fuse(coupling, state0, measured, dt_s, per_epoch, per_pair, settings, offset_max_sat, orbit_error_m,
                  orbit_error_model, progress)
    return SimulationResult(
        scenario=scenario, level=level, coupling=coupling, correction_period_s=float(correction_period_s),
        orbit_error_m=orbit_error_m, seed=int(seed), times_utc=times_utc, t_s=t_s,
        truth_pos_ecef_m=pos_rx, truth_vel_enu_mps=truth1.vel_enu_mps, truth_lat_rad=truth1.lat_rad,
        truth_lon_rad=truth1.lon_rad, ins_pos_ecef_m=ins_pos, ins_vel_enu_mps=ins.vel_enu_mps,
        fix_pos_ecef_m=per_epoch["fix_pos_ecef_m"],
        fix_vel_enu_mps=np.einsum("kji,kj->ki", C_e_n, per_epoch["fix_vel_ecef_mps"]), fix_cov=per_epoch["fix_cov"],
        fused=fused, n_visible=per_epoch["n_visible"], gdop=per_epoch["gdop"], tle_age_days=tle_age_days,
        runtime_s=time.perf_counter() - tic, n_visible_by_family=per_epoch["n_visible_by_family"])
