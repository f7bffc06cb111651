"""End-to-end simulation of [Shen 2024]'s experiment: truth flight, IMU, LEO Doppler, fixes, loose or tight EKF.

:func:`run_scenario` is the one entry point; the ``simulate`` command and the
table reproductions call it. For a scenario it

1. flies the truth trajectory and corrupts its ideal IMU increments
   ([Shen 2024] Table 1; bias signs drawn per run), both made a block at a
   time and consumed as made (the INS alone, then the EKF, read the same
   numbers), so that memory does not grow with the run's duration;
2. finds the visible satellites at the fix rate, 1 Hz (:mod:`leosop.orbits.visibility`),
   each family above its own mask (``leo.mask_deg_by_family``, else
   ``mask_deg``), and their true Doppler, plus a constant clock-induced
   offset per satellite drawn uniformly in [0, max] and the receiver's
   fixed offset;
3. measures every Doppler, either at signal level (a pilot block per
   satellite-epoch, estimated by the ``fast`` estimator) or at measurement
   level (the estimator's error model); the families of ``leo.constellations``
   without a pilot comb always at measurement level (the sigma model of
   :mod:`leosop.constellations`), each on its own carrier with its own
   receiver offset;
   in an outage (``leo.outage_s``) only the highest few are tracked;
4. solves a snapshot Doppler fix per epoch with 6 + k or more satellites
   (one receiver clock per constellation seen), with
   satellite positions carrying a constant orbit error (one per satellite,
   or one shift of all: ``leo.orbit_error_model``);
5. runs the INS alone and the EKF: loose (the fix aids of
   :mod:`leosop.fusion.aids_fix` in :mod:`leosop.fusion.engine`, each fix
   with its least-squares gain so that the filter can model the
   satellites' constant errors behind them) or tight
   (:mod:`leosop.simulate_tight`, each Doppler an aid of the engine); both
   model the orbit errors as the scenario draws them (independent or common).

Steps 3 and 4 go through the run :data:`FIX_BLOCK_EPOCHS` epochs at a
time, keeping only each epoch's fix and what the EKF needs of it.

Randomness: one ``numpy.random.SeedSequence(seed)`` spawns independent
streams for the IMU, the satellite offsets and orbit errors, and the
measurement noise, so that the IMU errors of a seed are the same at both
levels and for every correction period. The measurement noise is drawn
block by block (in a block, the pilot blocks at signal level first), which
is the same sequence as one block whenever one level measures all pairs.

The fix's weights account for every error source the receiver knows the
size of: estimator noise, the spread of the satellite offsets about their
mean (the mean is absorbed by the receiver offset of the satellite's
constellation) and the orbit error mapped
through the Doppler's sensitivity to the satellite position. The loose EKF
takes only the estimator noise as white (its ``R``) and the offsets and orbit
errors as constant states (:func:`_fix_error_model`).
"""

import dataclasses
import time
import warnings
from importlib.resources import files
from pathlib import Path

import numpy as np

from . import earth, frames, simulate_tight
from .constants import C_MPS, DAY_S
from .constellations import DEFAULT_FAMILY, clock_scale, family, tone_sigma_hz
from .errors import InputError
from .fusion import aids_fix, common, kalman
from .geometry.doppler import doppler_jacobian, doppler_rate
from .ins import imu, strapdown, trajectory
from .orbits import Constellation, load_constellation
from .orbits.propagate import drop_failing
from .orbits.visibility import compute_visibility
from .positioning.robust_ls import FixStatus
from .positioning.snapshot import solve_snapshots
from .scenarios import family_masks_deg, mask_label, scenario_tle
from .signal.doppler import estimate_block
from .signal.error_model import doppler_sigma_hz
from .signal.pilot import PilotComb, add_noise, comb_baseband
from .timebase import format_utc, seconds_since

__all__ = ["COUPLINGS", "LEVELS", "SimulationResult", "aided", "metrics", "run_scenario"]

LEVELS = ("signal", "measurement")
COUPLINGS = ("loose", "tight")
#: Initial attitude uncertainty of the filter (E, N, U) [deg]: the paper
#: gives none; the truth starts without attitude error, these are the
#: figures of a fine-aligned navigation-grade INS.
ATT_SIGMA_DEG = (0.01, 0.01, 0.05)
#: Element sets further than this from the start earn a warning.
STALE_TLE_DAYS = 14.0
#: Pilot blocks (signal level): the receiver tunes each satellite's comb to
#: the Doppler predicted from its INS and the element sets (off by at most
#: a few kHz), so 400 kHz holds the +-176 kHz comb with a +-20 kHz search;
#: 10 ms blocks (4000 samples) keep the default run well under a minute.
BLOCK_S = 0.01
SAMPLE_RATE_HZ = 400e3
SEARCH_HZ = 20e3
#: Fix epochs measured and solved at a time (the Doppler, the padded per-epoch
#: arrays and the snapshot fixes; the visibility screening goes through the
#: same length of time at a time): memory then stays flat in the run's duration.
FIX_BLOCK_EPOCHS = 600
#: Fix epochs of IMU increments made at a time (10,000 at 100 Hz and 1 Hz fixes):
#: memory then stays flat in the run's duration.
IMU_BLOCK_STEPS = 100
#: The bundled sky of the other families (OneWeb, Iridium NEXT, Orbcomm Walker
#: shells at the bundled Starlink set's epoch; tools/make_family_walker_tle.py).
FAMILIES_TLE = Path(str(files("leosop") / "data" / "leo_families_walker.tle"))


