"""``leosop replay`` end to end on generated snapshot recordings.

The generator and the receiver share nothing but the file: the recording's
truth (which satellites, their Doppler) sits in its SigMF annotations, the
receiver gets only the samples, the element sets and a prior position.
"""

import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.frames import geodetic_to_ecef

from tests.helpers import REPO_ROOT

SITE = (34.342, 108.940, 400.0)  # Xi'an, the bundled scenario's start
START = "2025-01-01T19:40:00Z"


def _generate(path, *extra):
    argv = ["generate", "-o", str(path), "--site", ",".join(map(str, SITE)), "--start", START,
            "--sample-rate-hz", "2.5e6", "--seed", "7", *extra]
    assert main(argv) == 0


@pytest.fixture(scope="module")
def snapshot_recording(tmp_path_factory):
    """60 snapshots of 20 ms, 1 s apart, every satellite above 40 deg."""
    path = tmp_path_factory.mktemp("rec") / "snap.sigmf-meta"
    _generate(path, "--duration-s", "60", "--snapshot-s", "0.02", "--period-s", "1", "--mask-deg", "40")
    meta = json.loads(path.read_text())
    truth = {a["leosop:sat_id"] for a in meta["annotations"] if "leosop:sat_id" in a}
    return path, truth


def _replay(capsys, *argv):
    capsys.readouterr()  # drop what came before (e.g. generate's summary)
    code = main(["replay", *argv, "--json"])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else None), out.err


def test_every_track_identified_and_the_fix_near_the_site(snapshot_recording, capsys, tmp_path):
    path, truth = snapshot_recording
    # A prior 100 km off (north-east), as the contract allows.
    init = "34.98,109.71,0"
    code, doc, err = _replay(capsys, str(path), "--init", init, "--static", "--out", str(tmp_path / "out"))
    assert code == 0, err
    ids = [t["sat_id"] for t in doc["tracks"]]
    assert set(ids) == truth and len(ids) == len(truth)  # all heard, all right, none twice
    (sol,) = doc["solutions"]
    pos = np.array([sol["x_m"], sol["y_m"], sol["z_m"]])
    site = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    # The generator's orbits are the TLE's (no orbit error here) and its clocks are
    # constant: a minute of 20 ms snapshots fixes to metres; 100 m leaves room for
    # the receiver clock drift and the time-offset states absorbing geometry.
    assert np.linalg.norm(pos - site) < 100.0
    for name in ("replay.json", "tracks.csv", "measurements.csv", "fixes.csv", "spectrogram.png"):
        assert (tmp_path / "out" / name).is_file()


def test_measurements_csv_reproduces_the_fix_with_leosop_position(snapshot_recording, capsys, tmp_path):
    path, _ = snapshot_recording
    code, doc, err = _replay(capsys, str(path), "--init", "34.98,109.71,0", "--static", "--out", str(tmp_path))
    assert code == 0, err
    capsys.readouterr()
    code = main(["position", str(tmp_path / "measurements.csv"), "--static", "--clock", "common",
                 "--init", "34.98,109.71,0", "--json"])
    pos_doc = json.loads(capsys.readouterr().out)
    assert code == 0
    a, b = doc["solutions"][0], pos_doc["solutions"][0]
    # Same rows, same solver: the same fix up to the CSV's float round trip.
    assert abs(a["x_m"] - b["x_m"]) < 0.01 and abs(a["y_m"] - b["y_m"]) < 0.01 and abs(a["z_m"] - b["z_m"]) < 0.01


def test_snapshot_fixes_carry_the_satellite_offsets_in_their_sigmas(snapshot_recording, capsys):
    # Without --static: one fix per 20 ms snapshot (position, velocity and
    # clock from ~9 Dopplers). The recording's satellites have their own
    # frequency offsets (up to 5 Hz), which one snapshot cannot estimate: the
    # fix adds SAT_OFFSET_SIGMA_HZ to each measurement's sigma. One draw of
    # offsets biases all fixes alike, so |error| / sigma is judged loosely:
    # median per axis below 2.5 (measured 1.3-1.7; 4-5.5 without the offset
    # term, 0.2 on a recording without offsets), horizontal error below 60 m
    # (measured ~35 m; the static fix, which estimates the offsets, ~5 m).
    from leosop.frames import C_e_n

    path, _ = snapshot_recording
    code, doc, err = _replay(capsys, str(path), "--init", "34.98,109.71,0")
    assert code == 0, err
    assert doc["mode"] != "static" and len(doc["solutions"]) >= 50
    site = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    c_enu_ecef = C_e_n(np.radians(SITE[0]), np.radians(SITE[1])).T  # ECEF to the site's ENU
    enu, sig = [], []
    for sol in doc["solutions"]:
        if sol["status"] == "ok":
            enu.append(c_enu_ecef @ (np.array([sol["x_m"], sol["y_m"], sol["z_m"]]) - site))
            sig.append(sol["sigma_enu_m"])
    enu, sig = np.array(enu), np.array(sig)
    assert len(enu) >= 40
    assert np.all(np.median(np.abs(enu) / sig, axis=0) < 2.5)
    assert np.median(np.hypot(enu[:, 0], enu[:, 1])) < 60.0


