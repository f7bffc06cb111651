"""Tight INS/Doppler EKF: Jacobian against finite differences, consistency on short flights."""

import dataclasses

import numpy as np
import pytest

from consistency import assert_filter_consistent
from leosop import frames
from leosop.fusion import common, tight
from leosop.ins import strapdown
from leosop.scenarios import XIAN_BAOJI
from leosop.simulate import run_scenario


@pytest.mark.parametrize("orbit_model", ["independent", "common"])
def test_jacobian_matches_the_change_of_the_predicted_doppler(orbit_model):
    # Feeding back an error state x must change the innovations by -H x (to
    # second order in x): an independent check of every column block, for
    # both layouts of the orbit-error states (per satellite, or one shift
    # shared by the three satellites), with two constellations (two receiver
    # clocks, two carriers: Starlink and Iridium NEXT rows).
    lat, lon, alt = np.radians(34.3), np.radians(108.5), 3000.0
    state = strapdown.NavState.from_dcm(lat, lon, alt, [-200.0, 5.0, 1.0], np.eye(3))
    r_rx = frames.geodetic_to_ecef(lat, lon, alt)
    rng = np.random.default_rng(5)
    up = r_rx / np.linalg.norm(r_rx)
    pos_sv = r_rx + 700e3 * up + rng.uniform(-4e5, 4e5, (3, 3))
    vel_sv = np.cross([0.0, 0.0, 1.0], pos_sv) / np.linalg.norm(pos_sv, axis=1)[:, None] * 7.5e3
    meas = tight.DopplerMeasurements(np.zeros(3, int), np.arange(3), rng.normal(0, 1e4, 3), np.ones(3), pos_sv, vel_sv,
                                     carrier_hz=np.array([11.325e9, 1626.2708e6, 1626.2708e6]),
                                     clock_index=np.array([0, 1, 1]))
    sats = common.SatelliteStates(17, orbit_model, 2.5, 1.4, 30.0)
    x_hat, P = sats.initial(np.zeros(17), np.eye(17))
    x_hat, P = sats.see(x_hat, P, [0, 1, 2], 0.0)
    columns = [sats.columns(j) for j in range(3)]
    offsets = [c for c, _ in columns]
    x_hat[15:17], x_hat[offsets] = [4.0, -7.0], [1.0, 2.0, 3.0]
    y0, H = tight._rows(state, x_hat, columns, meas, np.arange(3))
    x = np.zeros_like(x_hat)
    x[3:6] = [0.02, -0.01, 0.03]  # m/s
    x[6:9] = [1e-6, -2e-6, 3.0]  # rad, rad, m (about 6 and 11 m horizontally)
    x[15:17] = [0.5, -0.25]
    x[offsets] = [0.3, -0.2, 0.1]  # Hz
    for _, o in columns:
        x[o] = [2.0, -1.0, 1.5]  # m
    moved = state.corrected(dvel_enu_mps=x[3:6], dpos=x[6:9])
    y1, _ = tight._rows(moved, x_hat + np.r_[np.zeros(15), x[15:]], columns, meas, np.arange(3))
    # The response is 0.3-4 Hz; second-order terms are ~1e-4 Hz, while the
    # smallest first-order effect (the ENU frame turning with the position,
    # 3e-4 m/s of ECEF velocity) is worth 0.012 Hz at Ku: 1e-3 Hz separates them.
    np.testing.assert_allclose(y0 - y1, H @ x, atol=1e-3)
    # Each row sees its own constellation's clock only.
    np.testing.assert_array_equal(H[:, 15:17], [[1, 0], [0, 1], [0, 1]])
    # The layout: 4 states per satellite, or 3 shared and 1 per satellite.
    assert x_hat.size == (17 + 12 if orbit_model == "independent" else 17 + 3 + 3)


def _lag1_pairs(result):
    """Each satellite's normalised Doppler innovations at consecutive epochs, (2, m)."""
    d = np.sort(result.fused.doppler_innovation, order=("sat", "epoch"))
    nxt = (d["sat"][1:] == d["sat"][:-1]) & (d["epoch"][1:] == d["epoch"][:-1] + 1)
    return np.stack([d["normalized"][:-1][nxt], d["normalized"][1:][nxt]])


def test_filter_is_consistent_on_short_flights():
    # Measurement-level Doppler with the Table 1 satellite offsets and orbit
    # errors, which the tight filter models: NEES of position and velocity
    # within [0.5, 2] of its dimension (issue 6) and the NIS sum in the 99.9 %
    # interval of a chi-square with the total degrees of freedom.
    scenario = dataclasses.replace(XIAN_BAOJI, duration_s=90.0)
    nees, nis, dof, lag = [], [], [], []
    for seed in range(8):
        r = run_scenario(scenario, level="measurement", seed=seed, coupling="tight")
        nees.append(r.nees()[1:])
        a, b = r.nis()
        nis.append(a)
        dof.append(b)
        lag.append(_lag1_pairs(r))
    # Whiteness from each satellite's normalised innovations, m ~ 6000 pairs.
    assert_filter_consistent(np.concatenate(nees), np.concatenate(nis).sum(), np.concatenate(dof).sum(),
                             *np.concatenate(lag, axis=1))


def test_filter_is_consistent_under_the_common_orbit_shift():
    # Table 6's [E, E, E] read as one shift of every satellite (E = 60 m, the
    # largest case): the filter then carries three shared orbit-error states.
    # The shift is nearly unobservable (it acts as a receiver displacement), so
    # the position error stays near its prior (89 m over these runs) and
    # consistency is the claim: NEES within [0.5, 2] x 6 (issue 6; 0.96 x 6
    # measured; the same seeds with independent per-satellite orbit states
    # give 3.8 x 6, as the shift then looks re-drawn with every new satellite),
    # NIS sum and whiteness as in the independent case (0.988 per dof and
    # lag-1 0.009 measured, against a 99.9 % interval of 0.943-1.059 and a
    # 4 / sqrt(m) = 0.050 bound).
    leo = dataclasses.replace(XIAN_BAOJI.leo, orbit_error_m=60.0, orbit_error_model="common")
    scenario = dataclasses.replace(XIAN_BAOJI, duration_s=90.0, leo=leo)
    nees, nis, dof, lag = [], [], [], []
    for seed in range(8):
        r = run_scenario(scenario, level="measurement", seed=seed, coupling="tight")
        nees.append(r.nees()[1:])
        a, b = r.nis()
        nis.append(a)
        dof.append(b)
        lag.append(_lag1_pairs(r))
    assert_filter_consistent(np.concatenate(nees), np.concatenate(nis).sum(), np.concatenate(dof).sum(),
                             *np.concatenate(lag, axis=1))


def test_tight_is_no_worse_than_loose_on_the_same_measurements():
    # Same seeds, same Doppler. Both filters model the satellites' offsets and
    # orbit errors; tight uses every Doppler, loose the fix (7 of the m values
    # per epoch), so tight cannot be worse in expectation (782 s, 20 seeds:
    # 1.76 vs 2.17 m). Over 4 seeds x 120 s (errors after 60 s: tight 2.0 m,
    # loose 2.1 m measured) a 20 % allowance covers the spread of so few runs.
    scenario = dataclasses.replace(XIAN_BAOJI, duration_s=120.0)
    err = {c: np.mean([run_scenario(scenario, level="measurement", seed=s, coupling=c).errors()["fused"][0][60:].mean()
                       for s in range(4)]) for c in ("loose", "tight")}
    assert err["tight"] < 1.2 * err["loose"]