@dataclasses.dataclass(frozen=True)
class SimulationResult:
    """Everything a run produced, at the fix epochs ``t_s`` (n,), 1 Hz by default.

    Attributes
    ----------
    scenario : leosop.scenarios.Scenario
    level, coupling : str
    correction_period_s, orbit_error_m : float
    seed : int
    times_utc : ndarray of datetime64[ns], (n,)
    t_s : ndarray, (n,)
    truth_pos_ecef_m, truth_vel_enu_mps : ndarray, (n, 3)
    truth_lat_rad, truth_lon_rad : ndarray, (n,)
    ins_pos_ecef_m, ins_vel_enu_mps : ndarray, (n, 3)
        INS alone, from the same erroneous start and IMU.
    fix_pos_ecef_m, fix_vel_enu_mps : ndarray, (n, 3)
        LEO snapshot fixes; NaN where none.
    fix_cov : ndarray, (n, 7, 7)
    fused : leosop.fusion.common.FusionResult
    n_visible : ndarray of int, (n,)
    gdop : ndarray, (n,)
        Eq. 10 along the true flight (one receiver clock per constellation
        seen); NaN below 6 + k satellites of k constellations.
    tle_age_days : float
    runtime_s : float
    n_visible_by_family : ndarray of int, (n, k)
        Tracked satellites of each of the scenario's ``leo.constellations``.
    """

    scenario: object
    level: str
    coupling: str
    correction_period_s: float
    orbit_error_m: float
    seed: int
    times_utc: np.ndarray
    t_s: np.ndarray
    truth_pos_ecef_m: np.ndarray
    truth_vel_enu_mps: np.ndarray
    truth_lat_rad: np.ndarray
    truth_lon_rad: np.ndarray
    ins_pos_ecef_m: np.ndarray
    ins_vel_enu_mps: np.ndarray
    fix_pos_ecef_m: np.ndarray
    fix_vel_enu_mps: np.ndarray
    fix_cov: np.ndarray
    fused: common.FusionResult
    n_visible: np.ndarray
    gdop: np.ndarray
    tle_age_days: float
    runtime_s: float
    n_visible_by_family: np.ndarray = None

    @property
    def fused_label(self):
        """``Starlink/INS`` for a Starlink-only scenario, ``LEO/INS`` for a mix: the fused solution's name."""
        return fusion_label(self.scenario.leo.constellations)

    def errors(self):
        """3D position [m] and velocity [m/s] errors, dict of (n,) arrays per solution."""
        out = {}
        for key, pos, vel in (("ins_only", self.ins_pos_ecef_m, self.ins_vel_enu_mps),
                              ("leo_fix", self.fix_pos_ecef_m, self.fix_vel_enu_mps),
                              ("fused", self.fused.pos_ecef_m, self.fused.vel_enu_mps)):
            out[key] = (np.linalg.norm(pos - self.truth_pos_ecef_m, axis=-1),
                        np.linalg.norm(vel - self.truth_vel_enu_mps, axis=-1))
        return out

    def error_enu(self):
        """Fused errors ``[dv_enu, dpos_enu]`` (n, 6), m/s and m, in the filter's state order."""
        dpos = frames.ecef_to_enu(self.fused.pos_ecef_m - self.truth_pos_ecef_m, self.truth_lat_rad,
                                  self.truth_lon_rad)
        return np.concatenate([self.fused.vel_enu_mps - self.truth_vel_enu_mps, dpos], axis=-1)

    def nees(self):
        """NEES of the fused position and velocity (6 dof), (n,)."""
        return kalman.nees(self.error_enu(), self.fused.pos_vel_cov_enu())

    def nis(self):
        """NIS of the updates and their degrees of freedom, two (n_updates,) arrays."""
        u = self.fused.updated
        return self.fused.nis[u], self.fused.nis_dof[u]


def _check_options(level, coupling, correction_period_s, orbit_error_m):
    if level not in LEVELS:
        raise InputError(f"--level {level!r}: expected one of {', '.join(LEVELS)}")
    if coupling not in COUPLINGS:
        raise InputError(f"--coupling {coupling!r}: expected one of {', '.join(COUPLINGS)}")
    if not (np.isfinite(correction_period_s) and correction_period_s > 0):
        raise InputError(f"--correction-period-s {correction_period_s:g}: must be a positive number of seconds")
    if orbit_error_m is not None and not (np.isfinite(orbit_error_m) and orbit_error_m >= 0):
        raise InputError(f"--orbit-error-m {orbit_error_m:g}: must be a number >= 0")


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


