"""PPP/INS on the fusion engine: the PPP epoch aid against finite differences and against the SD filter.

References: the aid's own nonlinear model (central differences), one update
of :mod:`leosop.gnss.ppp_ins`'s single-differenced filter (a second
implementation: SD ambiguity states, its own design rows), and a short run
of that filter on the simulated car.
"""

import math

import numpy as np
import pytest
from conftest import ESBC_CLK, ESBC_SP3

from leosop.fusion import aids, kalman
from leosop.fusion.aids_gnss import ZWD_KEY, PppEpoch, ambiguity_block, zwd_block
from leosop.fusion.common import N_INS, pos_jacobian
from leosop.gnss import models, ppp_ins, ppp_ins_engine, ppp_ins_study
from leosop.gnss.products import read_clk, read_sp3
from leosop.ins.error_model import DPOS, DV, PHI
from leosop.ins.strapdown import NavState
from leosop.rotations import euler_to_dcm

pytestmark = pytest.mark.skipif(not (ESBC_SP3.exists() and ESBC_CLK.exists()), reason="ESBC data absent")
OPT = ppp_ins.PppInsOptions()
T_ORBIT_S = 6 * 3600.0
DOY = 177.0
# Central-difference steps per INS error group: position 1e-8 rad (6 cm; range curvature 1e-10 m) and
# 1 cm, so that the ranges' float rounding (~4e-9 m of 2e7 m) stays below 1e-6 of the differences.
STEP = np.r_[np.full(3, 1e-6), np.full(3, 1e-3), np.full(2, 1e-8), 1e-2, np.full(3, 1e-7), np.full(3, 1e-5)]


@pytest.fixture(scope="module")
def products():
    day = np.datetime64("2020-06-25", "ns")
    return read_sp3(ESBC_SP3, systems="G", ref_gps=day), read_clk(ESBC_CLK, systems="G", ref_gps=day)


def _state():
    C = euler_to_dcm(math.radians(1.0), math.radians(-2.0), math.radians(40.0))
    return NavState.from_dcm(math.radians(55.46), math.radians(8.45), 20.0, [9.0, -11.0, 0.2], C)


def _epoch(orbits):
    """An aid over the satellites above 15 deg at :func:`_state`; measurements the model at a nearby truth."""
    state = _state()
    probe = PppEpoch(0.0, T_ORBIT_S, orbits, np.arange(len(orbits.sv)), *np.zeros((3, len(orbits.sv))),
                     [], zwd_block(OPT), DOY, OPT)
    elev = probe.geometry(aids.InsView(state, np.zeros(3), np.zeros(3), np.zeros(3)))[3]
    sv = np.flatnonzero(elev > math.radians(15.0))
    rng = np.random.default_rng(5)
    b0 = rng.normal(size=sv.size) * 3.0
    blocks = [ambiguity_block(orbits.sv[j], T_ORBIT_S, b, OPT.amb_sigma_m, 1.0) for j, b in zip(sv, b0)]
    aid = PppEpoch(0.0, T_ORBIT_S, orbits, sv, *np.zeros((3, sv.size)), blocks, zwd_block(OPT), DOY, OPT)
    states = {ZWD_KEY: np.array([0.12])} | {b.key: np.array([b.mean0[0]]) for b in blocks}
    return aid, states, b0


def _view(state, states):
    return aids.InsView(state, np.zeros(3), np.zeros(3), np.zeros(3), states=states)


def test_ppp_design_matches_finite_differences(products):
    aid, states, _ = _epoch(products[0])
    state = _state()
    H = aid.design(_view(state, states))
    m = aid.orb_idx.size
    assert m >= 6 and H.shape == (3 * (m - 1), N_INS + 1 + m)
    H_fd = np.zeros_like(H)
    for i in range(N_INS):  # z(dx) = h(computed) - h(truth(dx)): H = dz/dx at 0
        e = np.zeros(N_INS)
        e[i] = STEP[i]
        H_fd[:, i] = (aid.predict(_view(state.corrected(-e[PHI], -e[DV], -e[DPOS]), states))
                      - aid.predict(_view(state.corrected(e[PHI], e[DV], e[DPOS]), states))) / (2 * STEP[i])
    for c, b in enumerate(aid.states):  # states: error = estimate - truth, h moves with the estimate
        plus, minus = dict(states), dict(states)
        plus[b.key], minus[b.key] = states[b.key] + 1.0, states[b.key] - 1.0  # linear: any step
        H_fd[:, N_INS + c] = (aid.predict(_view(state, plus)) - aid.predict(_view(state, minus))) / 2.0
    n = m - 1
    pos_m = H_fd[2 * n:, DPOS] @ np.linalg.inv(pos_jacobian(state.lat_rad, state.alt_m))
    # The rate's position term is neglected (as in ppp_ins): at most |v_sv| / rho = 3.9 km/s / 20200 km
    # = 1.9e-4 /s per satellite, 3.9e-4 for a difference (1 m of position: 0.4 mm/s against 6 cm/s of sigma).
    assert np.abs(pos_m).max() < 3.9e-4
    H_fd[2 * n:, DPOS] = 0.0
    # Relative 1e-6 of the largest column entry: central differences of smooth functions (second order);
    # the velocity columns 1e-4: the rate's light-time term (the receiver's motion moves the transmission
    # time, |v_sv . e| / c < 1.3e-5 per satellite) is neglected, as in ppp_ins; the position columns 1e-3:
    # so are the troposphere's gradients, the hydrostatic delay's with height (2.3 m over an 8 km scale
    # height, 2.8e-4 per metre at zenith, times an SD of mappings up to 4; measured 7e-4) and the mappings'
    # with the elevation (3e-6).
    tol = np.maximum(np.abs(H).max(axis=0), 1e-300) * 1e-6
    tol[DV] *= 100.0
    tol[DPOS] *= 1000.0
    err = np.abs(H - H_fd).max(axis=0)
    assert np.all(err <= tol), np.array2string(err / tol, precision=2, threshold=100)


