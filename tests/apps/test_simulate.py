"""simulate: the fix's dependence on the satellites' constant errors, and the common orbit-error model."""

import numpy as np
import pytest

from leosop import frames
from leosop.apps import simulate
from leosop.apps.simulate import measure, sky
from leosop.constants import C_MPS
from leosop.fusion import aids_fix
from leosop.fusion.aids import InsView
from leosop.fusion.common import N_INS
from leosop.ins import strapdown
from leosop.ins import trajectory
from leosop.apps.montecarlo.parameters import apply
from leosop.apps.montecarlo.spec import load_spec
from leosop.constellations import REGISTRY
from leosop.orbits.visibility import compute_visibility
from leosop.geometry.doppler import doppler_jacobian
from leosop.positioning.robust_ls import FixStatus
from leosop.positioning.snapshot import solve_snapshots
from leosop.apps.scenarios import XIAN_BAOJI


#: Receiver offsets of the case below by family (Starlink, Orbcomm, OneWeb) [Hz]; Orbcomm never rises.
RX_HZ = np.array([5.0, 0.0, -40.0])


def _noise_free_mixed_fixes():
    """Snapshot fixes of noise-free Doppler with satellite offsets and orbit errors, and their FixErrorModel.

    The first 40 s of the xian-baoji flight; Starlink and OneWeb of the bundled
    sky above a 35 deg mask: two carriers, two receiver clocks (:data:`RX_HZ`),
    8 states per fix. Orbcomm is asked for too and never rises: the fixes'
    clocks are those of the groups present (0 and 2), which the gains must
    follow. Offsets uniform 0-5 Hz, orbit errors 30 m per axis.
    """
    truth = trajectory.flight(np.asarray(XIAN_BAOJI.waypoints), speed_mps=200.0, rate_hz=100.0,
                              duration_s=40.0).resample(1.0)
    times = XIAN_BAOJI.start_utc + (truth.t_s * 1e9).astype("timedelta64[ns]")
    C_e_n = frames.C_e_n(truth.lat_rad, truth.lon_rad)
    vel_rx = np.einsum("kij,kj->ki", C_e_n, truth.vel_enu_mps)
    constellation, family_sat = sky.transmitters(("starlink", "orbcomm", "oneweb"), None, times[[0, -1]])
    vis = compute_visibility(constellation, times, truth.pos_ecef_m, 35.0, vel_rx_ecef_mps=vel_rx,
                             show_progress=False)
    fam = family_sat[vis.sat_index]
    assert set(fam) == {0, 2}
    f0 = np.array([REGISTRY[f].carrier_hz for f in ("starlink", "orbcomm", "oneweb")])[fam]
    rng = np.random.default_rng(3)
    offset_hz = rng.uniform(0.0, 5.0, len(constellation))
    orbit_m = 30.0 * rng.standard_normal((len(constellation), 3))
    ep, sat = vis.epoch_index, vis.sat_index
    doppler = (-frames.range_rate(vis.pos_sv_ecef_m, vis.vel_sv_ecef_mps, truth.pos_ecef_m[ep], vel_rx[ep]) * f0
               / C_MPS + offset_hz[sat] + RX_HZ[fam])
    pos_known = vis.pos_sv_ecef_m + orbit_m[sat]
    h = doppler_jacobian(pos_known[:, None], vis.vel_sv_ecef_mps[:, None], truth.pos_ecef_m[ep], vel_rx[ep],
                         f0[:, None])
    sigma = np.sqrt(0.05**2 + 25.0 / 12.0 + (np.linalg.norm(h[:, 0, :3], axis=-1) * 30.0) ** 2)
    x0 = np.concatenate([truth.pos_ecef_m + 50.0, vel_rx, np.zeros((vel_rx.shape[0], 1))], axis=-1)
    fixes = solve_snapshots(vis.padded(doppler), vis.padded(sigma), vis.padded(pos_known),
                            vis.padded(vis.vel_sv_ecef_mps), vis.padded(f0), x0=x0,
                            clock_group=np.nan_to_num(vis.padded(fam.astype(float))).astype(int))
    good = fixes.status == FixStatus.OK
    assert good.sum() >= 35
    assert (vis.n_visible_by_group(family_sat)[good][:, [0, 2]] > 0).all()  # both constellations in every fix
    model = measure.fix_error_model(vis, fixes, good, sigma, 0.05, pos_known, f0, fam,
                                    np.full(len(constellation), 5.0), 30.0, "independent")
    return truth, vel_rx, fixes, good, model, offset_hz, orbit_m


