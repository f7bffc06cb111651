"""``simulate``'s tight coupling: the engine (:mod:`leosop.fusion.engine`) fed with each Doppler as an aid.

Every Doppler of an epoch after the start is one
:class:`leosop.fusion.aids_leo.LeoDoppler` aid at that epoch, with the
states the scenario's errors call for: one receiver frequency offset per
constellation (a random walk, no drift: simulate's receiver offsets are
constant), each satellite's constant clock-induced offset with the prior of
its draw (uniform in [0, max]: mean max/2, sigma max/sqrt(12)) and the
constant orbit errors, three per satellite (``"independent"``) or three
shared by all (``"common"``, [Shen 2024] Table 6's [E, E, E]). The engine
propagates the covariance once per filter step, corrects the INS with all
Doppler of an epoch at most once per correction period, in one update,
gates each Doppler on its own innovation given the epoch's Doppler before it
(chi-square, one degree of freedom, never re-opened) and records the INS at
the filter's epochs, which :func:`run` maps to the
:class:`leosop.fusion.common.FusionResult` the loose filter gives too.

Tight coupling beats a snapshot fix where satellites are few: one Doppler of
one constellation is enough for an update, where a fix needs 6 + k.
"""

import numpy as np

from ...fusion import common, engine
from ...fusion.aids_leo import LeoOptions, leo_aids
from ...rotations import quat_to_dcm

__all__ = ["PAIR_FIELDS", "run"]

#: The per-Doppler arrays :func:`run` takes, each (m,) or (m, 3), sorted by epoch.
PAIR_FIELDS = ("epoch_index", "sat_index", "doppler_hz", "sigma_hz", "pos_sv_ecef_m", "vel_sv_ecef_mps",
               "carrier_hz", "clock_index")
#: No re-opening of the gate: a Doppler is rejected on its own innovation, however many were before it.
_NEVER_REOPEN = np.iinfo(np.int64).max


