"""The status of a fix (leosop.positioning.quality), its summaries, and all-or-nothing ``--out`` sets."""

import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.cli.position import summary as position_summary
from leosop.cli.replay import summary as replay_summary
from leosop.constants import C_MPS
from leosop.frames import azimuth_elevation_range, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef
from leosop.positioning.measurements import Measurements, sv_states_from_tle, write_measurements
from leosop.positioning.quality import ALT_MAX_M, ALT_MIN_M, SPEED_MAX_MPS, fix_status
from leosop.positioning.robust_ls import FixStatus

from tests.helpers import REPO_ROOT

SITE = (34.342, 108.940, 400.0)
F0_HZ = 11.325e9
OK, NC, INC = int(FixStatus.OK), int(FixStatus.NOT_CONVERGED), int(FixStatus.INCONSISTENT)


@pytest.mark.parametrize("solver, dof, chi2, alt, speed, ambiguous, passes, expected", [
    (OK, 3, 2.0, 400.0, 10.0, False, None, "ok"),
    (NC, 3, 2.0, np.nan, np.nan, False, None, "not_converged"),
    (OK, 0, 8e-11, 17229.0, 309.0, False, None, "no_redundancy"),  # the bundled recording's 7-for-7 fix
    (OK, 2, 20.0, 400.0, 10.0, False, None, "inconsistent"),       # p = exp(-10) = 4.5e-5 < 1e-3
    (INC, 5, 40.0, 400.0, 10.0, False, None, "inconsistent"),
    (OK, 2, 1.0, -5215.7, 42.6, False, None, "implausible_height"),  # the bundled recording's underground fix
    (OK, 2, 1.0, ALT_MIN_M - 1.0, 0.0, False, None, "implausible_height"),
    (OK, 2, 1.0, ALT_MAX_M + 1.0, 0.0, False, None, "implausible_height"),
    (OK, 2, 1.0, ALT_MAX_M, SPEED_MAX_MPS + 1.0, False, None, "implausible_velocity"),
    (OK, 200, 190.0, 95.0, None, True, 1, "ambiguous"),
    (OK, 3000, 3100.0, 610.0, None, False, 1, "single_pass"),  # FOX-1D's one pass
    (OK, 1700, 1000.0, 95.0, None, False, 2, "few_passes"),  # a DopTrack day of two passes
    (OK, 2200, 1300.0, 95.0, None, False, 3, "ok"),
])
def test_each_status_from_its_condition(solver, dof, chi2, alt, speed, ambiguous, passes, expected):
    (label,), (p,) = fix_status([solver], [dof], [chi2], [alt], None if speed is None else [speed],
                                ambiguous=ambiguous, n_passes=passes)
    assert label == expected
    if dof == 2:
        # Closed form of the chi-square survival function with 2 degrees of freedom: exp(-chi2 / 2).
        assert p == pytest.approx(np.exp(-chi2 / 2.0), rel=1e-12)
    assert np.isnan(p) == (dof < 1)


def test_significance_of_the_residual_test_is_the_callers():
    # p = exp(-3) = 0.050: rejected at 0.1, accepted at the default 1e-3.
    assert fix_status([OK], [2], [6.0], [0.0], alpha=0.1)[0][0] == "inconsistent"
    assert fix_status([OK], [2], [6.0], [0.0])[0][0] == "ok"


def _snapshot_table(path, n_sats, seed=1):
    """One epoch over Xi'an: the first ``n_sats`` satellites above 25 deg, noise 1 Hz (sigma 1 Hz), offset 5 Hz."""
    const = load_constellation()
    t = np.datetime64("2025-01-01T04:00:00", "ns")
    pos, _, _ = state_ecef(const, t[None])
    rx = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    _, el, _ = azimuth_elevation_range(pos[:, 0], rx)
    ids = const.sat_ids[np.flatnonzero(el > np.radians(25))[:n_sats]]
    assert len(ids) == n_sats
    tt = np.full(n_sats, t)
    p, v, _ = sv_states_from_tle(const, ids, tt, rx)
    rate = np.einsum("ni,ni->n", p - rx, v) / np.linalg.norm(p - rx, axis=1)
    dop = -rate * F0_HZ / C_MPS + 5.0 + np.random.default_rng(seed).normal(0.0, 1.0, n_sats)
    write_measurements(path, Measurements(t_s=np.zeros(n_sats), time_utc=tt, sat_id=ids, doppler_hz=dop,
                                          sigma_hz=np.ones(n_sats), carrier_hz=np.full(n_sats, F0_HZ),
                                          line=np.arange(n_sats)))
    return rx