def _signal_level(comb, doppler_geom_hz, rate_hz_per_s, clock_hz, predicted_hz, cn0_dbhz, rng, progress):
    """Generate a block of the pilot ``comb`` per pair and estimate its Doppler with ``fast``.

    Each block is centred on its epoch and mixed down by the predicted
    Doppler, as an aided receiver's oscillator would do; the estimate is
    the predicted Doppler plus the estimated residual.

    Returns
    -------
    doppler_hz, sigma_hz : ndarray, (m,)
        NaN where the comb was not detected.
    """
    n = int(round(BLOCK_S * SAMPLE_RATE_HZ))
    tau = (np.arange(n) - 0.5 * (n - 1)) / SAMPLE_RATE_HZ
    est = np.full(doppler_geom_hz.shape, np.nan)
    sigma = np.full(doppler_geom_hz.shape, np.nan)
    pairs = range(doppler_geom_hz.size)
    for i in (progress(pairs, desc="pilot blocks", unit="block") if progress else pairs):
        geom = (doppler_geom_hz[i] - predicted_hz[i]) * tau + 0.5 * rate_hz_per_s[i] * tau**2
        iq = add_noise(comb_baseband(comb, tau, geom, clock_hz[i] * tau), cn0_dbhz, SAMPLE_RATE_HZ, rng)
        out = estimate_block(iq, SAMPLE_RATE_HZ, method="fast", comb=comb, max_doppler_hz=SEARCH_HZ)
        if out["detected"]:
            est[i] = predicted_hz[i] + out["doppler_hz"]
            sigma[i] = out["sigma_hz"]
    return est, sigma


def _fix_error_model(vis, fixes, good, sigma_hz, sigma_est_hz, pos_sv_known, carrier_hz, family, offset_max_sat_hz,
                     orbit_error_m, orbit_error_model):
    """What each fix is made of: gains, Jacobian rows, residuals and receiver offsets.

    The fix is the weighted least squares ``x = x_true + G e`` (to first order)
    with ``G = cov H^T W`` at the solution, over the Doppler it used (``H``
    with one receiver-clock column per family); ``e_j`` holds the satellite's
    offset, its orbit error ``dr_j`` seen through ``h_j = dD/dr_rx`` (the
    Doppler depends on ``r_s - r_rx``, so a satellite believed ``dr`` away
    acts as a receiver moved by ``-dr``) and the estimator noise, the only
    white part.

    Parameters
    ----------
    sigma_hz : ndarray, (m,)
        The sigma each Doppler was weighted by in the fix.
    sigma_est_hz : float or ndarray, (m,)
        The estimator's white noise.
    carrier_hz : ndarray, (m,)
    family : ndarray of int, (m,)
        Clock group of each pair (the ``clock_group`` of the fixes).
    offset_max_sat_hz : ndarray, (n_sats,)
        Each satellite's offset bound (offsets uniform in [0, max]).

    Returns
    -------
    leosop.fusion.aids_fix.FixErrorModel
        Rows of the pairs used in the fixes ``good``.
    """
    H = doppler_jacobian(vis.padded(pos_sv_known), vis.padded(vis.vel_sv_ecef_mps), fixes.pos_ecef_m,
                         fixes.vel_ecef_mps, vis.padded(carrier_hz))
    # The fix's clock columns follow the groups present in the sky, sorted (fixes.clock_labels).
    labels = np.asarray(fixes.clock_labels if fixes.clock_labels else [0])
    clock = np.searchsorted(labels, family) if fixes.clock_labels else np.zeros(family.shape, int)
    onehot = np.nan_to_num(vis.padded(clock.astype(float)), nan=-1.0)[..., None] == np.arange(labels.size)
    H = np.concatenate([H[..., :6], onehot], -1)
    used = fixes.used & good[:, None]
    w = np.where(used, 1.0 / np.nan_to_num(vis.padded(sigma_hz), nan=1.0) ** 2, 0.0)
    G = np.nan_to_num(fixes.cov) @ np.swapaxes(np.nan_to_num(H) * w[..., None], 1, 2)  # (n_ep, 6 + k, n_sv)
    slot = np.arange(len(vis.epoch_index)) - np.searchsorted(vis.epoch_index, vis.epoch_index)
    ep = vis.epoch_index
    pair_used = used[ep, slot]
    sel = (ep[pair_used], slot[pair_used])
    return aids_fix.FixErrorModel(
        epoch_index=sel[0], sat_index=vis.sat_index[pair_used], gain_ecef=np.swapaxes(G, 1, 2)[sel],
        jacobian_pv=H[..., :6][sel], clock_index=clock[pair_used], weight_sqrt=1.0 / sigma_hz[pair_used],
        residual_hz=fixes.residuals_hz[sel],
        sigma_white_hz=np.broadcast_to(sigma_est_hz, sigma_hz.shape)[pair_used],
        fix_clock_hz=np.where(good[:, None], fixes.clock_offsets_hz, np.nan),
        offset_sigma_hz=offset_max_sat_hz / np.sqrt(12.0), orbit_sigma_m=orbit_error_m,
        orbit_model=orbit_error_model)


