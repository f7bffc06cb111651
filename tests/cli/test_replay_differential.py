"""``leosop generate --base-site`` and ``leosop replay --base``: a differential fix from signal, end to end.

The generator writes a base/rover pair with the same satellite errors; the
receiver gets the samples, the element sets (without those errors) and the
base's site. Truth: the rover's site given to the generator.
"""

import json
import os
from types import SimpleNamespace

import numpy as np
import pytest

from leosop.cli import main
from leosop.errors import InputError
from leosop.frames import azimuth_elevation_range, geodetic_to_ecef
from leosop.orbits import DEFAULT_TLE, load_constellation, read_tle
from leosop.orbits.propagate import state_ecef
from leosop.replay.differential import differential_fix
from leosop.replay.tracks import Track

ROVER = (34.342, 108.940, 400.0)  # Xi'an, the bundled scenario's start
BASE = (34.300, 108.900, 420.0)  # 5.9 km south-west of the rover
START = "2025-01-01T19:40:00Z"
#: Orbit errors of the size the differential solver's priors assume (positioning/differential.py), a
#: satellite oscillator drift of 0.01 Hz/s (positioning/differential_sim.py's default).
ERRORS = ("--orbit-error-along-m", "300", "--orbit-error-radial-m", "30", "--orbit-error-cross-m", "100",
          "--sat-drift-sigma-hz-per-s", "0.01")
#: The differential fix from 10 snapshots of 20 ms: the single differences' noise (~0.5 Hz per row at
#: ~42 dB-Hz, sigma E/N/U of a few metres) and the orbit errors' residual at 6 km (~1/100 of their
#: Doppler effect); 15 m is several sigmas. The rover alone errs by ~100 m here (orbit errors).
DIFF_TOL_M = 15.0


def _ecef(site):
    return geodetic_to_ecef(np.radians(site[0]), np.radians(site[1]), site[2])


def _sky_tle(path):
    """The bundled Walker set's satellites above the horizon at the start (a fifth of it: identification and
    reading the file are what take time; the others are no candidates anyway)."""
    const = read_tle(DEFAULT_TLE)
    pos, _, _ = state_ecef(const, np.array([np.datetime64(START[:-1], "ns")]))
    _, elev, _ = azimuth_elevation_range(pos[:, 0], _ecef(ROVER))
    keep = set(const.sat_ids[elev > 0].tolist())
    lines = DEFAULT_TLE.read_text().splitlines()
    path.write_text("\n".join(line for k in range(0, len(lines), 3) if lines[k + 1][2:7] in keep
                             for line in lines[k:k + 3]) + "\n")
    return path


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """10 snapshots of 20 ms, 1 s apart at 1 MS/s; the base's captures 0.5 s after the rover's."""
    d = tmp_path_factory.mktemp("pair")
    rover = d / "rover.sigmf-meta"
    tle = _sky_tle(d / "sky.tle")
    argv = ["generate", "-o", str(rover), "--tle", str(tle), "--site", ",".join(map(str, ROVER)), "--start", START,
            "--seed", "5", "--sample-rate-hz", "1e6",
            "--duration-s", "10", "--snapshot-s", "0.02", "--period-s", "1", "--mask-deg", "40",
            "--base-site", ",".join(map(str, BASE)), "--base-offset-s", "0.5", *ERRORS, "--out", str(d)]
    assert main(argv) == 0
    return rover, d / "rover-base.sigmf-meta", json.loads((d / "generate.json").read_text()), tle


def _replay(capsys, *argv):
    capsys.readouterr()
    code = main(["replay", *argv, "--json"])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else None), out.err


def test_pair_shares_satellite_errors(pair):
    """Same satellites, same orbit errors, oscillator offsets and drifts; the receivers' clocks differ."""
    rover, base, doc, _ = pair
    meta = [json.loads(p.read_text())["global"] for p in (rover, base)]
    sats = [m["leosop:satellites"] for m in meta]
    assert [s["sat_id"] for s in sats[0]] == [s["sat_id"] for s in sats[1]]
    for key in ("orbit_error_along_m", "orbit_error_radial_m", "orbit_error_cross_m", "sat_offset_hz",
                "sat_drift_hz_per_s", "tx_phase_rad", "range_ref_m"):
        assert [s[key] for s in sats[0]] == [s[key] for s in sats[1]], key
    assert any(s["sat_drift_hz_per_s"] != 0.0 for s in sats[0])
    # Each receiver's clock: satellite offset (drifted to its first sample) plus its own receiver offset.
    for s, rx, t0 in ((sats[0], meta[0]["leosop:rx_offset_hz"], 0.0), (sats[1], meta[1]["leosop:rx_offset_hz"], 0.5)):
        got = np.array([v["clock_offset_hz"] for v in s])
        want = np.array([v["sat_offset_hz"] + v["sat_drift_hz_per_s"] * t0 for v in s]) + rx
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert meta[0]["leosop:rx_offset_hz"] != meta[1]["leosop:rx_offset_hz"]
    # one transmitter per satellite, one LO per receiver: the rover's LO phase is the reference
    assert meta[0]["leosop:lo_phase_rad"] == 0.0 and 0.0 < meta[1]["leosop:lo_phase_rad"] < 2 * np.pi
    assert doc["base"]["lo_phase_rad"] == meta[1]["leosop:lo_phase_rad"]
    assert meta[1]["core:geolocation"]["coordinates"] == [BASE[1], BASE[0], BASE[2]]
    assert doc["base"]["start_utc"] == "2025-01-01T19:40:00.500000Z"