def test_moving_receiver_identified_and_fixed_per_snapshot(tmp_path, capsys):
    # A car at 20 m/s east: its own motion moves each satellite's Doppler by up to
    # ~750 Hz, differently per satellite. Identification fits one constant velocity,
    # the snapshot fixes estimate position and velocity each. Measured on this
    # recording: all identified, median error (7, 1.4) m east/north with sigmas
    # (19, 3) m, velocity 19.9 m/s east (another draw); the bounds leave room for other draws.
    from leosop.frames import C_e_n

    path = tmp_path / "car.sigmf-meta"
    _generate(path, "--duration-s", "40", "--snapshot-s", "0.02", "--period-s", "1", "--mask-deg", "40",
              "--velocity-enu-mps", "20,0,0")
    meta = json.loads(path.read_text())
    truth = {a["leosop:sat_id"] for a in meta["annotations"] if "leosop:sat_id" in a}
    code, doc, err = _replay(capsys, str(path), "--init", "34.98,109.71,0")
    assert code == 0, err
    ids = [t["sat_id"] for t in doc["tracks"]]
    assert set(ids) == truth and len(ids) == len(truth)
    site = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    c_e_n = C_e_n(np.radians(SITE[0]), np.radians(SITE[1]))
    enu, sig, vel = [], [], []
    for sol in doc["solutions"]:
        if sol["status"] == "ok":
            at = site + c_e_n @ np.array([20.0 * sol["t_s"], 0.0, 0.0])
            enu.append(c_e_n.T @ (np.array([sol["x_m"], sol["y_m"], sol["z_m"]]) - at))
            sig.append(sol["sigma_enu_m"])
            vel.append(c_e_n.T @ np.array([sol["vx_mps"], sol["vy_mps"], sol["vz_mps"]]))
    enu, sig, vel = np.array(enu), np.array(sig), np.array(vel)
    assert len(enu) >= 30
    assert np.median(np.hypot(enu[:, 0], enu[:, 1])) < 40.0
    assert np.all(np.median(np.abs(enu) / sig, axis=0) < 2.5)
    # Velocity: horizontal within 1 m/s; the vertical, which the satellites high overhead
    # observe worst in 20 ms, within 3 m/s (measured 0.06, 0.08, 1.1 m/s off).
    assert np.all(np.abs(np.median(vel, axis=0) - [20.0, 0.0, 0.0]) < [1.0, 1.0, 3.0])


def test_noise_only_recording_gives_empty_tracks_and_exit_0(tmp_path, capsys):
    path = tmp_path / "noise.sigmf-meta"
    _generate(path, "--duration-s", "3", "--snapshot-s", "0.02", "--period-s", "1", "--cn0-dbhz", "-20")
    code, doc, err = _replay(capsys, str(path), "--static")
    assert code == 0 and doc["tracks"] == [] and doc["solutions"] == []
    assert "no pilot comb detected" in err


