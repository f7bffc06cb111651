"""``leosop position`` end to end: simulate a table from element sets (with light time), recover the site."""

import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.constants import C_MPS
from leosop.frames import azimuth_elevation_range, ecef_to_geodetic, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef
from leosop.positioning.measurements import Measurements, sv_states_from_tle, write_measurements

SITE = (34.342, 108.940, 30.0)
F0_HZ = 11.325e9


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """3 epochs of the bundled constellation over Xi'an, 1 Hz noise, 5 Hz receiver offset."""
    const = load_constellation()
    t = np.datetime64("2025-01-01T04:00:00", "ns") + np.arange(3).astype("timedelta64[s]")
    pos, _, _ = state_ecef(const, t)
    rx = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    _, el, _ = azimuth_elevation_range(pos, rx)
    si, ti = np.nonzero(el > np.radians(25))
    ids, tt = const.sat_ids[si], t[ti]
    p, v, _ = sv_states_from_tle(const, ids, tt, rx)
    rate = np.einsum("ni,ni->n", p - rx, v) / np.linalg.norm(p - rx, axis=1)
    rng = np.random.default_rng(3)
    dop = -rate * F0_HZ / C_MPS + 5.0 + rng.normal(0.0, 1.0, len(rate))
    n = len(dop)
    path = tmp_path_factory.mktemp("cli") / "meas.csv"
    write_measurements(path, Measurements(t_s=np.zeros(n), time_utc=tt, sat_id=ids, doppler_hz=dop,
                                          sigma_hz=np.full(n, 1.0), carrier_hz=np.full(n, F0_HZ), line=np.arange(n)))
    return path, rx


def _run(capsys, *argv):
    status = main(["position", *map(str, argv), "--json"])
    out, err = capsys.readouterr()
    return status, (json.loads(out) if status == 0 else None), err


def test_snapshot_fixes_recover_site(capsys, table):
    path, rx = table
    status, doc, _ = _run(capsys, path)
    assert status == 0 and len(doc["solutions"]) == 3
    for s in doc["solutions"]:
        err = np.linalg.norm(np.array([s["x_m"], s["y_m"], s["z_m"]]) - rx)
        # 1 Hz noise, GDOP ~3.7 in mixed units: posterior sigma ~2-3 m per axis; 5 sigma bound.
        assert err < 5 * np.linalg.norm(s["sigma_enu_m"])
        assert abs(s["clock_offset_hz"] - 5.0) < 2.0  # posterior sigma ~0.4 Hz
        assert s["status"] == "ok" and s["n_used"] == s["n_sats"] >= 7
    assert set(doc["solutions"][0]) >= {"t_s", "time_utc", "lat_deg", "lon_deg", "alt_m", "x_m", "y_m", "z_m",
                                        "vx_mps", "vy_mps", "vz_mps", "clock_offset_hz", "gdop", "n_sats",
                                        "n_used", "iterations", "residual_rms_hz"}


def test_static_with_altitude_and_far_init(capsys, table, tmp_path):
    path, rx = table
    lat, lon, _ = ecef_to_geodetic(rx)
    init = f"{np.degrees(lat) + 9.0},{np.degrees(lon)},0"  # ~1,000 km north
    status, doc, _ = _run(capsys, path, "--static", "--alt-m", SITE[2], "--init", init, "--out", tmp_path)
    assert status == 0
    s = doc["solutions"][0]
    # ~80 measurements at 1 Hz: posterior sigma well below 1 m; 5 m covers 5 sigma.
    assert np.linalg.norm(np.array([s["x_m"], s["y_m"], s["z_m"]]) - rx) < 5.0
    assert abs(s["alt_m"] - SITE[2]) < 1.0
    assert (tmp_path / "fixes.csv").is_file() and (tmp_path / "residuals.csv").is_file()


