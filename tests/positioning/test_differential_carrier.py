"""Differential carrier-phase fix against the pair simulator (truth: the light-time range from SGP4 states moved by
the drawn offsets, :func:`~leosop.positioning.differential_sim.simulate_phase`, not the solver's linear model)."""

from types import SimpleNamespace

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.positioning.differential_carrier import solve_differential_carrier
from leosop.positioning.differential_sim import draw_satellite_errors, simulate_phase
from leosop.replay.differential_carrier import differential_carrier_fix
from leosop.timebase import seconds_since

from tests.positioning.helpers import base_rover_scene

#: Noise-free fixes: 1e-5 cycles of noise is 0.3 um of range; what is left is the model's approximations (the
#: rover's light time from its first guess, 30 m off, corrected to first order) and 1 mm bounds it.
ONE_MM = 1e-3
#: The noise-free fixes of test_noise_free_recovers_truth_and_integers, float and fixed: 9 and 1 um here (the
#: states' light times are whole nanoseconds, 7 um of satellite motion). Without the Earth's rotation in the
#: rover's light-time correction (the satellite's ECEF rate for its inertial velocity) they were 89 and 46 um.
FLOAT_TOL_M, FIXED_TOL_M = 30e-6, 10e-6
#: A double difference of noise-free phase is a whole number of cycles to this (the same round-off, in cycles).
CYCLE_TOL = 0.02
CARRIER_HZ = 11.325e9


@pytest.fixture(scope="module")
def scene():
    """Five Walker satellites above 25 deg over the base for 20 s (0.5 s epochs), base and rover 7.5 km apart."""
    return base_rover_scene((500 * np.arange(40)).astype("timedelta64[ms]"), 5)


def pair(scene, seed, *, sigma_cycles, **error_kw):
    """Rover and base phase of the scene's satellites (shared satellite errors), and the rover's first guess."""
    const, base, rover, t, ids = scene
    rng = np.random.default_rng(seed)
    err = draw_satellite_errors(ids, t[0], rng, **error_kw)
    pos0 = rover + np.array([30.0, -20.0, 10.0])
    b = simulate_phase(const, err, base, t, rng, sigma_cycles=sigma_cycles, clock_offset_hz=1.2e3,
                       clock_drift_hz_per_s=0.5)
    r = simulate_phase(const, err, rover, t, rng, sigma_cycles=sigma_cycles, pos_light_ecef_m=pos0,
                       clock_offset_hz=-2e3, clock_drift_hz_per_s=-0.2)
    return r, b, pos0


def solve(scene, r, b, pos0, **kw):
    _, base, _, t, _ = scene
    return solve_differential_carrier(seconds_since(t, t[0]), r.phase_cycles, r.sigma_cycles, r.arc, b.phase_cycles,
                                      b.sigma_cycles, b.arc, r.pos_sv_ecef_m, b.pos_sv_ecef_m, b.vel_sv_ecef_mps,
                                      base, pos0, carrier_hz=CARRIER_HZ, **kw)


@pytest.mark.parametrize("sat_clock_degree", [None, 1])
def test_noise_free_recovers_truth_and_integers(scene, sat_clock_degree):
    """Without noise or orbit errors (and without offset states: over 20 s they trade with the position, which
    only their prior then bounds) the fix is the truth to microns (the first guess 30 m off), the double
    differences whole cycles, and LAMBDA fixes them all; satellite offsets of 500 Hz and drifts of 1 Hz/s cancel
    (or are fitted)."""
    rover = scene[2]
    r, b, pos0 = pair(scene, 1, sigma_cycles=1e-5, orbit_sigma_rtn_m=(0, 0, 0), offset_max_hz=500.0,
                      drift_sigma_hz_per_s=1.0)
    fix = solve(scene, r, b, pos0, sat_clock_degree=sat_clock_degree, orbit_sigma_rtn_m=(0, 0, 0))
    assert np.linalg.norm(fix.pos_float_ecef_m - rover) < FLOAT_TOL_M
    assert np.linalg.norm(fix.pos_ecef_m - rover) < FIXED_TOL_M
    assert fix.n_ambiguities == 4 and fix.n_sats == 5 and fix.n_epochs == 40
    assert np.max(np.abs(fix.ambiguity_cycles - np.round(fix.ambiguity_cycles))) < CYCLE_TOL
    assert fix.status == "fixed" and fix.n_fixed == 4


def test_fractional_offsets_stay_float(scene):
    """A phase offset of its own per satellite and receiver (a tracker's template) makes the double differences
    real-valued: with ``integer=False`` the float fix still finds the rover (the offsets are ambiguities)."""
    rover = scene[2]
    r, b, pos0 = pair(scene, 2, sigma_cycles=1e-5, orbit_sigma_rtn_m=(0, 0, 0))
    shift = np.random.default_rng(3).uniform(0.0, 1.0, (r.phase_cycles.shape[0], 1))
    r = type(r)(r.phase_cycles + shift, r.sigma_cycles, r.arc, r.pos_sv_ecef_m, r.vel_sv_ecef_mps)
    fix = solve(scene, r, b, pos0, integer=False, orbit_sigma_rtn_m=(0, 0, 0))
    assert fix.status == "float" and fix.n_fixed == 0
    assert np.linalg.norm(fix.pos_ecef_m - rover) < ONE_MM
    assert np.max(np.abs(fix.ambiguity_cycles - np.round(fix.ambiguity_cycles))) > 0.1