def test_ppp_update_equals_the_sd_filter_update(products):
    # One update of the engine's aid (undifferenced ambiguities B) and of ppp_ins's SD rows (states
    # D_j = B_j - B_ref) from the same prior: the same INS and wet-delay corrections and the same D,
    # exactly (a linear map of the state; 1e-9 relative is the rounding of two solves).
    aid, states, b0 = _epoch(products[0])
    state = _state()
    view = _view(state, states)
    z, H, R = aid.matrices(view)
    m = aid.orb_idx.size
    n_x = N_INS + 1 + m
    rng = np.random.default_rng(2)
    A = rng.normal(size=(n_x, n_x)) * np.r_[np.full(3, 1e-3), np.full(3, 0.1), np.full(2, 1e-7), 1.0,
                                            np.full(6, 1e-5), 0.1, np.full(m, 2.0)][:, None]
    P = A @ A.T + np.diag(np.r_[np.full(N_INS + 1, 1e-14), np.full(m, 1e-4)])
    dx, P1, _, _ = kalman.update(np.zeros(n_x), P, z, H, R)
    # The SD filter: observations with the zenith hydrostatic delay removed, states mapped by T, the
    # non-INS states there being corrections (estimate + dx) instead of errors (estimate - dx): sign S.
    rho, rate, los, elev, C = aid.geometry(view)
    ref = int(np.argmax(elev))
    others = np.flatnonzero(np.arange(m) != ref)
    m_dry, m_wet = models.niell_mapping(elev, state.lat_rad, state.alt_m, DOY + T_ORBIT_S / 86400.0)
    zhd = models.saastamoinen_zhd_m(state.lat_rad, state.alt_m) * m_dry
    obs = aid.obs - np.stack([zhd, zhd, np.zeros(m)])
    x_old = np.zeros(ppp_ins._A0 + m)
    x_old[ppp_ins._ZWD] = states[ZWD_KEY][0]
    x_old[ppp_ins._A0 + others] = b0[others] - b0[ref]
    T = np.zeros((x_old.size, n_x))
    T[:N_INS + 1, :N_INS + 1] = np.eye(N_INS + 1)
    T[ppp_ins._A0 + others, N_INS + 1 + others] = 1.0
    T[ppp_ins._A0 + others, N_INS + 1 + ref] = -1.0
    T = np.diag(np.r_[np.ones(N_INS), -np.ones(1 + m)]) @ T
    geo = ppp_ins._Geometry(rho, rate, los, m_wet, np.sin(elev), ref, others, others)
    use = [np.ones(m - 1, bool)] * 3
    H_old, y, R_old, _ = ppp_ins._sd_measurements(geo, tuple(obs), x_old, C, pos_jacobian(state.lat_rad, state.alt_m),
                                                  use, OPT)
    dx_old, P1_old, _, _ = kalman.update(np.zeros(x_old.size), T @ P @ T.T, y, H_old, R_old)
    assert np.abs(z).max() > 1.0  # a real correction, not a no-op
    np.testing.assert_allclose(T @ dx, dx_old, rtol=1e-9, atol=1e-9 * np.abs(dx_old).max())
    np.testing.assert_allclose(T @ P1 @ T.T, P1_old, rtol=1e-9, atol=1e-9 * np.abs(P1_old).max())