def test_bad_rows_reported_and_rest_solved(capsys, table, tmp_path):
    path, rx = table
    lines = path.read_text().splitlines()
    t_first = lines[1].split(",")[0]
    bad = lines + [f"{t_first},99999,100.0,1.0,{F0_HZ}", lines[2], lines[3].replace(lines[3].split(",")[2], "nan")]
    bad_path = tmp_path / "bad.csv"
    bad_path.write_text("\n".join(bad) + "\n")
    status, doc, err = _run(capsys, bad_path)
    assert status == 0 and len(doc["solutions"]) == 3
    reasons = [r["reason"] for r in doc["rejected"]]
    assert any("99999" in r for r in reasons) and any("duplicate" in r for r in reasons)
    assert any("doppler_hz" in r for r in reasons)
    assert "warning" in err


def test_too_few_satellites_is_exit_2(capsys, tmp_path):
    path = tmp_path / "few.csv"
    path.write_text("time_utc,sat_id,doppler_hz\n" + "".join(
        f"2025-01-01T04:00:00Z,{70001 + k},{1000.0 * k}\n" for k in range(5)))
    status, _, err = _run(capsys, path)
    assert status == 2 and "fewer than 7 usable satellites" in err


@pytest.mark.parametrize("argv, message", [
    (["--alt-m", "10"], "--alt-m constrains a static fix"),
    (["--init", "north"], "--init"),
    (["--tle", "/nonexistent.tle"], "no such TLE file"),
])
def test_bad_options_are_exit_2(capsys, table, argv, message):
    path, _ = table
    status, _, err = _run(capsys, path, *argv)
    assert status == 2 and message in err


@pytest.mark.parametrize("path, message", [
    ("/nonexistent.csv", "no such measurement file"),
    ("/dev/null", "not a regular file (a device, pipe or socket), expected a measurement file"),
    ("/", "is a directory, expected a measurement file"),
])
def test_measurement_path_that_is_no_file_says_what_it_is(capsys, path, message):
    status, _, err = _run(capsys, path)
    assert status == 2 and message in err


def test_static_with_pass_id_column_solves_passes_jointly(capsys, tmp_path):
    """Two VHF passes (satellite states in the table), each with its own transmitter offset."""
    f0 = 145.87e6
    const = load_constellation().subset([0])
    rx = geodetic_to_ecef(np.radians(52.0), np.radians(4.37), 95.0)
    t = np.datetime64("2025-01-01T00:00:00", "ns") + np.arange(0, 86400, 4).astype("timedelta64[s]")
    pos, vel, _ = state_ecef(const, t)
    _, el, _ = azimuth_elevation_range(pos[0], rx)
    k = np.flatnonzero(el > np.radians(10))
    pass_id = np.concatenate([[0], np.cumsum(np.diff(k) > 1)])
    k, pass_id = k[pass_id < 2], pass_id[pass_id < 2]
    rate = np.einsum("ni,ni->n", pos[0, k] - rx, vel[0, k]) / np.linalg.norm(pos[0, k] - rx, axis=1)
    dop = -rate * f0 / C_MPS + np.array([-300.0, 200.0])[pass_id] + np.random.default_rng(2).normal(0, 1.0, len(k))
    n = len(k)
    path = tmp_path / "passes.csv"
    write_measurements(path, Measurements(
        t_s=np.zeros(n), time_utc=t[k], sat_id=np.full(n, "1"), doppler_hz=dop, sigma_hz=np.full(n, 1.0),
        carrier_hz=np.full(n, f0), pos_sv_ecef_m=pos[0, k], vel_sv_ecef_mps=vel[0, k], line=np.arange(n),
        pass_id=np.array(["a", "b"])[pass_id]))
    status, doc, _ = _run(capsys, path, "--static", "--alt-m", 95.0, "--alt-sigma-m", 1.0)
    assert status == 0
    s = doc["solutions"][0]
    # Two passes: solved from every row, but too few for the toolkit to vouch for the fix (each pass's
    # element-set error is seen only in the passes' disagreement; leosop.positioning.quality).
    assert s["status"] == "few_passes" and s["n_used"] == n and s["chi2_p"] > 1e-3
    assert [p["pass_id"] for p in doc["passes"]] == ["a", "b"]
    # Each pass's offset near its truth: ~0.1 Hz sigma for ~100 rows of 1 Hz with the clock alone; the
    # per-pass time offsets (on by default) share the offset's information near closest approach (the
    # Doppler rate column), achieved 0.06 and 0.59 Hz; bound 1.5 Hz. The position within 5 of its posterior
    # horizontal sigmas (constant clocks fitted by cubics).
    np.testing.assert_allclose([p["clock_poly_hz"][0] for p in doc["passes"]], [-300.0, 200.0], atol=1.5)
    err = np.linalg.norm(geodetic_to_ecef(np.radians(s["lat_deg"]), np.radians(s["lon_deg"]), s["alt_m"]) - rx)
    assert err < 5 * np.linalg.norm(s["sigma_enu_m"])