def _constellation(families, tle, span_utc):
    """The transmitting satellites of ``families`` and each one's family index, (n_sats,) int.

    Without ``tle``: the bundled Starlink-like set, plus the bundled sky of
    the other families (:data:`FAMILIES_TLE`) when they are asked for. A file
    without names (2-line TLEs) is taken whole as Starlink when only Starlink
    is asked for. Satellites SGP4 cannot propagate over ``span_utc`` (first
    and last epoch; decayed) are left out with a warning
    (:func:`leosop.orbits.propagate.drop_failing`).

    Raises
    ------
    InputError
        Naming a requested family of which the file holds no satellite.
    """
    if tle is None:
        needs_families = bool(set(families) - {DEFAULT_FAMILY})
        parts = [load_constellation()] + ([load_constellation(FAMILIES_TLE)] if needs_families else [])
        every = Constellation(sum((c.names for c in parts), ()), np.concatenate([c.sat_ids for c in parts]),
                              sum((c.satrecs for c in parts), ()), np.concatenate([c.epochs_utc for c in parts]),
                              "bundled sky")
    else:
        every = load_constellation(tle)
    if tuple(families) == (DEFAULT_FAMILY,) and not (every.families != "").any():
        every = drop_failing(every, span_utc, what="the flight")
        return every, np.zeros(len(every), int)
    every = drop_failing(every.subset(np.isin(every.families, families)), span_utc, what="the flight")
    index = [np.flatnonzero(every.families == f) for f in families]
    for f, idx in zip(families, index):
        if idx.size == 0:
            raise InputError(f"{every.source or tle}: no satellite of constellation {f!r} (leo.constellations)")
    return every.subset(np.concatenate(index)), np.repeat(np.arange(len(families)), [i.size for i in index])


def _family_models(leo):
    """Per family of ``leo.constellations``: carrier, clock scale, receiver offset, sigma and signal models.

    Returns
    -------
    dict
        ``carrier_hz``, ``clock_scale``, ``rx_offset_hz``, ``sigma_hz`` (the
        single-tone sigma model): ndarray (k,); ``comb``: tuple (k,) of each
        family's :class:`~leosop.signal.pilot.PilotComb`, None for a family
        without one. A comb family's C/N0 is the scenario's ``leo.cn0_dbhz``.
    """
    fams = [family(f) for f in leo.constellations]
    cn0 = [leo.cn0_dbhz if f.comb is not None else leo.cn0_dbhz_by_family.get(f.key, f.cn0_dbhz) for f in fams]
    scale = np.array([clock_scale(f.key) for f in fams])
    return {
        "carrier_hz": np.array([f.carrier_hz for f in fams]),
        "clock_scale": scale,
        "rx_offset_hz": np.array([leo.rx_freq_offsets_hz.get(f.key, leo.rx_freq_offset_hz * r)
                                  for f, r in zip(fams, scale)]),
        "sigma_hz": tone_sigma_hz(cn0, [f.integration_s for f in fams]),
        "comb": tuple(None if f.comb is None else PilotComb.of(f.key) for f in fams),
    }


def _keep_pairs(vis, keep):
    """The pairs of ``vis`` where ``keep`` (m,) is true."""
    return dataclasses.replace(vis, **{f: getattr(vis, f)[keep] for f in (
        "epoch_index", "sat_index", "az_rad", "elev_rad", "range_m", "pos_sv_ecef_m", "vel_sv_ecef_mps")})


def _above_family_masks(vis, family_sat, masks_deg):
    """The pairs above their family's mask, from pairs found above the lowest mask.

    Parameters
    ----------
    vis : Visibility
        Found with the mask ``masks_deg.min()``.
    family_sat : ndarray of int, (n_sats,)
    masks_deg : ndarray, (k,)
        Each family's mask. The pairs of the families at the lowest mask are
        kept as found (one mask: ``vis`` itself).
    """
    mask_pair_deg = masks_deg[family_sat[vis.sat_index]]
    keep = (mask_pair_deg == masks_deg.min()) | (vis.elev_rad >= np.radians(mask_pair_deg))
    return vis if keep.all() else _keep_pairs(vis, keep)


def _tracked(vis, t_s, outage_s, max_sats):
    """The visible pairs the receiver tracks: all, except in the outage ``[start, end]`` the ``max_sats`` highest."""
    if outage_s is None:
        return vis
    order = np.lexsort((-vis.elev_rad, vis.epoch_index))
    rank = np.empty(order.size, int)
    rank[order] = np.arange(order.size) - np.searchsorted(vis.epoch_index[order], vis.epoch_index[order])
    t = t_s[vis.epoch_index]
    keep = (t < outage_s[0]) | (t > outage_s[1]) | (rank < max_sats)
    return _keep_pairs(vis, keep)