def test_float_run_on_the_engine_matches_the_sd_filter(products):
    # 30 s of the simulated car (seed 3, float): both filters on the same simulated data. They differ by
    # design in small ways: the engine applies the first epoch after its first pair of IMU samples (and
    # records the start before it, so epoch 0 is left out), evaluates the error model at the end of each
    # step and the range rows at the updated INS. Measured here: 6e-4 sigma and sigmas within 5e-6 (bounds
    # 0.01 sigma, 1e-3); over 10 min on 5 seeds the differences stay below 1.5 mm (sigma 9 cm).
    runs = {e: ppp_ins_study.scenario(3, duration_s=30.0, outage_at_s=None, products=products, ar=False, engine=e)
            for e in (False, True)}
    truth = runs[False][0]
    np.testing.assert_array_equal(runs[True][0], truth)  # the same simulated run
    sd, eng = runs[False][1], runs[True][1]
    sigma = np.sqrt(np.trace(sd.cov_pos_enu_m2, axis1=1, axis2=2))[1:]
    diff = np.linalg.norm(eng.pos_float_ecef_m - sd.pos_float_ecef_m, axis=1)[1:]
    assert np.all(diff < 0.01 * sigma) and diff.max() > 0.0
    np.testing.assert_allclose(np.sqrt(np.trace(eng.cov_pos_enu_m2, axis1=1, axis2=2))[1:], sigma, rtol=1e-3)
    assert np.all(eng.n_sats[1:] >= 5) and np.linalg.norm(eng.pos_float_ecef_m[-1] - truth[-1]) < 3 * sigma[-1]


def test_ambiguity_fixing_equals_the_sd_filter_fixing():
    # The same float filter in both layouts (undifferenced ambiguities B for the engine, D_j = B_j - B_ref
    # for ppp_ins, mapped by T): the same wide-lanes, narrow-lanes, ratio, fixed position and conditioned
    # covariance; 1e-9 relative is the rounding of the solves.
    rng = np.random.default_rng(4)
    m, ref = 7, 2
    others = np.flatnonzero(np.arange(m) != ref)
    n_x = N_INS + 1 + m
    n_wl = np.r_[rng.integers(-20, 20, m)]
    n_wl[ref] = 0
    n1 = rng.integers(-50, 50, m)
    n1[ref] = 0
    b = 3.0 + ppp_ins.LAM_NL_M * n1 + ppp_ins.BETA_M * n_wl + rng.normal(size=m) * 0.002
    A = rng.normal(size=(n_x, n_x)) * np.r_[np.full(3, 1e-4), np.full(3, 0.01), np.full(2, 2e-9), 0.01,
                                            np.full(6, 1e-6), 0.01, np.full(m, 0.001)][:, None]
    P = A @ A.T + np.diag(np.r_[np.full(N_INS + 1, 1e-16), np.full(m, 1e-6)])
    P[-m:, -m:] += 4.0  # the unobservable common mode of B
    col = N_INS + np.arange(1 + m)
    est = np.r_[0.1, b]
    n_mw = np.full(m, 30)
    mean = 0.4 + n_wl + rng.normal(size=m) * 0.02
    ep = ppp_ins_engine._Epoch(0, np.arange(m), np.zeros(m, bool), mean * n_mw, n_mw * (mean**2 + 0.01), n_mw,
                               np.zeros(m))
    inertial = (np.zeros(m, bool), np.zeros(m))
    state = _state()

    def result():
        n = 1
        return ppp_ins.PppInsResult(np.zeros(n), *np.full((2, n, 3), np.nan), np.full((n, 3, 3), np.nan),
                                    np.full((n, N_INS, N_INS), np.nan), *np.zeros((3, n), int), np.full(n, np.nan),
                                    np.zeros(n, bool), 0, 0, 0)

    out = result()
    dx, P_fix = ppp_ins_engine._fix(out, 0, state, P, est, col, np.arange(m), np.arange(m), ref, ep, inertial,
                                    np.zeros(m), OPT)
    T = np.zeros((ppp_ins._A0 + m, n_x))
    T[:N_INS + 1, :N_INS + 1] = np.eye(N_INS + 1)
    T[ppp_ins._A0 + others, N_INS + 1 + others] = 1.0
    T[ppp_ins._A0 + others, N_INS + 1 + ref] = -1.0
    T = np.diag(np.r_[np.ones(N_INS), -np.ones(1 + m)]) @ T
    x_old = np.zeros(ppp_ins._A0 + m)
    x_old[ppp_ins._ZWD] = est[0]
    x_old[ppp_ins._A0 + others] = b[others] - b[ref]
    out_old = result()

    class Ins:
        pass

    ins = Ins()
    ins.state = state
    dx_old, P_fix_old = ppp_ins._fix(out_old, 0, ins, T @ P @ T.T, x_old, others, ref,
                                     (ep.mw_sum, ep.mw_sq, ep.mw_n), inertial, np.zeros(m), OPT)
    assert out.n_fixed[0] == out_old.n_fixed[0] == m - 1 and out.n_wl[0] == m - 1
    assert out.ratio[0] == pytest.approx(out_old.ratio[0], rel=1e-9)
    np.testing.assert_allclose(out.pos_fixed_ecef_m, out_old.pos_fixed_ecef_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(T @ dx, dx_old, rtol=1e-9, atol=1e-9 * np.abs(dx_old).max())
    np.testing.assert_allclose(T @ P_fix @ T.T, P_fix_old, rtol=1e-7, atol=1e-9 * np.abs(P_fix_old).max())