def test_recording_without_datetime_is_refused(snapshot_recording, tmp_path, capsys):
    path, _ = snapshot_recording
    meta = json.loads(path.read_text())
    for cap in meta["captures"]:
        cap.pop("core:datetime", None)
    bad = tmp_path / "nodate.sigmf-meta"
    bad.write_text(json.dumps(meta))
    (tmp_path / "nodate.sigmf-data").symlink_to(path.with_suffix(".sigmf-data"))
    code, _, err = _replay(capsys, str(bad), "--out", str(tmp_path / "o"))
    assert code == 2 and "core:datetime" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_truncated_recording_is_refused_without_outputs(snapshot_recording, tmp_path, capsys):
    path, _ = snapshot_recording
    data = path.with_suffix(".sigmf-data").read_bytes()
    bad = tmp_path / "cut.sigmf-meta"
    meta = json.loads(path.read_text())
    meta["global"].pop("core:sha512", None)
    bad.write_text(json.dumps(meta))
    (tmp_path / "cut.sigmf-data").write_bytes(data[: len(data) // 2 + 3])
    code, _, err = _replay(capsys, str(bad), "--out", str(tmp_path / "o"))
    assert code == 2 and err.count("\n") == 1
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_modified_recording_is_refused_by_its_checksum_without_outputs(snapshot_recording, tmp_path, capsys):
    # The checksum runs beside the replay (a background thread): a file of the right size whose bytes
    # changed ends in the checksum's one-line refusal, exit 2, no output file, even where the replay
    # stumbles on the change first (a NaN in the first block: fast; the refusal after a whole replay is
    # tests/signal/test_iq.py's).
    path, _ = snapshot_recording
    raw = np.fromfile(path.with_suffix(".sigmf-data"), dtype=np.float32)
    raw[0] = np.nan
    bad = tmp_path / "mod.sigmf-meta"
    bad.write_text(path.read_text())  # core:sha512 kept
    raw.tofile(tmp_path / "mod.sigmf-data")
    code, _, err = _replay(capsys, str(bad), "--static", "--init", "34.98,109.71,0", "--out", str(tmp_path / "o"))
    assert code == 2 and err.count("\n") == 1
    assert "mod.sigmf-data: contents do not match core:sha512 in mod.sigmf-meta" in err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_nan_samples_are_refused_naming_the_file_and_samples(snapshot_recording, tmp_path, capsys):
    # replay reads without a pass over the samples for NaN/inf: one sum of the block shows them.
    path, _ = snapshot_recording
    raw = np.fromfile(path.with_suffix(".sigmf-data"), dtype=np.float32)
    raw[2 * 123_456 + 1] = np.nan  # the imaginary part of sample 123,456 (the third snapshot)
    bad = tmp_path / "nan.sigmf-meta"
    meta = json.loads(path.read_text())
    meta["global"].pop("core:sha512", None)
    bad.write_text(json.dumps(meta))
    raw.tofile(tmp_path / "nan.sigmf-data")
    code, _, err = _replay(capsys, str(bad), "--out", str(tmp_path / "o"))
    assert code == 2 and err.count("\n") == 1
    assert "nan.sigmf-data" in err and "NaN or inf" in err
    lo, hi = (int(v) for v in err.split("samples ")[1].split(" hold")[0].split(".."))
    assert lo <= 123_456 <= hi
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_narrow_keeps_each_tone_with_its_phase_at_the_decimated_times():
    from leosop.replay.stream import narrow

    fs, factor, n = 240e6, 96, 96 * 4000
    t = np.arange(n) / fs
    tones_hz = np.array([-300e3, 12.3e3, 176e3])  # comb edges under LEO Doppler
    # Whole cycles over the block, so the band-limited decimation is exact up to complex64 rounding.
    tones_hz = np.round(tones_hz * n / fs) * fs / n
    x = np.sum(np.exp(2j * np.pi * tones_hz[:, None] * t + 1j * np.array([[0.3], [1.1], [2.0]])), axis=0)
    y = narrow(x, factor)
    assert y.size == n // factor
    assert np.max(np.abs(y - x[::factor])) < 1e-5


def test_ofdm_snapshot_recording_is_identified_from_its_pilot_combs(tmp_path, capsys):
    path = tmp_path / "ofdm.sigmf-meta"
    _generate(path, "--duration-s", "20", "--snapshot-s", "0.02", "--period-s", "1", "--mask-deg", "40",
              "--waveform", "ofdm")
    truth = {a["leosop:sat_id"] for a in json.loads(path.read_text())["annotations"] if "leosop:sat_id" in a}
    code, doc, err = _replay(capsys, str(path), "--init", "34.98,109.71,0", "--static")
    assert code == 0, err
    ids = [t["sat_id"] for t in doc["tracks"] if t["sat_id"] is not None]
    # The OFDM subcarriers in band are interference to the combs; every identity given must be right
    # and most satellites heard.
    assert set(ids) <= truth and len(set(ids)) == len(ids) and len(ids) >= len(truth) - 3


def test_bundled_example_identified_and_fixed_with_and_without_a_prior(capsys):
    meta = REPO_ROOT / "signals" / "starlink_xian_snapshots.sigmf-meta"
    truth = {a["leosop:sat_id"] for a in json.loads(meta.read_text())["annotations"] if "leosop:sat_id" in a}
    site = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    for prior in (["--init", "34.98,109.71,0"], []):
        code, doc, err = _replay(capsys, str(meta), "--static", *prior)
        assert code == 0, err
        assert sorted(t["sat_id"] for t in doc["tracks"]) == sorted(truth)
        s = doc["solutions"][0]
        err_m = np.linalg.norm(np.array([s["x_m"], s["y_m"], s["z_m"]]) - site)
        # 30 snapshots of 20 ms with 300 m (1 sigma) along-track errors: sigmas of ~10 m per axis;
        # 5 sigma of the horizontal ones.
        assert err_m < 5.0 * np.linalg.norm(s["sigma_enu_m"])


def test_continuous_recording_in_tracking_mode_identifies_every_satellite(tmp_path, capsys, monkeypatch):
    from leosop.orbits import load_constellation
    from leosop.replay import pipeline
    from leosop.signal.iq import open_sigmf

    path = tmp_path / "cont.sigmf-meta"
    # Five satellites of the default set for 3 s: 30 blocks of 0.1 s, full searches at blocks 0, 10, 20
    # and tracking mode (predicted combs only) in between.
    sats = ["70002", "70524", "71563", "71607", "72129"]
    _generate(path, "--duration-s", "3", "--sat", *sats)
    code, doc, err = _replay(capsys, str(path), "--init", "34.98,109.71,0", "--static")
    assert code == 0, err
    ids = [t["sat_id"] for t in doc["tracks"]]
    assert sorted(ids) == sats
    assert all(t["n_blocks"] >= 28 for t in doc["tracks"])  # no block lost to tracking mode
    # More satellites than a search finds in one block (here 2, normally 10): tracking keeps every comb
    # found and the searches at blocks 10 and 20 add the rest (tracking once kept only the first 2).
    monkeypatch.setattr(pipeline, "MAX_NEW_COMBS", 2)
    res = pipeline.replay(open_sigmf(path), load_constellation(), init_pos_ecef_m=geodetic_to_ecef(
        np.radians(34.98), np.radians(109.71), 0.0), static=True)
    assert sorted(tr.sat_id for tr in res.tracks if tr.sat_id) == sats


def test_continuous_recording_600_khz_off_keeps_every_comb_in_tracking_mode(tmp_path, capsys):
    """Tracking blocks fit the tone model through a rough LO offset (the first search's median Doppler).

    600 kHz off, the Doppler-only model puts the comb's edge tones 9.3 Hz off, most of a cycle over a
    0.1 s block: at 36 dB-Hz a tracked comb then fell below the detector in some blocks (tracks of 8,
    8 and 9 of 10 blocks, none identified, measured) and the refit through the LO cannot bring back a
    detection the first pass did not make. Now 10, 9 and 9 (the first block, a full search before any
    offset is known, uses the Doppler-only model), all identified.

    With ``--threads`` the blocks are read and cleaned on worker threads, in the first pass and in the
    refit through the LO offset (which this recording needs): the JSON is the same, key for key and
    bit for bit, with one thread, with three (two workers finishing blocks out of order) and with the
    default (the cores, at most two).
    """
    path = tmp_path / "cont_lo.sigmf-meta"
    sats = ["70002", "70524", "71563"]
    # 1 s: 10 blocks of 0.1 s, one full search and nine tracking blocks; a drifting LO as an LNB's.
    _generate(path, "--duration-s", "1", "--sat", *sats, "--cn0-model", "constant", "--cn0-dbhz", "36",
              "--rx-offset-hz", "600e3", "--rx-drift-hz-per-s", "50")
    docs = []
    for threads in (["--threads", "1"], ["--threads", "3"], []):
        code, doc, err = _replay(capsys, str(path), "--init", "34.98,109.71,0", "--static", "--lo-offset-max-hz",
                                 "1e6", *threads)
        assert code == 0, err
        docs.append(doc)
    assert sorted(t["sat_id"] for t in docs[0]["tracks"]) == sats
    assert all(t["n_blocks"] >= 9 for t in docs[0]["tracks"])
    # The refit ran: 600 kHz puts the edge tones (176 kHz out) 0.9 cycles off over a block, beyond
    # pipeline.LO_REFIT_CYCLES (0.01).
    assert abs(docs[0]["lo_offset_hz"] - 600e3) < 1e3
    assert docs[0] == docs[1] == docs[2]


def test_element_sets_far_from_the_recording_warn_then_refuse(snapshot_recording, tmp_path, capsys):
    from leosop.orbits import DEFAULT_TLE

    path, _ = snapshot_recording
    # The bundled set's epoch is 2025-01-01T00:00Z. Shifting every epoch by 6 days (the
    # element sets themselves unchanged) makes them 6 days off: a warning, still a result.
    def shifted(days):
        lines = DEFAULT_TLE.read_text().splitlines()
        out = []
        for line in lines:
            if line.startswith("1 "):
                year = 2000 + int(line[18:20])
                epoch = np.datetime64(f"{year}-01-01") + np.timedelta64(
                    int(round((float(line[20:32]) - 1.0 + days) * 86400e6)), "us")
                year = epoch.astype("datetime64[Y]")
                doy = (epoch - year) / np.timedelta64(1, "D") + 1.0
                line = line[:18] + f"{int(str(year)) % 100:02d}{doy:012.8f}" + line[32:68]
                line += str(sum(int(c) if c.isdigit() else (c == "-") for c in line) % 10)
            out.append(line)
        f = tmp_path / f"shift{days}.tle"
        f.write_text("\n".join(out) + "\n")
        return f

    code, doc, err = _replay(capsys, str(path), "--tle", str(shifted(-6)), "--static", "--init", "34.98,109.71,0")
    assert code == 0 and "warning" in err and "6.8 days from the recording" in err
    code, _, err = _replay(capsys, str(path), "--tle", str(shifted(-40)), "--static", "--out", str(tmp_path / "o"))
    assert code == 2 and "no element set within 30 days" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_recording_whose_band_misses_the_combs_is_refused(snapshot_recording, tmp_path, capsys):
    # Centred 5 MHz above the 11.325 GHz channel at 2.5 MS/s: the combs would sit at -5 MHz, +-0.58 MHz
    # (100 kHz offset searched, 300 kHz Doppler, 176 kHz half comb), all outside +-1.25 MHz.
    path, _ = snapshot_recording
    meta = json.loads(path.read_text())
    for cap in meta["captures"]:
        cap["core:frequency"] += 5e6
    bad = tmp_path / "offband.sigmf-meta"
    bad.write_text(json.dumps(meta))
    (tmp_path / "offband.sigmf-data").symlink_to(path.with_suffix(".sigmf-data"))
    code, _, err = _replay(capsys, str(bad), "--out", str(tmp_path / "o"))
    assert code == 2 and err.count("\n") == 1
    assert "offband.sigmf-data" in err and "11330.0000 MHz +- 1.25 MHz" in err and "-5.0000 MHz" in err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_band_check_refuses_exactly_beyond_the_combs_reach():
    from types import SimpleNamespace

    from leosop.errors import InputError
    from leosop.replay.lo import check_band
    from leosop.signal.coarse import MAX_DOPPLER_HZ

    # Closed form: refused when |channel - centre| - (offset + Doppler + half comb) > rate / 2.
    half_comb, lo_max, fs = 175_798.0, 100e3, 2.5e6
    edge = 0.5 * fs + lo_max + MAX_DOPPLER_HZ + half_comb
    for sign in (-1, 1):
        check_band(SimpleNamespace(center_hz=11.325e9 + sign * (edge - 10.0), sample_rate_hz=fs, data_path="r"),
                   half_comb, lo_max)
        with pytest.raises(InputError, match="does not contain the pilot combs"):
            check_band(SimpleNamespace(center_hz=11.325e9 + sign * (edge + 10.0), sample_rate_hz=fs,
                                       data_path="r"), half_comb, lo_max)
    # A wider offset searched reaches the combs again; no centre frequency: taken as on the carrier.
    check_band(SimpleNamespace(center_hz=11.325e9 + edge + 10.0, sample_rate_hz=fs, data_path="r"),
               half_comb, lo_max + 20.0)
    check_band(SimpleNamespace(center_hz=None, sample_rate_hz=fs, data_path="r"), half_comb, lo_max)