def _leo_fixes(scenario, constellation, family_sat, models, times_utc, t_s, pos_rx_ecef_m, vel_rx_ecef_mps,
               ins_pos_ecef_m, ins_vel_ecef_mps, sat_offset_hz, offset_max_sat_hz, orbit_err_ecef_m, *, level, coupling,
               orbit_error_m, orbit_error_model, rng_meas, progress):
    """Steps 2-4 of the module docstring: the tracked satellites, their Doppler and the snapshot fixes.

    The visible pairs are found for the whole run; the Doppler, the padded
    per-epoch arrays and the fixes are made :data:`FIX_BLOCK_EPOCHS` epochs
    at a time, and only what the EKF and the result need is kept, so that
    the working memory is that of a block.

    Parameters
    ----------
    family_sat : ndarray of int, (n_sats,)
    times_utc : ndarray of datetime64[ns], (n,)
    t_s : ndarray, (n,)
        Seconds since the start.
    pos_rx_ecef_m, vel_rx_ecef_mps : ndarray, (n, 3)
        Truth.
    ins_pos_ecef_m, ins_vel_ecef_mps : ndarray, (n, 3)
        The INS alone (the fixes' start, the signal level's prediction).
    sat_offset_hz, offset_max_sat_hz : ndarray, (n_sats,)
        Each satellite's clock-induced offset and its bound.
    orbit_err_ecef_m : ndarray, (n_sats, 3)
        Each satellite's orbit error.

    Returns
    -------
    per_epoch : dict of ndarray, (n, ...)
        See :func:`_measure_and_solve`, plus ``n_visible`` (n,) and
        ``n_visible_by_family`` (n, k).
    per_pair : dict of ndarray, (m, ...)
        See :func:`_measure_and_solve`, with run-wide epoch indices.
    """
    masks_deg = family_masks_deg(scenario)
    vis = compute_visibility(constellation, times_utc, pos_rx_ecef_m, masks_deg.min(),
                             vel_rx_ecef_mps=vel_rx_ecef_mps, block_s=FIX_BLOCK_EPOCHS / scenario.leo.fix_rate_hz,
                             show_progress=progress is not None)
    vis = _above_family_masks(vis, family_sat, masks_deg)
    vis = _tracked(vis, t_s, scenario.leo.outage_s, scenario.leo.outage_max_sats)
    if not vis.n_visible.any():
        warnings.warn(f"{scenario.name}: no satellite rises above the {mask_label(scenario)} mask during the "
                      "flight; the result is the INS alone", stacklevel=3)
    # One receiver clock per family tracked in the run, the same in every block.
    clock_labels = None if len(scenario.leo.constellations) == 1 else np.unique(family_sat[vis.sat_index])
    blocks = [_measure_and_solve(
        vis.epochs(e0, e0 + FIX_BLOCK_EPOCHS), e0, ins_pos_ecef_m[e0:e0 + FIX_BLOCK_EPOCHS],
        ins_vel_ecef_mps[e0:e0 + FIX_BLOCK_EPOCHS], family_sat, models, sat_offset_hz, offset_max_sat_hz,
        orbit_err_ecef_m, level=level, coupling=coupling, cn0_dbhz=scenario.leo.cn0_dbhz,
        orbit_error_m=orbit_error_m, orbit_error_model=orbit_error_model, clock_labels=clock_labels,
        rng_meas=rng_meas, progress=progress) for e0 in range(0, len(times_utc), FIX_BLOCK_EPOCHS)]
    per_epoch, per_pair = ({k: np.concatenate([b[i][k] for b in blocks]) for k in blocks[0][i]} for i in (0, 1))
    per_epoch.update(n_visible=vis.n_visible, n_visible_by_family=vis.n_visible_by_group(family_sat))
    return per_epoch, per_pair