def test_static_passes_too_short_for_their_terms_is_exit_2_naming_the_table(capsys, table, tmp_path):
    """3 epochs a satellite, each its own pass: shorter than a pass's cubic clock and time offset (it crashed)."""
    path, _ = table
    rows = path.read_text().splitlines()
    col = rows[0].split(",").index("sat_id")
    short = tmp_path / "short.csv"
    short.write_text("\n".join([rows[0] + ",pass_id"] + [r + "," + r.split(",")[col] for r in rows[1:]]) + "\n")
    status, _, err = _run(capsys, short, "--static")
    assert status == 2 and err.count("\n") == 1
    assert f"{short}: no pass has the 5 usable rows its own terms need (the most: 3)" in err and "--clock" in err
    status, doc, _ = _run(capsys, short, "--static", "--clock", "common")  # one receiver clock: solvable
    assert status == 0 and doc["solutions"][0]["n_used"] == len(rows) - 1


def test_static_summary_counts_measurements_and_satellites(capsys, table):
    # A static fix uses every row: the human summary says how many rows of how many satellites
    # (it used to print "80/27 sats", rows over satellites).
    path, _ = table
    assert main(["position", str(path), "--static", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)["solutions"][0]
    assert main(["position", str(path), "--static"]) == 0
    out = capsys.readouterr().out
    assert f"{s['n_used']} measurements of {s['n_sats']} sats" in out and s["n_used"] > s["n_sats"]


def test_format_fll_reads_a_gnu_radio_log_and_needs_the_satellite(capsys, tmp_path):
    # A synthetic FLL log in the GNU Radio format (index, doppler_offset, timestamp,
    # measured_freq), carrier 145.88 MHz; the real FOX-1D log is read in test_position_realdata.
    log = tmp_path / "fll.csv"
    log.write_text("index,doppler_offset,timestamp,measured_freq\n"
                   "0,2240.5,2018-01-13T16:12:01.862011Z,145882240.5\n"
                   "1,2239.0,2018-01-13T16:12:01.962011Z,145882239.0\n")
    from leosop.positioning.datasets import read_fll

    meas = read_fll(log, "43137")
    np.testing.assert_allclose(meas.carrier_hz, 145.88e6)
    np.testing.assert_allclose(meas.doppler_hz, [2240.5, 2239.0])
    np.testing.assert_allclose(meas.t_s, [0.0, 0.1], atol=1e-9)
    assert main(["position", str(log), "--format", "fll"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--sat-id" in err
    bad = tmp_path / "bad.csv"
    bad.write_text("index,doppler_offset,timestamp\n0,1.0,2018-01-13T16:12:01Z\n")
    assert main(["position", str(bad), "--format", "fll", "--sat-id", "43137"]) == 2
    assert "measured_freq" in capsys.readouterr().err


def test_format_doptrack_names_the_missing_archive(capsys, tmp_path):
    assert main(["position", str(tmp_path), "--format", "doptrack", "--static"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "data.tar.xz" in err
