"""``leosop position ROVER.csv --base BASE.csv --base-site ...``: tables written by write_measurements from the pair
simulator (truth from frames.range_rate on SGP4 states, independent of the solver's Jacobians)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from leosop.cli import main
from leosop.frames import C_e_n, azimuth_elevation_range, geodetic_to_ecef
from leosop.orbits import DEFAULT_TLE, read_tle
from leosop.orbits.propagate import state_ecef
from leosop.positioning.differential_sim import draw_satellite_errors, simulate_receiver
from leosop.positioning.measurements import write_measurements

LAT_DEG, LON_DEG, ALT_M = 34.3, 108.9, 400.0
#: Noise of each row [Hz]: 0.05 Hz over 7 satellites x 30 s gives a fix sigma of ~0.1-0.2 m.
SIGMA_HZ = 0.05


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """Rover 7.5 km from the base, 7 satellites above 25 deg, 30 s at 1 Hz, no element-set error."""
    const = read_tle(DEFAULT_TLE)
    lat, lon = np.radians(LAT_DEG), np.radians(LON_DEG)
    base = geodetic_to_ecef(lat, lon, ALT_M)
    rover = base + C_e_n(lat, lon) @ np.array([6e3, 4.5e3, 30.0])
    t = const.epochs_utc.max() + np.arange(30).astype("timedelta64[s]")
    pos, _, _ = state_ecef(const, t[[0, -1]])
    _, el, _ = azimuth_elevation_range(pos, base)
    ids = const.sat_ids[np.flatnonzero(el.min(-1) > np.radians(25.0))[:7]]
    rng = np.random.default_rng(5)
    err = draw_satellite_errors(ids, t[0], rng, orbit_sigma_rtn_m=(0.0, 0.0, 0.0))
    b = simulate_receiver(const, err, base, t - np.timedelta64(300, "ms"), rng, sigma_hz=SIGMA_HZ,
                          clock_offset_hz=900.0, clock_drift_hz_per_s=0.4)
    r = simulate_receiver(const, err, rover, t, rng, sigma_hz=SIGMA_HZ, clock_offset_hz=-1.5e3)
    d = tmp_path_factory.mktemp("diff")
    write_measurements(d / "rover.csv", r)
    write_measurements(d / "base.csv", b)
    return d, rover, ids, b


def _run(capsys, *argv):
    status = main(["position", *map(str, argv), "--json"])
    out, err = capsys.readouterr()
    return status, (json.loads(out) if status == 0 else None), err


SITE = f"{LAT_DEG},{LON_DEG},{ALT_M}"


def test_static_fix_and_outputs(capsys, tables, tmp_path):
    """The static fix lands on the rover; outputs as position writes.

    The truth has no element-set error, so only the noise moves the fix: ~0.1 m from 0.05 Hz over 210 rows
    (its sigma also carries the orbit offsets' priors, ~0.8 m); 0.5 m bounds it.
    """
    d, rover, ids, _ = tables
    status, doc, _ = _run(capsys, d / "rover.csv", "--base", d / "base.csv", "--base-site", SITE, "--static",
                          "--out", tmp_path)
    assert status == 0
    (sol,) = doc["solutions"]
    err = np.linalg.norm([sol["x_m"] - rover[0], sol["y_m"] - rover[1], sol["z_m"] - rover[2]])
    sigma_3d = np.linalg.norm(sol["sigma_enu_m"])
    assert err < 0.5 and err < 4 * sigma_3d and sol["status"] == "ok"
    # Rover minus base clock (-1500 - 900 Hz at t0, drift -0.4 Hz/s) at the fix's time; 0.1 Hz bounds it.
    assert sol["clock_drift_hz_per_s"] == pytest.approx(-0.4, abs=0.01)
    dd = doc["differential"]
    assert dd["n_common"] == 7 and sorted(dd["common"]) == sorted(ids) and dd["model"] == "single_difference"
    assert dd["n_unmatched_rows"] == 7  # the rover's last epoch lies after the base's (0.3 s earlier) last row
    assert {p.name for p in tmp_path.iterdir()} == {"position.json", "fixes.csv", "residuals.csv"}
    assert len((tmp_path / "residuals.csv").read_text().splitlines()) == 1 + 7 * 30
    # The joint fit of the same tables agrees within the single-difference fix's sigma.
    status, joint, _ = _run(capsys, d / "rover.csv", "--base", d / "base.csv", "--base-site", SITE, "--static",
                            "--sat-clock-degree", "1")
    (sj,) = joint["solutions"]
    assert np.linalg.norm([sj["x_m"] - sol["x_m"], sj["y_m"] - sol["y_m"], sj["z_m"] - sol["z_m"]]) < sigma_3d


@pytest.mark.parametrize("extra", [(), ("--motion", "constant_velocity", "--sat-clock-degree", "1")])
def test_blocks(capsys, tables, extra):
    """Without --static: one fix per --block-s (at rest, or at a constant velocity: the truth's is zero)."""
    d, rover, _, _ = tables
    status, doc, _ = _run(capsys, d / "rover.csv", "--base", d / "base.csv", "--base-site", SITE, "--block-s", 15,
                          *extra)
    assert status == 0 and doc["mode"] == "blocks" and len(doc["solutions"]) == 2
    for sol in doc["solutions"]:
        assert np.linalg.norm([sol["x_m"] - rover[0], sol["y_m"] - rover[1], sol["z_m"] - rover[2]]) < \
            4 * np.linalg.norm(sol["sigma_enu_m"])
        assert sol["status"] == "ok"


def test_bad_pairs(capsys, tables, tmp_path):
    """One-line errors, exit 2: no --base-site, no satellite in common, another day."""
    d, _, ids, b = tables
    status, _, err = _run(capsys, d / "rover.csv", "--base", d / "base.csv")
    assert status == 2 and "--base-site" in err and len(err.strip().splitlines()) == 1
    write_measurements(tmp_path / "other.csv", b.take(np.flatnonzero(b.sat_id == ids[0])))
    write_measurements(tmp_path / "rover1.csv", b.take(np.flatnonzero(b.sat_id != ids[0])))
    status, _, err = _run(capsys, tmp_path / "rover1.csv", "--base", tmp_path / "other.csv", "--base-site", SITE)
    assert status == 2 and "no satellite in common" in err and len(err.strip().splitlines()) == 1
    write_measurements(tmp_path / "late.csv", replace(b, time_utc=b.time_utc + np.timedelta64(1, "D")))
    status, _, err = _run(capsys, d / "rover.csv", "--base", tmp_path / "late.csv", "--base-site", SITE)
    assert status == 2 and "different days" in err and len(err.strip().splitlines()) == 1