def _measure_and_solve(vis, epoch0, ins_pos_ecef_m, ins_vel_ecef_mps, family_sat, models, sat_offset_hz,
                       offset_max_sat_hz, orbit_err_ecef_m, *, level, coupling, cn0_dbhz, orbit_error_m,
                       orbit_error_model, clock_labels, rng_meas, progress):
    """The Doppler and snapshot fixes of a block of ``n_b`` epochs, from epoch ``epoch0`` of the run.

    Parameters
    ----------
    vis : leosop.orbits.visibility.Visibility
        The tracked pairs of the block, along the true flight.
    ins_pos_ecef_m, ins_vel_ecef_mps : ndarray, (n_b, 3)
    clock_labels : ndarray of int, (k,), or None
        The families of the run, one receiver clock each; None for one family.

    Other parameters as :func:`_leo_fixes`.

    Returns
    -------
    per_epoch : dict of ndarray, (n_b, ...)
        ``fix_pos_ecef_m``, ``fix_vel_ecef_mps`` (n_b, 3) and ``fix_cov``
        (n_b, 6 + k, 6 + k): NaN without a fix; ``checked`` (n_b,): the fixes
        the loose filter may take; ``gdop`` (n_b,): eq. 10 along the true
        flight; loose coupling: ``fix_clock_hz`` (n_b, k), the fixes'
        receiver offsets.
    per_pair : dict of ndarray, (m_b, ...)
        Loose coupling: the :class:`leosop.fusion.aids_fix.FixErrorModel` rows
        (:data:`leosop.fusion.aids_fix.PAIR_FIELDS`); tight: the
        :data:`leosop.simulate_tight.PAIR_FIELDS`.
    """
    pos_rx, vel_rx = vis.pos_rx_ecef_m, vis.vel_rx_ecef_mps
    n_ep = len(vis.times_utc)
    ep, sat = vis.epoch_index, vis.sat_index
    fam = family_sat[sat]
    carrier_sat = models["carrier_hz"][family_sat]
    carrier = carrier_sat[sat]
    range_rate = frames.range_rate(vis.pos_sv_ecef_m, vis.vel_sv_ecef_mps, pos_rx[ep], vel_rx[ep])
    doppler_geom = -range_rate * carrier / C_MPS
    clock_hz = sat_offset_hz[sat] + models["rx_offset_hz"][fam]
    pos_sv_known = vis.pos_sv_ecef_m + orbit_err_ecef_m[sat]
    H_known = doppler_jacobian(pos_sv_known[:, None], vis.vel_sv_ecef_mps[:, None], ins_pos_ecef_m[ep],
                               ins_vel_ecef_mps[ep], carrier[:, None])[:, 0]
    # Measurement-level sigma of each family; a comb family's is the comb's (fast estimator).
    sigma_est = models["sigma_hz"][fam]
    doppler_meas = np.full(doppler_geom.shape, np.nan)
    signal = np.zeros(fam.shape, bool)
    for k, pilot in enumerate(models["comb"]):
        if pilot is None:
            continue
        comb = fam == k
        sigma_est[comb] = doppler_sigma_hz(cn0_dbhz, BLOCK_S, comb=pilot, sample_rate_hz=SAMPLE_RATE_HZ)
        if level != "signal" or not comb.any():
            continue
        # At signal level: prediction from the INS alone and the known
        # orbits (range-rate part of the Jacobian).
        predicted = np.einsum("mi,mi->m", H_known[comb, 3:6], ins_vel_ecef_mps[ep[comb]] - vis.vel_sv_ecef_mps[comb])
        # Only the shape of the generated chirp depends on the rate (the aircraft's acceleration neglected).
        rate = doppler_rate(vis.pos_sv_ecef_m[comb, None], vis.vel_sv_ecef_mps[comb, None], pos_rx[ep[comb]],
                            carrier[comb, None], vel_rx[ep[comb], None])[0][:, 0]
        doppler_meas[comb], sigma_est[comb] = _signal_level(pilot, doppler_geom[comb], rate, clock_hz[comb],
                                                            predicted, cn0_dbhz, rng_meas, progress)
        signal |= comb
    modelled = ~signal
    doppler_meas[modelled] = (doppler_geom[modelled] + clock_hz[modelled]
                              + sigma_est[modelled] * rng_meas.standard_normal(int(modelled.sum())))

    # Snapshot fixes from what the receiver knows: orbits with their errors; 6 + k states for k families.
    offset_max = offset_max_sat_hz[sat]
    sigma_hz = np.sqrt(sigma_est**2 + offset_max**2 / 12.0
                       + (np.linalg.norm(H_known[:, :3], axis=-1) * orbit_error_m) ** 2)
    x0 = np.concatenate([ins_pos_ecef_m, ins_vel_ecef_mps, np.zeros((n_ep, 1))], axis=-1)
    clock_group = None if clock_labels is None else np.nan_to_num(vis.padded(fam.astype(float))).astype(int)
    fixes = solve_snapshots(vis.padded(doppler_meas), vis.padded(sigma_hz), vis.padded(pos_sv_known),
                            vis.padded(vis.vel_sv_ecef_mps), vis.padded(carrier), x0=x0, clock_group=clock_group,
                            clock_labels=clock_labels)
    good = fixes.status == FixStatus.OK
    # The loose filter takes only redundant or well-conditioned fixes (aids_fix.checkable_fixes); all are reported.
    checked = good & aids_fix.checkable_fixes(fixes.n_used, fixes.cov, fixes.gdop)
    per_epoch = {"fix_pos_ecef_m": np.where(good[:, None], fixes.pos_ecef_m, np.nan),
                 "fix_vel_ecef_mps": np.where(good[:, None], fixes.vel_ecef_mps, np.nan),
                 "fix_cov": np.where(good[:, None, None], fixes.cov, np.nan), "checked": checked,
                 "gdop": vis.doppler_gdop(carrier_sat, None if clock_labels is None else family_sat)}
    if coupling == "tight":
        per_pair = {"epoch_index": ep + epoch0, "sat_index": sat, "doppler_hz": doppler_meas, "sigma_hz": sigma_est,
                    "pos_sv_ecef_m": pos_sv_known, "vel_sv_ecef_mps": vis.vel_sv_ecef_mps, "carrier_hz": carrier,
                    "clock_index": fam}
        return per_epoch, per_pair
    fix_errors = _fix_error_model(vis, fixes, checked, sigma_hz, sigma_est, pos_sv_known, carrier, fam,
                                  offset_max_sat_hz, orbit_error_m, orbit_error_model)
    per_epoch["fix_clock_hz"] = fix_errors.fix_clock_hz
    per_pair = {f: getattr(fix_errors, f) for f in aids_fix.PAIR_FIELDS}
    per_pair["epoch_index"] = per_pair["epoch_index"] + epoch0
    return per_epoch, per_pair