def run(state0, measured, dt_s, pairs, settings, n_epochs, *, offset_max_sat_hz, orbit_sigma_m, orbit_model,
        progress=None):
    """Run the INS with each Doppler as an engine aid over a whole flight.

    Parameters
    ----------
    state0 : leosop.ins.strapdown.NavState
    measured : leosop.ins.imu.MeasuredIncrements
        Its ``dtheta_b_rad`` and ``dvel_b_mps`` at interval ``dt_s``.
    dt_s : float
    pairs : dict of ndarray
        :data:`PAIR_FIELDS`: epoch and satellite index of each Doppler, its
        value and sigma [Hz] (NaN or non-positive: not used), the satellite
        state as the receiver knows it (with orbit errors; ECEF m, m/s, (m, 3)),
        the carrier [Hz] and the receiver clock (constellation) index.
    settings : leosop.fusion.common.FilterSettings
        INS priors and noise; ``step_s`` is the epoch interval.
    n_epochs : int
        Epochs of the flight, the start included (epoch k at ``k * step_s``).
    offset_max_sat_hz : ndarray, (n_sats,)
        Largest clock-induced offset of each satellite.
    orbit_sigma_m : float
        Orbit error per ECEF axis.
    orbit_model : {"independent", "common"}
    progress : callable, optional

    Returns
    -------
    leosop.fusion.common.FusionResult
        At the epochs; ``doppler_innovation`` holds each used Doppler's
        normalised innovation (measured minus predicted); ``nis`` and
        ``nis_dof`` sum the Doppler of each update.
    """
    per_step = round(settings.step_s / dt_s)
    n_imu = (n_epochs - 1) * per_step
    t_imu = (np.arange(n_imu) + 1) * dt_s
    ep, sat = pairs["epoch_index"], pairs["sat_index"]
    use = np.flatnonzero((ep > 0) & (ep < n_epochs) & np.isfinite(pairs["doppler_hz"]) & (pairs["sigma_hz"] > 0))
    options = LeoOptions(rx_offset_sigma_hz=common.RX_OFFSET_SIGMA_HZ, rx_drift_sigma_hz_per_s=None,
                         rx_offset_psd_hz2_per_s=common.RX_OFFSET_PSD_HZ2_PER_S, sat_offset_psd_hz2_per_s=0.0,
                         orbit_sigma_m=max(orbit_sigma_m, 1e-3), orbit_model=orbit_model)
    # An aid at epoch k is due at the end of the IMU interval that ends the epoch (the same float).
    aids = leo_aids(t_imu[ep[use] * per_step - 1], sat[use], pairs["clock_index"][use], pairs["doppler_hz"][use],
                    pairs["sigma_hz"][use], pairs["carrier_hz"][use], pairs["pos_sv_ecef_m"][use],
                    pairs["vel_sv_ecef_mps"][use], np.zeros(3), options,
                    sat_offset_mean_hz=offset_max_sat_hz[sat[use]] / 2,
                    sat_offset_sigma_hz=offset_max_sat_hz[sat[use]] / np.sqrt(12.0))
    engine_settings = engine.EngineSettings(
        gyro_arw_rad_per_rt_s=settings.gyro_arw_rad_per_rt_s, accel_vrw_mps_per_rt_s=settings.accel_vrw_mps2_per_rt_hz,
        gyro_bias_rw_rad_per_s_per_rt_s=0.0, accel_bias_rw_mps2_per_rt_s=0.0, step_s=settings.step_s,
        reopen_after=_NEVER_REOPEN, correction_period_s=settings.correction_period_s, record_every=per_step // 2,
        record_cov_ins=True)
    P0 = common.initial_covariance(settings, state0.lat_rad, state0.alt_m)
    log = _DopplerLog(len(aids))
    res = engine.run(state0, P0, t_imu, np.full(n_imu, dt_s), measured.dtheta_b_rad, measured.dvel_b_mps, aids,
                     engine_settings, progress=progress, on_aid=log)
    return log.result(res, ep[use], sat[use], n_epochs, settings.step_s)


class _DopplerLog:
    """The engine's gate test of each Doppler aid (its ``on_aid``): offered, used, NIS and normalised innovation."""

    def __init__(self, n_aids):
        self.offered = np.zeros(n_aids, dtype=bool)
        self.used = np.zeros(n_aids, dtype=bool)
        self.nis = np.full(n_aids, np.nan)
        self.normalized = np.full(n_aids, np.nan)

    def __call__(self, index, aid, z, S, used, reopened):
        self.offered[index], self.used[index] = True, used
        # The engine's innovation is predicted minus measured.
        self.nis[index], self.normalized[index] = z[0] ** 2 / S[0, 0], -z[0] / np.sqrt(S[0, 0])

    def result(self, res, epoch_index, sat_index, n, step_s):
        """The :class:`leosop.fusion.common.FusionResult` of engine run ``res`` whose aid j was Doppler j."""
        used, rejected_aid = self.used, self.offered & ~self.used
        updated, rejected = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        updated[epoch_index[used]], rejected[epoch_index[rejected_aid]] = True, True
        nis_dof = np.bincount(epoch_index[used], minlength=n)
        nis = np.where(updated, np.bincount(epoch_index[used], weights=self.nis[used], minlength=n), np.nan)
        innovations = np.zeros(int(used.sum()), dtype=[("epoch", int), ("sat", int), ("normalized", float)])
        innovations["epoch"], innovations["sat"], innovations["normalized"] = (
            epoch_index[used], sat_index[used], self.normalized[used])
        return common.FusionResult(np.arange(n) * step_s, res.lat_rad, res.lon_rad, res.alt_m, res.vel_enu_mps,
                                   quat_to_dcm(res.q_n_b), res.cov_ins, updated, rejected, nis, nis_dof,
                                   res.gyro_bias_rad_per_s, res.accel_bias_mps2, doppler_innovation=innovations)
