"""Tight INS/Doppler coupling of simulate (the engine with LEO Doppler aids): the old loop's results, consistency.

The aid's rows are checked against finite differences in tests/fusion/test_aids_leo.py.
"""

import dataclasses

import numpy as np
import pytest

from leosop.apps.scenarios import XIAN_BAOJI
from leosop.apps.simulate import run_scenario

from tests.helpers import assert_filter_consistent

# The tight filter's own loop (fusion/tight.run, until issue 21) on these runs, seed 0, measurement level:
# mean, max and last 3D position error [m], mean velocity error [m/s], NIS sum, its dof, updates and
# the last position sigma [m] (trace of the ENU covariance).
OLD_LOOP = {
    (60.0, 1.0): (4.265468520541924, 8.220748712653846, 2.3596958701519624, 0.048229399128967176, 520.4760516190072,
                  559, 60, 3.8303919939819107),
    (120.0, 30.0): (54.28798992770421, 223.29995224896155, 3.2970938386132054, 0.47506884383154424, 25.6819094118894,
                    32, 4, 5.486933859937983),
}


@pytest.mark.parametrize("duration_s, correction_period_s", list(OLD_LOOP))
def test_engine_gives_the_old_tight_loop_results(duration_s, correction_period_s):
    # The engine takes the Doppler of an epoch one at a time, each linearised about the INS the
    # previous one corrected, where the old loop took them as one batch about the epoch's prior:
    # the same update to first order, not to rounding. Measured differences: 0.055 m (1 s
    # corrections) and 0.11 m (30 s) at worst along the track, against a position sigma of 3.8 and
    # 5.5 m; NIS sums 0.14 and 0.08 apart. Tolerances: 0.1 m on the mean and max (0.15 m on the
    # last epoch, 3 % of sigma), 0.5 on the NIS sum (0.1 % and 2 % of it), the update count and
    # dof exactly (the same Doppler pass the gate, the same epochs are correction epochs), the
    # covariance to 1e-4 relative (measured 4e-5).
    sc = dataclasses.replace(XIAN_BAOJI, duration_s=duration_s)
    r = run_scenario(sc, level="measurement", seed=0, coupling="tight", correction_period_s=correction_period_s)
    mean, worst, last, vel, nis, dof, n_upd, sigma = OLD_LOOP[duration_s, correction_period_s]
    e, ev = r.errors()["fused"]
    assert e[1:].mean() == pytest.approx(mean, abs=0.1) and e[1:].max() == pytest.approx(worst, abs=0.1)
    assert e[-1] == pytest.approx(last, abs=0.15) and ev[1:].mean() == pytest.approx(vel, abs=2e-3)
    a, b = r.nis()
    assert a.sum() == pytest.approx(nis, abs=0.5) and b.sum() == dof and r.fused.updated.sum() == n_upd
    cov = r.fused.pos_vel_cov_enu()[-1, 3:, 3:]
    assert np.sqrt(np.trace(cov)) == pytest.approx(sigma, rel=1e-4)


def _lag1_pairs(result):
    """Each satellite's normalised Doppler innovations at consecutive epochs, (2, m)."""
    d = np.sort(result.fused.doppler_innovation, order=("sat", "epoch"))
    nxt = (d["sat"][1:] == d["sat"][:-1]) & (d["epoch"][1:] == d["epoch"][:-1] + 1)
    return np.stack([d["normalized"][:-1][nxt], d["normalized"][1:][nxt]])


def _assert_tight_consistent(scenario, seeds=range(8)):
    """NEES, NIS sum and lag-1 whiteness of the tight filter over ``seeds`` measurement-level runs."""
    nees, nis, dof, lag = [], [], [], []
    for seed in seeds:
        r = run_scenario(scenario, level="measurement", seed=seed, coupling="tight")
        nees.append(r.nees()[1:])
        a, b = r.nis()
        nis.append(a)
        dof.append(b)
        lag.append(_lag1_pairs(r))
    assert_filter_consistent(np.concatenate(nees), np.concatenate(nis).sum(), np.concatenate(dof).sum(),
                             *np.concatenate(lag, axis=1))


def test_filter_is_consistent_on_short_flights():
    # Measurement-level Doppler with the Table 1 satellite offsets and orbit
    # errors, which the tight filter models: NEES of position and velocity
    # within [0.5, 2] of its dimension (issue 6) and the NIS sum in the 99.9 %
    # interval of a chi-square with the total degrees of freedom.
    scenario = dataclasses.replace(XIAN_BAOJI, duration_s=90.0)
    # Whiteness from each satellite's normalised innovations, m ~ 6000 pairs.
    _assert_tight_consistent(scenario)


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
    _assert_tight_consistent(scenario)


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