def run_scenario(scenario, *, level="signal", correction_period_s=1.0, orbit_error_m=None, orbit_error_model=None,
                 seed=0, tle=None, coupling="loose", progress=None):
    """Simulate one flight end to end.

    Parameters
    ----------
    scenario : leosop.scenarios.Scenario
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
        Element-set file; default the scenario's (:func:`leosop.scenarios.scenario_tle`:
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
    models = _family_models(scenario.leo)

    # 1. Truth and IMU, made a block at a time (never the whole run at the IMU rate).
    flight = trajectory.plan_flight(np.asarray(scenario.waypoints), speed_mps=scenario.speed_mps,
                                    rate_hz=scenario.imu.rate_hz, duration_s=scenario.duration_s)
    errors = _imu_errors(scenario.imu, rng_imu)
    dt_s = flight.dt_s
    # Fixes and fusion at leo.fix_rate_hz ([Shen 2024]: 1 Hz), on the IMU's two-sample grid.
    per_step = int(round(scenario.imu.rate_hz / scenario.leo.fix_rate_hz))
    if per_step < 2 or per_step % 2 or abs(per_step * scenario.leo.fix_rate_hz - scenario.imu.rate_hz) > 1e-6:
        raise InputError(f"{scenario.name}: leo.fix_rate_hz={scenario.leo.fix_rate_hz:g} must divide "
                         f"imu.rate_hz={scenario.imu.rate_hz:g} into an even number of IMU samples")
    measured = imu.MeasuredIncrements(flight.increments, imu.Corruption(errors, dt_s, flight.n_samples - 1, rng_imu),
                                      IMU_BLOCK_STEPS * per_step)
    truth1 = flight.track(every=per_step)
    n_ep = truth1.t_s.size
    t_s = truth1.t_s
    times_utc = scenario.start_utc + (t_s * 1e9).round().astype("timedelta64[ns]")
    constellation, family_sat = _constellation(scenario.leo.constellations, tle, times_utc[[0, -1]])
    tle_age_days = float(np.abs(seconds_since(constellation.epochs_utc, scenario.start_utc)).min() / DAY_S)
    if tle_age_days > STALE_TLE_DAYS:
        warnings.warn(f"scenario start {format_utc(scenario.start_utc)} is {tle_age_days:.0f} days from the "
                      "nearest element-set epoch; satellite positions will be off by many kilometres",
                      stacklevel=2)
    pos_rx = truth1.pos_ecef_m
    C_e_n = frames.C_e_n(truth1.lat_rad, truth1.lon_rad)
    vel_rx = np.einsum("kij,kj->ki", C_e_n, truth1.vel_enu_mps)

    # 2. INS alone.
    state0 = _initial_state(truth1, scenario.init_error)
    ins = strapdown.integrate_blocks(state0, measured.blocks((n_ep - 1) * per_step), dt_s, out_every=per_step // 2)
    ins_pos = frames.geodetic_to_ecef(ins.lat_rad, ins.lon_rad, ins.alt_m)
    ins_vel_ecef = np.einsum("kij,kj->ki", frames.C_e_n(ins.lat_rad, ins.lon_rad), ins.vel_enu_mps)

    # 3-4. Visibility, Doppler and snapshot fixes; satellite offsets and orbit errors drawn per satellite.
    offset_max_sat = scenario.leo.sat_doppler_offset_max_hz * models["clock_scale"][family_sat]
    sat_offset_hz = offset_max_sat * rng_sat.uniform(0.0, 1.0, len(constellation))
    orbit_err = orbit_error_m * rng_sat.standard_normal((len(constellation), 3))
    if orbit_error_model == "common":
        orbit_err = np.full((len(constellation), 3), orbit_error_m)
    per_epoch, per_pair = _leo_fixes(
        scenario, constellation, family_sat, models, times_utc, t_s, pos_rx, vel_rx, ins_pos, ins_vel_ecef,
        sat_offset_hz, offset_max_sat, orbit_err, level=level, coupling=coupling, orbit_error_m=orbit_error_m,
        orbit_error_model=orbit_error_model, rng_meas=rng_meas, progress=progress)
    fix_pos, fix_vel, checked = per_epoch["fix_pos_ecef_m"], per_epoch["fix_vel_ecef_mps"], per_epoch["checked"]

    # 5. EKF.
    settings = _filter_settings(scenario, errors, correction_period_s)
    if coupling == "loose":
        fix_errors = aids_fix.FixErrorModel(**per_pair, fix_clock_hz=per_epoch["fix_clock_hz"],
                                            offset_sigma_hz=offset_max_sat / np.sqrt(12.0),
                                            orbit_sigma_m=orbit_error_m, orbit_model=orbit_error_model)
        fused = aids_fix.fuse(state0, measured.dtheta_b_rad, measured.dvel_b_mps, dt_s,
                              (np.where(checked[:, None], fix_pos, np.nan), fix_vel, per_epoch["fix_cov"][:, :6, :6]),
                              settings, fix_errors=fix_errors, progress=progress)
    else:
        fused = simulate_tight.run(state0, measured, dt_s, per_pair, settings, n_ep, offset_max_sat_hz=offset_max_sat,
                                   orbit_sigma_m=orbit_error_m, orbit_model=orbit_error_model, progress=progress)
    fix_vel_enu = np.einsum("kji,kj->ki", C_e_n, fix_vel)
    return SimulationResult(
        scenario=scenario, level=level, coupling=coupling, correction_period_s=float(correction_period_s),
        orbit_error_m=orbit_error_m, seed=int(seed), times_utc=times_utc, t_s=t_s,
        truth_pos_ecef_m=pos_rx, truth_vel_enu_mps=truth1.vel_enu_mps, truth_lat_rad=truth1.lat_rad,
        truth_lon_rad=truth1.lon_rad, ins_pos_ecef_m=ins_pos, ins_vel_enu_mps=ins.vel_enu_mps,
        fix_pos_ecef_m=fix_pos, fix_vel_enu_mps=fix_vel_enu, fix_cov=per_epoch["fix_cov"], fused=fused,
        n_visible=per_epoch["n_visible"], gdop=per_epoch["gdop"], tle_age_days=tle_age_days,
        runtime_s=time.perf_counter() - tic, n_visible_by_family=per_epoch["n_visible_by_family"])


def aided(result):
    """Which output epochs the LEO measurements aided, (n,) bool.

    An epoch is aided when the filter's last update (a fix taken, loose; at
    least one Doppler taken, tight) is less than a correction period old
    (at least one output step): with corrections every 30 s the 29 epochs
    after an update are aided too. The start is never aided.
    """
    t = result.t_s
    step_s = float(t[1] - t[0]) if t.size > 1 else 1.0
    last_s = np.maximum.accumulate(np.where(result.fused.updated, t, -np.inf))
    return t - last_s < max(result.correction_period_s, step_s) - 1e-9


def metrics(result):
    """The ``simulate`` JSON document (DESIGN.md 4.1), every key present.

    Means are over the output epochs (1 Hz by default) after the start;
    ``availability`` is the fraction of those epochs with a fused output
    (the INS alone counts: the filter always has one). Beyond the contract,
    ``fused`` also says how much of it rests on LEO: ``aided_fraction``, the
    fraction of those epochs the LEO measurements aided (:func:`aided`), and
    ``n_updates``, the filter's updates (loose: the fixes it took; tight:
    the epochs whose Doppler it took).
    """
    err = result.errors()
    out = slice(1, None)

    def mean(a):
        a = a[out]
        a = a[np.isfinite(a)]
        return float(a.mean()) if a.size else None

    fused_pos = err["fused"][0][out]
    fix_ok = np.isfinite(err["leo_fix"][0][out])
    gdop = result.gdop[np.isfinite(result.gdop)]
    return {
        "scenario": result.scenario.name,
        "duration_s": float(result.t_s[-1]),
        "ins_only": {"pos_err_mean_m": mean(err["ins_only"][0]), "vel_err_mean_mps": mean(err["ins_only"][1])},
        "leo_fix": {"pos_err_mean_m": mean(err["leo_fix"][0]), "vel_err_mean_mps": mean(err["leo_fix"][1]),
                    "n_fixes": int(fix_ok.sum())},
        "fused": {"pos_err_mean_m": mean(err["fused"][0]), "vel_err_mean_mps": mean(err["fused"][1]),
                  "pos_err_rms_m": float(np.sqrt(np.nanmean(fused_pos**2))) if np.isfinite(fused_pos).any() else None,
                  "availability": float(np.isfinite(fused_pos).mean()),
                  "aided_fraction": float(aided(result)[out].mean()), "n_updates": int(result.fused.updated.sum())},
        "visible": {"min": int(result.n_visible.min()), "max": int(result.n_visible.max())},
        "gdop": {"max": float(gdop.max()) if gdop.size else None},
        "runtime_s": float(result.runtime_s),
    }


def fusion_label(constellations):
    """The fused solution's name from the scenario's constellations: ``Starlink/INS`` or ``LEO/INS``."""
    return "Starlink/INS" if tuple(constellations) == ("starlink",) else "LEO/INS"


def solution_table(result):
    """The solution CSV: header and rows, one per output epoch.

    Columns: time; truth, INS-only, LEO fix and fused position (deg, deg, m)
    and ENU velocity (m/s); the fused 1-sigma position (ENU m) and velocity
    (m/s); visible satellites, GDOP and whether the filter updated.
    """
    header = ["t_s", "time_utc"]
    cols = [result.t_s, format_utc(result.times_utc)]
    for name, pos, vel in (("truth", result.truth_pos_ecef_m, result.truth_vel_enu_mps),
                           ("ins", result.ins_pos_ecef_m, result.ins_vel_enu_mps),
                           ("fix", result.fix_pos_ecef_m, result.fix_vel_enu_mps),
                           ("fused", result.fused.pos_ecef_m, result.fused.vel_enu_mps)):
        lat, lon, alt = frames.ecef_to_geodetic(pos)
        header += [f"{name}_lat_deg", f"{name}_lon_deg", f"{name}_alt_m",
                   f"{name}_ve_mps", f"{name}_vn_mps", f"{name}_vu_mps"]
        cols += [np.degrees(lat), np.degrees(lon), alt, vel[:, 0], vel[:, 1], vel[:, 2]]
    sigma = np.sqrt(np.diagonal(result.fused.pos_vel_cov_enu(), axis1=-2, axis2=-1))
    header += ["sigma_e_m", "sigma_n_m", "sigma_u_m", "sigma_ve_mps", "sigma_vn_mps", "sigma_vu_mps",
               "n_visible", "gdop", "updated"]
    cols += [sigma[:, 3], sigma[:, 4], sigma[:, 5], sigma[:, 0], sigma[:, 1], sigma[:, 2], result.n_visible,
             result.gdop, result.fused.updated.astype(int)]

    def cell(v):
        if isinstance(v, str):
            return v
        v = float(v)
        return "" if not np.isfinite(v) else f"{v:.10g}"

    rows = [[cell(c[k]) for c in cols] for k in range(result.t_s.size)]
    return header, rows