def test_rover_samples_do_not_depend_on_the_base(tmp_path):
    """The base draws from its own stream and takes the rover's satellite phases: the rover's samples are those
    written without ``--base-site``, bit for bit."""
    argv = ["generate", "--site", ",".join(map(str, ROVER)), "--start", START, "--duration-s", "0.02",
            "--truth-step-s", "0.02", "--sample-rate-hz", "1e6", "--sat", "71607", "--seed", "2", *ERRORS]
    assert main([*argv, "-o", str(tmp_path / "alone.sigmf-meta")]) == 0
    assert main([*argv, "-o", str(tmp_path / "rover.sigmf-meta"), "--base-site", ",".join(map(str, BASE))]) == 0
    data = [(tmp_path / f"{name}.sigmf-data").read_bytes() for name in ("alone", "rover", "rover-base")]
    assert data[0] == data[1] and data[2] != data[1]


def test_differential_fix_from_signal(pair, capsys, tmp_path):
    rover, base, _, _ = pair
    code, doc, err = _replay(capsys, str(rover), "--base", str(base), "--base-site", ",".join(map(str, BASE)),
                             "--tle", str(pair[3]), "--init", "34.3,108.9,0", "--static",
                             "--out", str(tmp_path / "out"))
    assert code == 0, err
    d = doc["differential"]
    assert d["n_common"] >= 7 and d["base_only"] == [] and d["rover_only"] == []
    (sol,), (alone,) = doc["solutions"], doc["solutions_alone"]
    assert set(alone) <= set(sol)  # the keys of replay's fix, and more
    truth = _ecef(ROVER)
    err_diff = np.linalg.norm(np.array([sol["x_m"], sol["y_m"], sol["z_m"]]) - truth)
    err_alone = np.linalg.norm(np.array([alone["x_m"], alone["y_m"], alone["z_m"]]) - truth)
    assert err_diff < DIFF_TOL_M and err_diff < err_alone / 3, (err_diff, err_alone)
    for name in ("replay.json", "fixes.csv", "measurements.csv", "base_measurements.csv"):
        assert (tmp_path / "out" / name).is_file()


def _variant(tmp_path, meta_path, edit):
    """A copy of a recording's metadata, edited, beside a link to its samples."""
    meta = json.loads(meta_path.read_text())
    edit(meta)
    new = tmp_path / "variant.sigmf-meta"
    new.write_text(json.dumps(meta))
    os.symlink(meta_path.with_suffix(".sigmf-data"), new.with_suffix(".sigmf-data"))
    return new


@pytest.mark.parametrize("what, edit, message", [
    ("band", lambda m: [c.update({"core:frequency": c["core:frequency"] + 1e6}) for c in m["captures"]],
     "different bands"),
    ("day", lambda m: [c.update({"core:datetime": "2025-01-02" + c["core:datetime"][10:]}) for c in m["captures"]],
     "different days"),
])
def test_pair_refused(pair, capsys, tmp_path, what, edit, message):
    rover, base, _, _ = pair
    code, _, err = _replay(capsys, str(rover), "--base", str(_variant(tmp_path, base, edit)),
                           "--base-site", ",".join(map(str, BASE)))
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, (what, err)


def test_base_without_site(pair, capsys):
    rover, base, _, _ = pair
    code, _, err = _replay(capsys, str(rover), "--base", str(base))
    assert code == 2 and "--base-site" in err


def test_no_satellite_in_common(pair):
    """Tracks identified as different satellites: a one-line InputError naming both sets."""
    t = np.datetime64("2025-01-01T19:40:00", "ns") + np.arange(3) * np.timedelta64(1, "s")
    ones = np.ones(3)

    def result(sat_id):
        return SimpleNamespace(tracks=[Track(np.arange(3.0), t, 1e3 * ones, ones, 40 * ones, ones, sat_id=sat_id)],
                               identification=None)

    with pytest.raises(InputError, match="no satellite in common.*70002.*70524"):
        differential_fix(result("70002"), result("70524"), load_constellation(pair[3]), _ecef(BASE),
                         carrier_hz=11.325e9)
