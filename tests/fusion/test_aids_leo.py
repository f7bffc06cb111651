"""LEO Doppler aids of the engine: H against finite differences, the model against a second formula, state blocks.

References: central differences of the aid's own nonlinear model (as for the
other aids in tests/fusion/test_engine.py); the Doppler closed form written out here
from the DESIGN 4.3 definition (range rate = -doppler c / f0); the clock
block's transition against the integral of white noise; the velocity of a
circular drive in closed form for the ``--leo-sim`` reference track.
"""

import dataclasses
import math

import numpy as np
import pytest

from leosop import frames
from leosop.constants import C_MPS
from leosop.apps import fuse_leo
from leosop.fusion import aids_leo, engine
from leosop.fusion.aids import StateBlock
from leosop.fusion.blocks import Blocks
from leosop.fusion.common import N_INS
from leosop.gnss.rtklib_pos import PosSolution
from leosop.ins.error_model import DPOS, DV, EPS, PHI
from leosop.ins.strapdown import NavState
from leosop.ins.trajectory import static

from tests.helpers import central_difference_jacobian, leo_geometry
from tests.fusion.helpers import CARRIER_HZ, STEP, computed_state, true_view

CLOCK = StateBlock("leo_clock:starlink", (0.0, 0.0), (100.0, 1.0), (1e-6, 1e-6), integrated=True)
SAT = StateBlock("leo_sat:44713", (0.0,), (1.5,), (1e-3,), drop_after_s=30.0)
X_BLOCKS = {CLOCK.key: np.array([123.4, 0.05]), SAT.key: np.array([-1.7])}


def _aid(lever=(0.3, -0.8, 1.2)):
    """A satellite 550 km up and ~900 km away, moving at 7.6 km/s, as seen from the test's INS."""
    _, r_sv, v_sv, _, _ = leo_geometry(computed_state()[0])
    return aids_leo.LeoDoppler(0.0, -25e3, 3.0, CARRIER_HZ, r_sv, v_sv, lever, CLOCK, SAT)


def _with_blocks(view, d_clock=(0.0, 0.0), d_sat=(0.0,)):
    """``view`` with the block estimates less the errors ``d_*`` (error = estimate minus truth)."""
    return dataclasses.replace(view, states={CLOCK.key: X_BLOCKS[CLOCK.key] - d_clock,
                                             SAT.key: X_BLOCKS[SAT.key] - d_sat})


def test_design_matrix_matches_finite_differences():
    aid = _aid()
    computed = _with_blocks(true_view(np.zeros(N_INS)))
    _, H, R = aid.matrices(computed)
    assert H.shape == (1, N_INS + 3) and R.shape == (1, 1)
    # 100x the other aids' steps: a Doppler of ~3e4 Hz from ECEF coordinates of 6e6 m rounds at ~1e-9 m
    # (3e-10 Hz), which 1e-10 rad steps would divide into errors of 1e-5; at 100x the second-order terms are
    # still below 1e-6 relative (checked: 1e-7 at 1000x).
    step = np.r_[100 * STEP, 1e-3, 1e-4, 1e-3]
    H_fd = central_difference_jacobian(
        lambda e: -aid.predict(_with_blocks(true_view(e[:N_INS]), e[N_INS:N_INS + 2], e[N_INS + 2:])), step)
    # z(dx) = h(computed) - h(truth(dx)): its derivative at 0 is H. The drift column is zero in H (the drift
    # reaches the measurement through the block's transition), and so in the model.
    assert H[0, N_INS + 1] == 0.0 == H_fd[0, N_INS + 1]
    # Column by column to 1e-6 of its size: central differences are exact to O(step^2); the
    # position columns are ~1e6 Hz/rad, the frame-rotation terms of the velocity ~1e2 of them.
    scale = np.maximum(np.abs(H_fd), 1e-3)
    np.testing.assert_array_less(np.abs(H - H_fd), 1e-6 * scale + 1e-9 * np.abs(H).max())