@pytest.mark.parametrize("n_sats, expected", [(7, "no_redundancy"), (12, "ok")])
def test_seven_satellites_for_seven_unknowns_is_no_redundancy(capsys, tmp_path, n_sats, expected):
    rx = _snapshot_table(tmp_path / "meas.csv", n_sats)
    init = f"{SITE[0]},{SITE[1]},{SITE[2]}"
    assert main(["position", str(tmp_path / "meas.csv"), "--init", init, "--json"]) == 0
    (s,) = json.loads(capsys.readouterr().out)["solutions"]
    assert s["status"] == expected and s["dof"] == n_sats - 7
    if n_sats == 7:
        # Seven unknowns from seven Dopplers: the residuals vanish whatever the noise (no test possible).
        assert s["residual_rms_hz"] < 1e-6 and s["chi2_p"] is None
    else:
        # 1 Hz noise at 1 Hz sigma: the fix passes its test and lies within 4 sigma per axis of the site.
        from leosop.frames import C_e_n

        enu = C_e_n(np.radians(SITE[0]), np.radians(SITE[1])).T @ (np.array([s["x_m"], s["y_m"], s["z_m"]]) - rx)
        assert 1e-3 < s["chi2_p"] <= 1.0 and np.all(np.abs(enu) < 4.0 * np.array(s["sigma_enu_m"]))


def _null_fix(status):
    keys = ("lat_deg", "lon_deg", "alt_m", "x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps", "clock_offset_hz",
            "gdop", "residual_rms_hz", "chi2_p")
    return {**dict.fromkeys(keys), "t_s": 20.0, "time_utc": "2025-01-01T19:40:20Z", "n_sats": 7, "n_used": 7,
            "iterations": 50, "dof": 0, "status": status, "sigma_enu_m": [None] * 3}


def test_summaries_print_a_fix_without_a_solution_and_count_the_statuses():
    # The bundled recording's per-block replay has a not-converged fix (JSON nulls): its summary used to
    # stop with "unsupported format string passed to NoneType".
    ok = {**_null_fix("ok"), "lat_deg": 34.3, "lon_deg": 108.9, "alt_m": 400.0, "sigma_enu_m": [1.0, 2.0, 3.0]}
    solutions = [_null_fix("not_converged"), ok, _null_fix("no_redundancy")]
    text = replay_summary({"tracks": [], "n_blocks": 30, "n_identified": 0, "solutions": solutions,
                           "lo_offset_hz": None})
    assert "n/a n/a n/a m" in text and "not_converged" in text
    assert text.splitlines()[-1] == "1 of 3 fix(es) ok (1 not_converged, 1 no_redundancy)"
    text = position_summary({"solutions": solutions, "unsolved": [], "rejected": [], "mode": "snapshot"})
    assert "1 of 3 fix(es) ok (1 not_converged, 1 no_redundancy)" in text.splitlines()[-1]


@pytest.mark.parametrize("in_the_way", ["position.json", "fixes.csv", "residuals.csv"])
def test_position_out_is_all_or_nothing(capsys, tmp_path, in_the_way):
    _snapshot_table(tmp_path / "meas.csv", 12)
    out = tmp_path / "out"
    (out / in_the_way).mkdir(parents=True)
    assert main(["position", str(tmp_path / "meas.csv"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert in_the_way in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == [in_the_way]  # nothing else, no staged leftovers
    (out / in_the_way).rmdir()
    assert main(["position", str(tmp_path / "meas.csv"), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["fixes.csv", "position.json", "residuals.csv"]
    header = (out / "fixes.csv").read_text().splitlines()[0].split(",")
    assert {"status", "dof", "chi2_p"} <= set(header)


def test_replay_out_is_all_or_nothing_and_refused_before_the_work(capsys, tmp_path):
    meta = REPO_ROOT / "signals" / "starlink_xian_snapshots.sigmf-meta"
    out = tmp_path / "out"
    (out / "fixes.csv").mkdir(parents=True)
    # The whole replay takes ~30 s; the refusal comes before it (a bound far below that).
    import time

    t0 = time.perf_counter()
    assert main(["replay", str(meta), "--out", str(out)]) == 2
    assert time.perf_counter() - t0 < 5.0
    assert "fixes.csv" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["fixes.csv"]
