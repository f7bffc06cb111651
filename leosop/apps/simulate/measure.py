"""The Doppler of the tracked satellites, measured at signal or measurement level, and the snapshot fixes.

:func:`leo_fixes` goes through the run :data:`FIX_BLOCK_EPOCHS` epochs at a
time, keeping only each epoch's fix and what the EKF needs of it;
:func:`fix_error_model` says what each fix is made of, for the loose filter.
"""

import warnings

import numpy as np

from ... import frames
from ...constants import C_MPS
from ...fusion import aids_fix
from ...geometry.doppler import doppler_jacobian, doppler_rate
from ...orbits.visibility import compute_visibility
from ...positioning.robust_ls import FixStatus
from ...positioning.snapshot import solve_snapshots
from ...signal.doppler import estimate_block
from ...signal.error_model import doppler_sigma_hz
from ...signal.pilot import add_noise, comb_baseband
from ..scenarios import family_masks_deg, mask_label
from .sky import above_family_masks, tracked

__all__ = ["BLOCK_S", "FIX_BLOCK_EPOCHS", "SAMPLE_RATE_HZ", "SEARCH_HZ", "fix_error_model", "leo_fixes"]

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


def fix_error_model(vis, fixes, good, sigma_hz, sigma_est_hz, pos_sv_known, carrier_hz, family, offset_max_sat_hz,
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


def leo_fixes(scenario, constellation, family_sat, models, times_utc, t_s, pos_rx_ecef_m, vel_rx_ecef_mps,
               ins_pos_ecef_m, ins_vel_ecef_mps, sat_offset_hz, offset_max_sat_hz, orbit_err_ecef_m, *, level, coupling,
               orbit_error_m, orbit_error_model, rng_meas, progress):
    """Steps 2-4 of :mod:`leosop.apps.simulate`: the tracked satellites, their Doppler and the snapshot fixes.

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
    vis = above_family_masks(vis, family_sat, masks_deg)
    vis = tracked(vis, t_s, scenario.leo.outage_s, scenario.leo.outage_max_sats)
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

    Other parameters as :func:`leo_fixes`.

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
        :data:`leosop.apps.simulate.tight.PAIR_FIELDS`.
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
    fix_errors = fix_error_model(vis, fixes, checked, sigma_hz, sigma_est, pos_sv_known, carrier, fam,
                                  offset_max_sat_hz, orbit_error_m, orbit_error_model)
    per_epoch["fix_clock_hz"] = fix_errors.fix_clock_hz
    per_pair = {f: getattr(fix_errors, f) for f in aids_fix.PAIR_FIELDS}
    per_pair["epoch_index"] = per_pair["epoch_index"] + epoch0
    return per_epoch, per_pair