def test_prediction_is_the_design_doppler_with_the_clock_states():
    """The DESIGN 4.3 Doppler written out, at the antenna moved by the lever arm (closed-form lever geometry)."""
    state = computed_state()[0]
    aid = _aid(lever=(0.0, 0.0, 0.0))
    view = _with_blocks(true_view(np.zeros(N_INS)))
    r_rx = frames.geodetic_to_ecef(state.lat_rad, state.lon_rad, state.alt_m)
    v_rx = frames.C_e_n(state.lat_rad, state.lon_rad) @ state.vel_enu_mps
    los = (aid.pos_sv_ecef_m - r_rx) / np.linalg.norm(aid.pos_sv_ecef_m - r_rx)
    range_rate = los @ (aid.vel_sv_ecef_mps - v_rx)
    expected = -range_rate * CARRIER_HZ / C_MPS + 123.4 - 1.7
    assert aid.predict(view)[0] == pytest.approx(expected, abs=1e-6)  # 1 uHz: rounding of ~3e4 Hz terms
    assert abs(expected) > 1e3  # a real LEO Doppler, not a degenerate geometry


def test_clock_block_transition_is_the_integrated_random_walk():
    """Offset = integral of the drift plus white noise: Q over dt from the closed form, checked by Monte Carlo."""
    b = StateBlock("c", (0.0, 0.0), (1.0, 1.0), (0.3, 0.7), integrated=True)
    Phi, Qd = b.transition(2.0)
    np.testing.assert_allclose(Phi, [[1.0, 2.0], [0.0, 1.0]])
    rng = np.random.default_rng(3)
    n, dt = 200, 0.01  # 200 fine steps of 10 ms make the 2 s
    w_d = rng.normal(0.0, math.sqrt(0.7 * dt), (20_000, n))
    w_o = rng.normal(0.0, math.sqrt(0.3 * dt), (20_000, n))
    drift = np.cumsum(w_d, axis=1)
    offset = np.sum(drift * dt, axis=1) + w_o.sum(axis=1)
    emp = np.cov(np.stack([offset, drift[:, -1]]))
    # 20 000 samples: the variances' relative scatter is sqrt(2 / 20 000) = 1 %; 5 % is 5 sigma
    # (plus the fine grid's 1/n bias on the dt^3 term).
    np.testing.assert_allclose(emp, Qd, rtol=0.05)


@pytest.mark.parametrize("lever", [(0.0, 0.0, 0.0), (0.3, -0.8, 1.2)])
def test_orbit_error_columns_match_finite_differences(lever):
    """With an orbit-error block (and a clock without drift), every column against central differences."""
    clock = StateBlock("leo_clock:0", (0.0,), (10.0,), (1e-6,))
    orbit = StateBlock("leo_orbit:44713", (0.0,) * 3, (20.0,) * 3, (0.0,) * 3, drop_after_s=30.0)
    base = _aid(lever)
    aid = aids_leo.LeoDoppler(0.0, -25e3, 3.0, CARRIER_HZ, base.pos_sv_ecef_m, base.vel_sv_ecef_mps, lever, clock,
                              SAT, orbit)
    x = {clock.key: np.array([7.0]), SAT.key: np.array([-1.7]), orbit.key: np.array([12.0, -30.0, 5.0])}

    def view(e):
        """The truth moved by the error ``e`` (INS errors, then the blocks: estimate minus truth)."""
        d = np.split(e[N_INS:], [1, 2])
        return dataclasses.replace(true_view(e[:N_INS]), states={k: x[k] - di for k, di in zip(x, d)})

    _, H, _ = aid.matrices(view(np.zeros(N_INS + 5)))
    assert H.shape == (1, N_INS + 5)
    step = np.r_[100 * STEP, 1e-3, 1e-3, np.full(3, 1e-2)]  # 1 cm of orbit: the Doppler is linear to 1e-8 there
    H_fd = central_difference_jacobian(lambda e: -aid.predict(view(e)), step)
    # As test_design_matrix_matches_finite_differences; the orbit columns are dD/dr_rx, ~1e-2 Hz/m at Ku.
    scale = np.maximum(np.abs(H_fd), 1e-3)
    np.testing.assert_array_less(np.abs(H - H_fd), 1e-6 * scale + 1e-9 * np.abs(H).max())
    assert np.abs(H[0, N_INS + 2:]).min() > 1e-4  # the orbit columns are not trivially zero