def test_fix_error_is_the_gain_times_the_satellite_errors():
    # Independent reference: the nonlinear least-squares fix itself. The fix
    # error must equal sum_j G_j (o_j + h_j . dr_j) from _fix_error_model,
    # clocks included, and the residuals what the fix leaves of those errors.
    truth, vel_rx, fixes, good, model, offset_hz, orbit_m = _noise_free_mixed_fixes()
    assert model.gain_ecef.shape[1] == 6 + 2 and model.n_clocks == 2
    e_dopp = offset_hz[model.sat_index] + np.sum(model.orbit_hz_per_m * orbit_m[model.sat_index], axis=-1)
    predicted = np.zeros((good.size, 8))
    np.add.at(predicted, model.epoch_index, model.gain_ecef * e_dopp[:, None])
    actual = np.concatenate([fixes.pos_ecef_m - truth.pos_ecef_m, fixes.vel_ecef_mps - vel_rx,
                             fixes.clock_offsets_hz - RX_HZ[[0, 2]]], axis=-1)
    # The errors are tens to hundreds of metres; what the first-order model leaves
    # out is of relative size |error| / range (1e-4 at 700 km), amplified by the
    # geometry (0.2-0.3 % measured here): 1 % of the largest error plus 0.1 m
    # (1 mm/s, 0.01 Hz), while a wrong sign of the orbit term would leave ~100 %.
    scale = np.abs(actual[good]).max(axis=0)
    # Errors of metres at least on every axis (tens horizontally), so that a
    # wrong gain (~100 % off) cannot hide in the 0.1 m floor.
    assert np.all(scale[:3] > 2.0) and scale[:3].max() > 10.0
    floor = np.r_[0.1, 0.1, 0.1, 1e-3, 1e-3, 1e-3, 0.01, 0.01]
    assert np.all(np.abs(predicted[good] - actual[good]) <= 0.01 * scale + floor)
    # The residuals are what the fix left of the same errors: e_j - J_j G e to first order.
    J = np.concatenate([model.jacobian_pv, model.clock_index[:, None] == [0, 1]], -1)
    res_first_order = e_dopp - np.einsum("mi,mi->m", J, predicted[model.epoch_index])
    assert np.abs(res_first_order).max() > 1.0  # Hz: the offsets alone are 0-5 Hz
    np.testing.assert_allclose(model.residual_hz, res_first_order, atol=0.01 * np.abs(res_first_order).max())


def test_loose_fix_measurement_is_linear_in_the_satellite_errors():
    # What the loose filter takes of a fix (aids_fix.LeoFix): the 6 fix values,
    # its receiver offsets and its residuals in the space orthogonal to its
    # states. Independent references: (1) the residual rows hold the fix's
    # whole weighted residual sum, the solver's own chi-square; (2) with the INS
    # at the truth and the block estimates zero, the innovation is the true
    # receiver offsets' and satellite errors' share, -H x_true over the blocks
    # (error = estimate - truth) to first order (noise-free Doppler), which
    # checks every sign of H on the clock and satellite columns.
    truth, _, fixes, good, model, offset_hz, orbit_m = _noise_free_mixed_fixes()
    # Every good fix but the start's (epoch 0) is a correction when the period is zero.
    made = aids_fix.fix_aids(np.arange(good.size, dtype=float), np.where(good[:, None], fixes.pos_ecef_m, np.nan),
                             fixes.vel_ecef_mps, np.zeros((good.size, 6, 6)), 0.0, fix_errors=model)
    assert [aid.epoch for aid in made] == [k for k in np.flatnonzero(good) if k > 0]
    bounds = np.searchsorted(model.epoch_index, np.arange(good.size + 1))
    checked = 0
    for aid in made:
        k = aid.epoch
        rows = np.arange(bounds[k], bounds[k + 1])
        sats = model.sat_index[rows]
        x_true = np.concatenate([RX_HZ[[0, 2]], np.column_stack([offset_hz[sats], orbit_m[sats]]).ravel()])
        state = strapdown.NavState.from_dcm(truth.lat_rad[k], truth.lon_rad[k], truth.alt_m[k],
                                            truth.vel_enu_mps[k], np.eye(3))
        zeros = np.zeros(3)
        zero_states = {b.key: np.zeros(b.size) for b in aid.states}
        z, H, R = aid.matrices(InsView(state, zeros, zeros, zeros, states=zero_states))
        n_res = rows.size - 8
        assert z.shape == (6 + 2 + n_res,) and H.shape == (z.size, N_INS + x_true.size) and R.shape == (z.size, z.size)
        np.testing.assert_allclose(np.sum(z[8:] ** 2), fixes.chi2[k], rtol=1e-6)
        # First-order leftovers as in test_fix_error_is_the_gain_times_the_satellite_errors: 1 % of the
        # largest value of each kind of row plus 0.1 m, 1 mm/s, 0.01 Hz and 0.01 for the whitened residuals.
        scale = np.r_[np.full(3, np.abs(z[:3]).max()), np.full(3, np.abs(z[3:6]).max()), np.abs(z[6:8]),
                      np.full(n_res, np.abs(z[8:]).max())]
        floor = np.r_[np.full(3, 1e-3), np.full(3, 0.1), np.full(2, 0.01), np.full(n_res, 0.01)]
        assert np.all(np.abs(z + H[:, N_INS:] @ x_true) <= 0.01 * scale + floor), k
        checked += 1
    assert checked >= 35