def test_orbit_offsets_within_sigma(scene):
    """With element-set offsets (30 / 300 / 100 m) and 0.01-cycle noise the joint fit's error is inside its
    sigma (chi-square with 3 dof exceeds 16.3 with probability 1e-3), and the residuals are white (chi2 test)."""
    rover = scene[2]
    r, b, pos0 = pair(scene, 4, sigma_cycles=0.01)
    fix = solve(scene, r, b, pos0, sat_clock_degree=1)
    e = fix.pos_ecef_m - rover
    assert e @ np.linalg.solve(fix.cov, e) < 16.3
    assert 1e-3 < fix.chi2_p < 1 - 1e-3


def test_bad_input(scene):
    r, b, pos0 = pair(scene, 5, sigma_cycles=0.01)
    none = np.full_like(b.phase_cycles, np.nan)
    _, base, _, t, _ = scene
    with pytest.raises(InputError, match="no double difference"):
        solve_differential_carrier(seconds_since(t, t[0]), r.phase_cycles, r.sigma_cycles, r.arc, none, b.sigma_cycles,
                                   b.arc, r.pos_sv_ecef_m, b.pos_sv_ecef_m, b.vel_sv_ecef_mps, base, pos0,
                                   carrier_hz=CARRIER_HZ)
    with pytest.raises(InputError, match="^phase_base_cycles: shape"):
        solve_differential_carrier(seconds_since(t, t[0]), r.phase_cycles, r.sigma_cycles, r.arc,
                                   b.phase_cycles[:, 1:], b.sigma_cycles, b.arc, r.pos_sv_ecef_m, b.pos_sv_ecef_m,
                                   b.vel_sv_ecef_mps, base, pos0, carrier_hz=CARRIER_HZ)
    with pytest.raises(InputError, match="^t_s: the epochs must increase"):
        solve_differential_carrier(seconds_since(t, t[0])[::-1], r.phase_cycles, r.sigma_cycles, r.arc,
                                   b.phase_cycles, b.sigma_cycles, b.arc, r.pos_sv_ecef_m, b.pos_sv_ecef_m,
                                   b.vel_sv_ecef_mps, base, pos0, carrier_hz=CARRIER_HZ)


def _carrier(phase, sat_id, time_utc, rows=slice(None), cols=slice(None)):
    """What :func:`~leosop.replay.differential_carrier.differential_carrier_fix` reads of a ReplayCarrier: the
    satellites ``rows`` (named ``sat_id``) at the epochs ``cols`` (at ``time_utc``)."""
    tracks = SimpleNamespace(**{k: getattr(phase, v)[rows][:, cols] for k, v in (
        ("phase_cycles", "phase_cycles"), ("phase_sigma_cycles", "sigma_cycles"), ("arc", "arc"))})
    return SimpleNamespace(sat_id=tuple(sat_id), time_utc=time_utc, tracks=tracks)


def test_replay_pair_matches_satellites_and_blocks(scene):
    """The base's satellites in another order, one the rover lacks, its blocks starting earlier: matched by id
    and instant, the joint fix is within its sigma; its JSON says the model, the ambiguities (integers tried, too
    uncertain from 1.5 s to pass) and the float fix beside the final one."""
    const, base, rover, t, ids = scene
    r, b, pos0 = pair(scene, 6, sigma_cycles=0.001)
    rover_c = _carrier(r, ids[:4], t[5:], slice(0, 4), slice(5, None))
    order = np.array([4, 2, 0, 1, 3])
    base_c = _carrier(b, ids[order], t, order)
    got = differential_carrier_fix(rover_c, base_c, const, base, pos0, carrier_hz=CARRIER_HZ)
    assert got.sat_id == tuple(sorted(ids[:4])) and got.time_utc.size == t.size - 5
    e = got.joint.pos_ecef_m - rover
    assert e @ np.linalg.solve(got.joint.cov, e) < 16.3
    doc = got.doc()
    assert (doc["model"], doc["ambiguities"], doc["single_difference"]["ambiguities"]) == ("joint", "float", "float")
    assert doc["n_sats"] == 4 and doc["n_epochs"] == t.size - 5
    assert doc["ratio"] is not None and len(doc["ambiguity_cycles"]) == len(doc["ambiguity_sigma_cycles"]) == 3
    cov = np.array(doc["float"]["cov_ecef_m2"])
    np.testing.assert_allclose(cov, got.joint.cov_float, rtol=1e-12)
    # the east / north / up sigmas are the same covariance rotated: the same trace
    assert np.sum(np.square(doc["float"]["sigma_enu_m"])) == pytest.approx(np.trace(cov), rel=1e-12)


def test_replay_pair_refused(scene):
    const, base, rover, t, ids = scene
    r, b, pos0 = pair(scene, 7, sigma_cycles=0.001)
    rover_c = _carrier(r, ids, t)
    with pytest.raises(InputError, match="^the base's blocks are not at the rover's instants"):
        differential_carrier_fix(rover_c, _carrier(b, ids, t + np.timedelta64(50, "ms")), const, base,
                                 pos0, carrier_hz=CARRIER_HZ)
    with pytest.raises(InputError, match="^no satellite tracked in carrier phase by both"):
        differential_carrier_fix(rover_c, _carrier(b, [f"9{s}" for s in ids], t), const, base,
                                 pos0, carrier_hz=CARRIER_HZ)