@pytest.mark.parametrize("lever", [(0.0, 0.0, 0.0), (0.3, -0.8, 1.2)])
def test_window_aid_columns_and_clone_rows_match_finite_differences(lever):
    """The 1 s window model: every column (INS, clock, satellite, cloned start) against central differences, the
    prediction against the DESIGN 4.3 Doppler of the chord, and the clone's rows against its own position."""
    T = 1.0
    clone = StateBlock("leo_window:0.0", (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, drop_after_s=1.5, cloned=True)
    base = _aid(lever)
    aid = aids_leo.LeoDoppler(0.5, -25e3, 3.0, CARRIER_HZ, base.pos_sv_ecef_m, base.vel_sv_ecef_mps, lever, CLOCK,
                              SAT, window=(T, clone))
    start = aids_leo.LeoWindowStart(-0.5, lever, clone)
    r_end, G = start.clone_rows(true_view(np.zeros(N_INS)))
    v_mean = np.array([3.0, -5.0, 6.5])  # the chord differs from the INS velocity at the end (rocking)
    x = {CLOCK.key: X_BLOCKS[CLOCK.key], SAT.key: X_BLOCKS[SAT.key], clone.key: r_end - T * v_mean}

    def view(e):
        """The truth moved by the error ``e`` (INS errors, then the blocks: estimate minus truth)."""
        d = np.split(e[N_INS:], [2, 3])
        return dataclasses.replace(true_view(e[:N_INS]), states={k: x[k] - di for k, di in zip(x, d)})

    _, H, _ = aid.matrices(view(np.zeros(N_INS + 6)))
    assert H.shape == (1, N_INS + 6)
    # The chord takes the ECEF position's ~1e-9 m rounding at 38 Hz/m (1/T at Ku): the position steps 1000x the
    # other aids' (0.6 m; h is linear in the window's end but for the line of sight's ~1e-8 curvature there),
    # 1 mm of the cloned start (~0.04 Hz).
    ins_step = 100 * STEP
    ins_step[DPOS] *= 10
    step = np.r_[ins_step, 1e-3, 1e-4, 1e-3, np.full(3, 1e-3)]
    H_fd = central_difference_jacobian(lambda e: -aid.predict(view(e)), step)
    # As test_design_matrix_matches_finite_differences: central differences exact to O(step^2).
    scale = np.maximum(np.abs(H_fd), 1e-3)
    np.testing.assert_array_less(np.abs(H - H_fd), 1e-6 * scale + 1e-9 * np.abs(H).max())
    # Only the position and attitude (through the lever arm) of the INS: the velocity is the chord's.
    assert not H[0, DV].any() and not H[0, EPS].any() and np.abs(H[0, N_INS + 3:]).min() > 1.0
    # The prediction: the Doppler of the chord seen from the window's midpoint, plus the offsets.
    mid = 0.5 * (r_end + x[clone.key])
    los = (aid.pos_sv_ecef_m - mid) / np.linalg.norm(aid.pos_sv_ecef_m - mid)
    expected = -los @ (aid.vel_sv_ecef_mps - v_mean) * CARRIER_HZ / C_MPS + 123.4 - 1.7
    assert aid.predict(view(np.zeros(N_INS + 6)))[0] == pytest.approx(expected, abs=1e-6)
    # The clone's rows: the antenna position over the INS errors, by central differences of clone_rows itself.
    G_fd = central_difference_jacobian(lambda e: -start.clone_rows(true_view(e))[0], ins_step)
    # m per unit error: position columns ~6e6 m/rad, their differences rounded at 1e-9 m / 2e-7 rad = 5e-3 m/rad.
    np.testing.assert_allclose(G, G_fd, rtol=1e-6, atol=2e-2)
    assert np.abs(G[:, PHI]).max() >= 0.5 * np.linalg.norm(lever)  # the lever's rotation is in the clone


def test_blocks_clone_is_the_linear_map_of_the_covariance():
    """Stochastic cloning: the grown P is ``A P A^T`` with ``A = [I; G 0]`` (the clone a copy of ``G dx_ins``)."""
    rng = np.random.default_rng(5)
    n = N_INS + 4
    L = rng.standard_normal((n, n))
    P = L @ L.T
    G = rng.standard_normal((3, N_INS))
    blocks = Blocks()
    clone = StateBlock("c", (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, drop_after_s=1.0, cloned=True)
    grown = blocks.clone(P, clone, np.array([1.0, 2.0, 3.0]), G, 0.0)
    A = np.vstack([np.eye(n), np.hstack([G, np.zeros((3, n - N_INS))])])
    np.testing.assert_allclose(grown, A @ P @ A.T, rtol=1e-12, atol=1e-12)
    assert blocks.alive((clone,)) and blocks.layout()["c"][0] == n
    # Marginalised once stale, as the other blocks.
    assert blocks.drop_stale(grown, 1.5).shape == P.shape and not blocks.alive((clone,))


def test_leo_aids_with_a_window_start_clones_before_and_measure_after():
    """``window_s``: one clone per epoch shared by its rows, made T/2 before it; the rows due T/2 after it."""
    m = 3
    sv = np.tile([7e6, 0.0, 0.0], (m, 1))
    aids = aids_leo.leo_aids(np.array([10.0, 10.0, 11.0]), ["1", "2", "1"], ["0"] * m, np.ones(m), np.ones(m),
                             np.full(m, CARRIER_HZ), sv, sv, np.zeros(3), aids_leo.LeoOptions(window_s=1.0))
    starts = [a for a in aids if a.clones]
    rows = [a for a in aids if not a.clones]
    assert [a.t_s for a in starts] == [9.5, 10.5] and [a.t_s for a in rows] == [10.5, 10.5, 11.5]
    assert rows[0].states[-1] is rows[1].states[-1] is starts[0].states[0] and rows[2].states[-1].cloned
    with pytest.raises(ValueError, match="window_s"):
        aids_leo.leo_aids(np.zeros(1), ["1"], ["0"], np.ones(1), np.ones(1), np.ones(1), sv[:1], sv[:1], np.zeros(3),
                          aids_leo.LeoOptions(window_s=0.0))


@pytest.mark.parametrize("model", ["independent", "common"])
def test_leo_aids_share_the_orbit_blocks_as_the_model_says(model):
    """Independent: one orbit block per satellite (dropped with it); common: one for all, never dropped."""
    opts = aids_leo.LeoOptions(rx_drift_sigma_hz_per_s=None, orbit_sigma_m=5.0, orbit_model=model)
    m = 4
    sv = np.tile([7e6, 0.0, 0.0], (m, 1))
    aids = aids_leo.leo_aids(np.arange(m, dtype=float), ["1", "2", "1", "3"], ["0"] * m, np.ones(m), np.ones(m),
                             np.full(m, CARRIER_HZ), sv, sv, np.zeros(3), opts,
                             sat_offset_mean_hz=np.array([2.5, 1.0, 9.0, 0.5]))
    orbit_keys = [a.states[2].key for a in aids]
    if model == "common":
        assert set(orbit_keys) == {"leo_orbit:common"} and aids[0].states[2].drop_after_s is None
    else:
        assert orbit_keys == ["leo_orbit:1", "leo_orbit:2", "leo_orbit:1", "leo_orbit:3"]
        assert aids[0].states[2].drop_after_s == aids_leo.SAT_DROP_AFTER_S
    assert all(a.states[0].size == 1 for a in aids) and aids[0].states[0] is aids[3].states[0]
    # Each satellite's prior is its first row's.
    assert [a.states[1].mean0[0] for a in aids] == [2.5, 1.0, 2.5, 0.5]
    assert aids[0].states[2].sigma0 == (5.0,) * 3
    with pytest.raises(ValueError, match="orbit_model"):
        aids_leo.leo_aids(np.zeros(1), ["1"], ["0"], np.ones(1), np.ones(1), np.ones(1), sv[:1], sv[:1], np.zeros(3),
                          dataclasses.replace(opts, orbit_model="shared"))


def test_reference_track_velocity_in_a_turn_is_the_chord_closed_form():
    """``--leo-sim``'s reference velocity from 4 Hz fixes on a circle, 10 m/s at 30 deg/s (the drive's sharpest).

    It is the 1 s chord: along the mid-point tangent, the speed times ``sin(w / 2) / (w / 2)`` (0.11 m/s short
    here, the mean velocity over the second), exactly; the tolerance is the geodetic round trip.
    """
    speed_mps, rate_rad_per_s, step_s = 10.0, math.radians(30.0), 0.25
    t = np.arange(0.0, 20.0, step_s)
    radius = speed_mps / rate_rad_per_s
    lat0, lon0 = math.radians(40.1), math.radians(-105.1)
    C = frames.C_e_n(lat0, lon0)
    r0 = frames.geodetic_to_ecef(lat0, lon0, 1600.0)

    def circle_ecef_m(t_s):
        a = rate_rad_per_s * t_s
        return r0 + radius * np.stack([np.sin(a), 1.0 - np.cos(a), 0.0 * a], axis=-1) @ C.T

    lat, lon, alt = frames.ecef_to_geodetic(circle_ecef_m(t))
    n = t.size
    sol = PosSolution(1.75e9 + t, np.degrees(lat), np.degrees(lon), alt, np.ones(n, dtype=int), np.full(n, 20),
                      np.tile(np.eye(3) * 1e-4, (n, 1, 1)), None, None, "circle.pos")
    t_s, pos, vel, valid = fuse_leo.reference_track(sol)
    assert valid.all() and t_s[0] == 0.5 and t_s[-1] == 18.5
    np.testing.assert_allclose(pos, circle_ecef_m(t_s), rtol=0, atol=1e-6)
    a, half = rate_rad_per_s * t_s, 0.5 * rate_rad_per_s
    chord = speed_mps * math.sin(half) / half * np.stack([np.cos(a), np.sin(a), 0.0 * a], axis=-1) @ C.T
    np.testing.assert_allclose(vel, chord, rtol=0, atol=1e-5)  # 1e-6 m over the 1 s chord, doubled
    assert 0.11 < speed_mps - np.linalg.norm(vel, axis=1).max() < 0.12


def test_engine_clones_each_window_start_and_skips_windows_begun_before_the_run():
    """A static IMU (20 s) with windowed Doppler of four satellites at 1 Hz, exact for a receiver at rest.

    Each epoch's rows are due 0.5 s after it, on the clone made 0.5 s before it: the epoch at 0 s (its window
    starting before the run) is skipped, the other 19 x 4 rows are applied; the clones are dropped 1.5 s after
    their use; the INS, started 0.07 m/s off (sigma 0.1 m/s), ends at rest inside the filter's 3 sigma, which the
    Doppler has brought under 0.02 m/s horizontally (measured 0.009 m/s; no noise is added, so the error is
    the linearisation's and the clones', ~3e-4 m/s).
    """
    truth = static(40.1, -105.15, 1600.0, 1.0, -2.0, 30.0, 20.0)
    n, dt = truth.dtheta_b_rad.shape[0], truth.dt_s
    r_rx = truth.pos_ecef_m[0]
    up = r_rx / np.linalg.norm(r_rx)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    r_sv = r_rx + 550e3 * up + 700e3 * np.array([east, -east, north, -north])
    v_sv = 7.6e3 * np.array([north, -north, -east, east]) + 100.0 * up
    los = (r_sv - r_rx) / np.linalg.norm(r_sv - r_rx, axis=1)[:, None]
    doppler = -np.einsum("ij,ij->i", los, v_sv) * CARRIER_HZ / C_MPS
    epochs = np.arange(0.0, 20.0)
    m = epochs.size * 4
    rows = np.tile(np.arange(4), epochs.size)
    opts = aids_leo.LeoOptions(rx_offset_sigma_hz=1.0, rx_drift_sigma_hz_per_s=None, sat_offset_sigma_hz=0.1,
                               window_s=1.0)
    aid_list = aids_leo.leo_aids(np.repeat(epochs, 4), rows.astype(str), ["0"] * m, doppler[rows], np.full(m, 0.3),
                                 np.full(m, CARRIER_HZ), r_sv[rows], v_sv[rows], np.zeros(3), opts)
    aid_list.sort(key=lambda a: a.t_s)
    used = []
    state0 = NavState.from_dcm(truth.lat_rad[0], truth.lon_rad[0], truth.alt_m[0], [0.05, -0.05, 0.0],
                               truth.C_n_b[0])
    P0 = np.diag(np.r_[np.full(3, 1e-6), np.full(3, 0.01), np.full(2, 1e-14), 1e-2, np.full(3, 1e-10),
                       np.full(3, 1e-6)])
    res = engine.run(state0, P0, truth.t_s[1:], np.full(n, dt), truth.dtheta_b_rad, truth.dvel_b_mps, aid_list,
                     engine.EngineSettings(1e-6, 1e-5, 0.0, 0.0),
                     on_aid=lambda i, a, z, S, ok, reopened: used.append((a.t_s, ok)))
    assert res.aids["leo_doppler"][0] == 19 * 4 and min(t for t, _ in used) == 1.5 and all(ok for _, ok in used)
    # The clones of the last two epochs are alive at the end (dropped 1.5 s after their use), the others gone.
    assert sorted(k for k in res.states if k.startswith("leo_window:")) == ["leo_window:18.0", "leo_window:19.0"]
    sigma_v = res.sigma[-1, DV][:2]
    assert sigma_v.max() < 0.02 and (np.abs(res.vel_enu_mps[-1, :2]) < 3 * sigma_v).all()
