"""tools/bench_lo_offset.py: the least-variance weighting of the satellites' offsets, on hand-made covariances.

The bench's runs take minutes (recordings generated and replayed); its
weights are checked here against closed forms and a second implementation.
"""

import importlib.util
from types import SimpleNamespace

import numpy as np

from tests.helpers import REPO_ROOT

_spec = importlib.util.spec_from_file_location("bench_lo_offset", REPO_ROOT / "tools" / "bench_lo_offset.py")
bench_lo = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench_lo)

#: Float64 round-off of solving a well-conditioned 4x4 system.
TIGHT = 1e-12


def _fix(cov, n_sat, n_rx=2):
    """The fields the weighting reads: ``[pos (3), receiver polynomial (n_rx), satellite offsets, ...]``."""
    return SimpleNamespace(cov=cov, rx_clock_polys_hz=np.zeros((1, n_rx)), sat_offset_hz=np.zeros(n_sat))


def test_independent_offsets_get_inverse_variance_weights():
    # Receiver term uncorrelated with the satellites' offsets of variances v: minimising
    # c + sum(a^2 v) under sum(a) = 1 gives a = (1 / v) / sum(1 / v), variance c + 1 / sum(1 / v).
    v = np.array([0.25, 1.0, 4.0, 16.0])
    cov = np.diag(np.concatenate([np.ones(3), [2.0, 0.1], v, np.ones(4)]))
    fix = _fix(cov, len(v))
    a = bench_lo._min_variance_weights(fix)
    np.testing.assert_allclose(a, (1 / v) / np.sum(1 / v), rtol=0, atol=TIGHT)
    assert abs(bench_lo._sum_sigma_hz(fix, a) - np.sqrt(2.0 + 1 / np.sum(1 / v))) < TIGHT


def test_correlated_weights_solve_the_constrained_problem():
    # Second implementation: the KKT system of min (e0 + a)^T C (e0 + a), sum(a) = 1, written out whole.
    rng = np.random.default_rng(3)
    n_sat, n_rx = 5, 2
    m = rng.standard_normal((20, 3 + n_rx + 2 * n_sat))
    cov = m.T @ m / 20
    fix = _fix(cov, n_sat, n_rx)
    a = bench_lo._min_variance_weights(fix)
    s = 3 + n_rx + np.arange(n_sat)
    kkt = np.block([[2 * cov[np.ix_(s, s)], -np.ones((n_sat, 1))], [np.ones((1, n_sat)), np.zeros((1, 1))]])
    want = np.linalg.solve(kkt, np.concatenate([-2 * cov[3, s], [1.0]]))[:n_sat]
    np.testing.assert_allclose(a, want, rtol=0, atol=1e-9)
    # No other combination summing to 1 does better, the plain mean included.
    plain = bench_lo._sum_sigma_hz(fix, np.full(n_sat, 1 / n_sat))
    best = bench_lo._sum_sigma_hz(fix, a)
    others = [bench_lo._sum_sigma_hz(fix, a + d - d.mean()) for d in rng.standard_normal((50, n_sat)) * 0.1]
    assert best <= plain and best <= min(others)


def _row(seed, fe, err3d_m, dsig3d_m, d_off_hz, crb_hz, d_drift, sats=20, s_id=20, wrong=0):
    """One run's numbers, as the bench's --rows writes them (only the fields the summary reads)."""
    return {"kind": "snapshot", "fe": fe, "offset_hz": 0.0 if fe == "none" else 620e3,
            "drift_hz_per_s": 0.0 if fe == "none" else 25.0, "tag": "", "search": "init", "seed": seed,
            "err3d_m": err3d_m, "dsig3d_m": dsig3d_m, "d_off_hz": d_off_hz, "crb_hz": crb_hz, "d_drift": d_drift,
            "sats": sats, "s_id": s_id, "wrong": wrong}


def test_summary_over_seeds_against_hand_computed_values(capsys):
    # Two seeds, each impaired run against its own seed's clean twin:
    # ratios 2.0 / 1.0 (median 1.5); RMS ratio sqrt((4^2 + 3^2) / 2) / sqrt((2^2 + 3^2) / 2) = 5 / sqrt(13);
    # sigma ratio sqrt((2^2 + 4^2) / 2) / sqrt((2^2 + 2^2) / 2) = sqrt(10) / 2; NEES ((4/2)^2 + (3/4)^2) / 2;
    # offset z^2 ((0.5 / 0.5)^2 + (1.5 / 0.5)^2) / 2 = 5; one offset of two within 1 Hz, both drifts within 0.05.
    rows = [_row(8, "none", 2.0, 2.0, 0.1, 0.5, 0.0), _row(9, "none", 3.0, 2.0, 0.1, 0.5, 0.0),
            _row(8, "consumer", 4.0, 2.0, 0.5, 0.5, 0.01), _row(9, "consumer", 3.0, 4.0, -1.5, 0.5, -0.04,
                                                                  s_id=19, wrong=1)]
    bench_lo.print_summary(rows)
    lines = capsys.readouterr().out.strip().splitlines()
    head, imp = lines[0].split(), lines[-1].split()
    got = dict(zip(head[5:], imp[5:]))
    assert got["seeds"] == "2" and got["all_id"] == "1" and got["wrong"] == "1"
    # The printed columns carry two decimals.
    for key, want in {"x_med": 1.5, "x_rms": 5 / np.sqrt(13), "xsig_rms": np.sqrt(10) / 2,
                      "nees": (4 + 0.5625) / 2, "off<1Hz": 0.5, "dr<.05": 1.0, "z2_off": 5.0,
                      "rms_off_hz": np.sqrt((0.25 + 2.25) / 2)}.items():
        assert abs(float(got[key]) - want) <= 0.005 + 1e-9, key