def test_imu_made_in_blocks_gives_the_same_run_as_one_block(monkeypatch):
    # run_scenario makes the 100 Hz truth and IMU a block at a time and reads them twice (INS alone,
    # then the EKF); the block size must not change a bit of anything the run stores.
    import dataclasses

    sc = dataclasses.replace(XIAN_BAOJI, duration_s=120.0)

    def arrays(res):
        out = {f.name: getattr(res, f.name) for f in dataclasses.fields(res)}
        out.update({"fused." + f.name: getattr(res.fused, f.name) for f in dataclasses.fields(res.fused)})
        return {k: v for k, v in out.items() if isinstance(v, np.ndarray)}

    monkeypatch.setattr("leosop.apps.simulate.run.IMU_BLOCK_STEPS", 1000)  # one block for the whole run
    one = arrays(simulate.run_scenario(sc, level="measurement", seed=3))
    monkeypatch.setattr("leosop.apps.simulate.run.IMU_BLOCK_STEPS", 7)
    blocks = arrays(simulate.run_scenario(sc, level="measurement", seed=3))
    assert one.keys() == blocks.keys() and "fused.lat_rad" in one
    for k in one:
        assert np.array_equal(one[k], blocks[k], equal_nan=one[k].dtype.kind == "f"), k


@pytest.mark.parametrize("constellations, coupling", [(("starlink",), "loose"), (("starlink",), "tight"),
                                                      (("starlink", "orbcomm", "oneweb"), "loose")])
def test_fixes_made_in_blocks_give_the_same_run_as_one_block(monkeypatch, constellations, coupling):
    # run_scenario measures and solves the fixes a block of epochs at a time (one receiver clock per
    # family of the whole run in every block); the block size must not change a bit of anything the
    # run stores, the noise drawn in block order included. Three families at a 25 deg mask, of which
    # Orbcomm does not rise: fixes of 8 states in blocks of 7 epochs.
    import dataclasses

    sc = dataclasses.replace(XIAN_BAOJI, duration_s=120.0, mask_deg=25.0,
                             leo=dataclasses.replace(XIAN_BAOJI.leo, constellations=constellations))

    def arrays(res):
        out = {f.name: getattr(res, f.name) for f in dataclasses.fields(res)}
        out.update({"fused." + f.name: getattr(res.fused, f.name) for f in dataclasses.fields(res.fused)})
        return {k: v for k, v in out.items() if isinstance(v, np.ndarray)}

    monkeypatch.setattr(measure, "FIX_BLOCK_EPOCHS", 1000)  # one block for the whole run
    one = arrays(simulate.run_scenario(sc, level="measurement", coupling=coupling, seed=3))
    monkeypatch.setattr(measure, "FIX_BLOCK_EPOCHS", 7)
    blocks = arrays(simulate.run_scenario(sc, level="measurement", coupling=coupling, seed=3))
    assert one.keys() == blocks.keys() and np.isfinite(one["fix_pos_ecef_m"]).all()
    assert one["fix_cov"].shape[-1] == 6 + len(constellations) - ("orbcomm" in constellations)
    for k in one:
        assert np.array_equal(one[k], blocks[k], equal_nan=one[k].dtype.kind == "f"), k

def test_loose_filter_leaves_out_near_singular_fixes_of_the_cn0_imu_outlier():
    # leosop/data/studies/README.md: cn0_imu, MEMS grade at 50 dB-Hz, run seed 1488067860. At
    # 684-689 s seven satellites give zero-redundancy fixes of Doppler GDOP 540-2,200 that are
    # 1-13 km off; the loose filter took them, then its gate rejected 72 s of good fixes (18.3 m
    # mean error). The filter must skip exactly the fixes that are neither redundant nor
    # well-conditioned, reject none of the rest here, and stay with the other 19 seeds of
    # the cell (1.8-3.2 m; 1.86 m measured after the change, 5 m leaves room for small changes).
    spec = load_spec("cn0_imu")
    cell = next(c for c in spec.cells() if c["cn0_dbhz"] == 50 and c["imu_grade"] == "mems")
    scenario, options = apply(spec.scenario, cell, spec.source)
    captured = []  # one call per block of epochs (measure.FIX_BLOCK_EPOCHS)

    def solve(*args, **kwargs):
        captured.append(solve_snapshots(*args, **kwargs))
        return captured[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(measure, "solve_snapshots", solve)
        res = simulate.run_scenario(scenario, seed=1488067860, **options)
    status, n_used, cov, gdop = (np.concatenate([getattr(f, k) for f in captured])
                                 for k in ("status", "n_used", "cov", "gdop"))
    ok = status == FixStatus.OK
    usable = ok & aids_fix.checkable_fixes(n_used, cov, gdop)
    assert np.all(~usable[684:690] & ok[684:690])  # the six bad fixes exist and are left out
    assert np.array_equal(res.fused.updated, usable & (np.arange(usable.size) > 0))
    assert not res.fused.rejected.any()
    assert simulate.metrics(res)["fused"]["pos_err_mean_m"] < 5.0
