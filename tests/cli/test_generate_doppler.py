"""leosop generate / leosop doppler end to end: contract keys, truth recovery, bad inputs."""

import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.signal.error_model import doppler_sigma_hz
from leosop.signal.iq_write import write_sigmf

SAT = "71585"  # above 40 deg from Xi'an at the default start (2025-01-01T19:40Z)


def _run(capsys, argv):
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "one.sigmf-meta"
    assert main(["generate", "-o", str(path), "--sat", SAT, "--duration-s", "0.4", "--sample-rate-hz", "1e6",
                 "--cn0-dbhz", "45", "--cn0-model", "constant", "--seed", "1", "--json"]) == 0
    return path


def test_generate_and_recover(recording, capsys, tmp_path):
    capsys.readouterr()
    status, out, _ = _run(capsys, ["doppler", str(recording), "--json", "--out", str(tmp_path / "out")])
    assert status == 0
    doc = json.loads(out)
    assert doc["method"] == "fast" and len(doc["estimates"]) == 4
    keys = {"t_s", "time_utc", "doppler_hz", "doppler_rate_hz_per_s", "cn0_dbhz", "sigma_hz"}
    for e in doc["estimates"]:
        assert keys <= set(e) and e["status"] == "ok" and e["truth_sat_id"] == SAT
    assert doc["estimates"][0]["t_s"] == pytest.approx(49_999.5 / 1e6)
    assert doc["estimates"][0]["time_utc"] == "2025-01-01T19:40:00.050000Z"  # 49 999.5 us, rounded to the us
    err = np.array([e["doppler_hz"] - e["truth_doppler_hz"] for e in doc["estimates"]])
    bound = doppler_sigma_hz(45.0, 0.1, sample_rate_hz=1e6)
    # Four blocks at the bound: |error| < 4.5 sigma each (false failure ~3e-5 per run).
    assert np.all(np.abs(err) < 4.5 * bound)
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"doppler.csv", "doppler.json", "spectrogram.png"}


def test_paper_method_on_recording(recording, capsys):
    status, out, err = _run(capsys, ["doppler", str(recording), "--json", "--method", "fmlef",
                                     "--resolution-hz", "0.01"])
    assert status == 0
    # The user is told, in one line, why the paper's method errs here.
    assert err.count("\n") == 1 and "--method fmlef assumes a constant tone within a block" in err
    doc = json.loads(out)
    assert all(e["doppler_rate_hz_per_s"] is None for e in doc["estimates"])
    # Under a LEO rate (~2.6 kHz/s over 0.1 s) the constant-tone model smears: the
    # estimate still lies within the swept band (+-130 Hz) around the truth.
    assert all(abs(e["doppler_hz"] - e["truth_doppler_hz"]) < 140 for e in doc["estimates"])


def test_no_signal(tmp_path, capsys):
    meta = tmp_path / "noise.sigmf-meta"
    rng = np.random.default_rng(0)
    write_sigmf(meta, [rng.standard_normal(200_000) + 1j * rng.standard_normal(200_000)], sample_rate_hz=1e6,
                center_hz=11.325e9, start_utc="2025-01-01T00:00:00Z")
    status, out, _ = _run(capsys, ["doppler", str(meta), "--json"])
    assert status == 0
    for e in json.loads(out)["estimates"]:
        assert e["status"] == "no pilot detected"
        assert e["doppler_hz"] is None and e["sigma_hz"] is None and e["cn0_dbhz"] is None


def _bad(tmp_path, recording, case):
    meta = tmp_path / "bad.sigmf-meta"
    data = meta.with_suffix(".sigmf-data")
    meta.write_text(recording.read_text())
    data.write_bytes(recording.with_suffix(".sigmf-data").read_bytes())
    doc = json.loads(meta.read_text())
    args = ["doppler", str(meta)]
    if case == "missing data":
        data.unlink()
    elif case == "datatype":
        doc["global"]["core:datatype"] = "ri8"
        meta.write_text(json.dumps(doc))
    elif case == "truncated":
        data.write_bytes(data.read_bytes()[:-5])
    elif case == "rate":
        doc["global"]["core:sample_rate"] = 0
        meta.write_text(json.dumps(doc))
    elif case == "block":
        args += ["--block-s", "5"]
    elif case == "nan":
        raw = np.fromfile(data, dtype="<c8")
        raw[250_000] = np.nan
        raw.tofile(data)
        doc["global"].pop("core:sha512")
        meta.write_text(json.dumps(doc))
    elif case in ("capture frequency", "capture overlap", "top-level list"):
        second = dict(doc["captures"][0], **{"core:sample_start": 200_000})
        if case == "capture frequency":
            second["core:frequency"] = "11.325e9"
        else:  # 0.1 s into the first capture's 0.4 s
            second["core:datetime"] = "2025-01-01T19:40:00.1Z"
        doc["captures"].append(second)
        meta.write_text(json.dumps([doc] if case == "top-level list" else doc))
    elif case == "raw rate":
        raw = tmp_path / "rec.cf32"
        data.rename(raw)
        args = ["doppler", str(raw), "--dtype", "cf32", "--sample-rate-hz", "-1"]
    return args


@pytest.mark.parametrize("case", ["missing data", "datatype", "truncated", "rate", "block", "nan", "raw rate",
                                  "capture frequency", "capture overlap", "top-level list"])
def test_bad_input(recording, tmp_path, capsys, case):
    args = _bad(tmp_path, recording, case) + ["--out", str(tmp_path / "out")]
    status, out, err = _run(capsys, args)
    assert status == 2 and out == ""
    assert err.count("\n") == 1 and "error:" in err  # one line
    assert not (tmp_path / "out").exists()  # no partial outputs


def test_snapshot_recording_end_to_end(tmp_path, capsys):
    from leosop.signal.iq import open_sigmf

    meta = tmp_path / "snap.sigmf-meta"
    status, out, _ = _run(capsys, ["generate", "-o", str(meta), "--snapshot-s", "0.02", "--period-s", "1",
                                   "--duration-s", "10", "--orbit-error-along-m", "100", "--seed", "3", "--json"])
    assert status == 0
    doc = json.loads(out)
    fs = 2.5e6
    assert doc["n_captures"] == 10 and doc["snapshot_s"] == 0.02 and doc["n_samples"] == 10 * 50_000
    rec = open_sigmf(meta)
    start = np.datetime64("2025-01-01T19:40:00", "ns")
    assert [(c.sample_start, c.n_samples) for c in rec.captures] == [(50_000 * k, 50_000) for k in range(10)]
    assert [c.start_utc for c in rec.captures] == [start + np.timedelta64(k, "s") for k in range(10)]
    assert meta.with_suffix(".sigmf-data").stat().st_size == 10 * 50_000 * 8  # cf32: sum of the snapshots
    sats = doc["satellites"]
    assert len(sats) >= 7 and all(abs(s["orbit_error_along_m"]) > 0 for s in sats)
    # One truth block per snapshot and satellite (the 0.1 s truth step is longer than a snapshot).
    assert len(rec.annotations) == 10 * len(sats)
    # Every satellite whose comb is clear of the others' (tones > 5 kHz apart modulo the
    # 43.95 kHz spacing: closer tones bias the estimator's noise floor, a property of the
    # estimator, not of the recording): Doppler at its truth within 4.5 CRLB sigmas (false
    # failure ~1e-5 each), C/N0 within 1 dB (estimator spread ~0.1 dB over 20 ms at
    # 40 dB-Hz; the other nine combs raise the noise floor by up to ~0.5 dB).
    checked = 0
    for k, cap in enumerate(rec.captures):
        iq = rec.read(cap.sample_start, cap.n_samples)
        truth = [a for a in rec.annotations if a["core:sample_start"] == cap.sample_start]
        assert all(a["leosop:t_s"] == pytest.approx(k + 24_999.5 / fs) for a in truth)  # phases run on in gaps
        checked += _check_truth(iq, fs, truth, 0.02, cn0_tol_db=1.0)
    assert checked >= 3
    # The docs' first example used 0.1 s blocks on these 20 ms captures: each joins five of them.
    capsys.readouterr()
    status, out, err = _run(capsys, ["doppler", str(meta), "--json"])
    assert status == 0 and "join 10 captures" in err
    assert {e["status"] for e in json.loads(out)["estimates"]} == {"joins captures"}
    status, out, _ = _run(capsys, ["doppler", str(meta), "--block-s", "0.02", "--json"])
    doc = json.loads(out)
    # Ten satellites of one sky: some blocks are not ok (overlapping combs, a fit lost between two
    # equal combs: weak comb); the ok ones are within 3 sigma (10 blocks: no miss expected).
    assert doc["n_ok"] >= 6 and doc["truth_within_3_sigma"] == 1.0


def test_ml_warns_of_its_run_time(recording, capsys):
    from leosop.cli.doppler import _warn_ml_time
    from leosop.signal.iq import open_sigmf

    # 0.1 s blocks at 1 MS/s, STFT coarse error 244 Hz: +-1000 Hz at 1e-3 Hz, each point a pass over 1e5 samples.
    _warn_ml_time(open_sigmf(recording), 100_000, 1e6 / 4096, 1e-3, 4)
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--method ml evaluates 2,000,001 frequencies per block" in err


def _check_truth(iq, fs, truth, block_s, cn0_tol_db):
    """Estimate every clear comb of ``iq`` near its truth annotation; return how many were checked."""
    from leosop.signal.doppler import estimate_block

    spacing = 43_949.5
    dop = np.array([a["leosop:doppler_hz"] for a in truth])
    n = 0
    for i, a in enumerate(truth):
        if np.min(np.abs((dop[i] - np.delete(dop, i) + spacing / 2) % spacing - spacing / 2), initial=np.inf) < 5e3:
            continue
        est = estimate_block(iq, fs, coarse_hz=dop[i], coarse_error_hz=150.0)
        bound = doppler_sigma_hz(a["leosop:cn0_dbhz"], block_s, sample_rate_hz=fs)
        assert abs(est["doppler_hz"] - dop[i]) < 4.5 * bound, a
        assert abs(est["cn0_dbhz"] - a["leosop:cn0_dbhz"]) < cn0_tol_db, a
        n += 1
    return n


def test_per_satellite_cn0_and_orbit_error(tmp_path, capsys):
    from leosop.signal.iq import open_sigmf

    meta = tmp_path / "three.sigmf-meta"
    sats = ["71585", "70524", "71563"]  # combs 6.6-21 kHz apart modulo the tone spacing
    status, out, _ = _run(capsys, ["generate", "-o", str(meta), "--sat", *sats, "--cn0-model", "constant",
                                   "--cn0-dbhz", "45", "39", "42", "--sample-rate-hz", "1e6", "--duration-s", "0.3",
                                   "--orbit-error-along-m", "100", "--orbit-error-radial-m", "30",
                                   "--orbit-error-cross-m", "30", "--seed", "2", "--json"])
    assert status == 0
    doc = json.loads(out)
    assert [s["cn0_dbhz"] for s in doc["satellites"]] == [45.0, 39.0, 42.0]
    rec = open_sigmf(meta)
    drawn = {s["sat_id"]: s for s in json.loads(meta.read_text())["global"]["leosop:satellites"]}
    for s in doc["satellites"]:  # the draws in the JSON are those in the metadata, and nonzero
        assert drawn[s["sat_id"]] == s
        assert min(abs(s[f"orbit_error_{k}"]) for k in ("along_m", "radial_m", "cross_m")) > 0
    # Three 0.1 s blocks x 3 satellites at the bound; C/N0 within 1 dB (spread ~0.05 dB
    # at 39-45 dB-Hz over 0.1 s; a comb 6 dB stronger in the band lifts the estimator's
    # noise floor by ~0.6 dB).
    for start in (0, 100_000, 200_000):
        truth = [a for a in rec.annotations if a["core:sample_start"] == start]
        assert _check_truth(rec.read(start, 100_000), 1e6, truth, 0.1, cn0_tol_db=1.0) == 3


@pytest.mark.parametrize("argv, match", [
    (["--snapshot-s", "0.02"], "--snapshot-s and --period-s"),
    (["--snapshot-s", "2", "--period-s", "1"], "longer than --period-s"),
    (["--cn0-dbhz", "40", "41"], "--cn0-dbhz: 2 values"),
    (["--orbit-error-radial-m", "-1"], "--orbit-error-radial-m"),
    (["--frame-jump-sigma-s", "3e-7"], "need --waveform ofdm"),
    (["--frame-jump-period-s", "1"], "give --frame-jump-sigma-s"),
    (["--waveform", "ofdm", "--frame-jump-sigma-s", "-1e-9"], "--frame-jump-sigma-s"),
])
def test_generate_bad_options(tmp_path, capsys, argv, match):
    meta = tmp_path / "x.sigmf-meta"
    status, out, err = _run(capsys, ["generate", "-o", str(meta), "--duration-s", "0.2", "--sat", SAT,
                                     "--out", str(tmp_path / "out")] + argv)
    assert status == 2 and out == "" and err.count("\n") == 1 and match in err
    assert list(tmp_path.iterdir()) == []  # no recording, no output folder


def test_frame_timing_jumps_in_the_truth(tmp_path, capsys):
    from leosop.signal.ofdm import FrameTimingJumps

    meta = tmp_path / "jumps.sigmf-meta"
    status, out, _ = _run(capsys, ["generate", "-o", str(meta), "--sat", SAT, "--duration-s", "0.25",
                                   "--truth-step-s", "0.05", "--waveform", "ofdm", "--frame-jump-sigma-s", "3e-7",
                                   "--frame-jump-period-s", "0.1", "--seed", "5", "--json"])
    assert status == 0
    doc = json.loads(out)
    jumps = doc["satellites"][0]["frame_jumps"]
    assert jumps == json.loads(meta.read_text())["global"]["leosop:satellites"][0]["frame_jumps"]
    # The steps are satellite 0's of the seed; each at the receive time of frame-clock 0.1 s, 0.2 s: later
    # by the range's change over it / c (< 7.6 km/s x 0.2 s / c = 5 us).
    assert [j["jump_s"] for j in jumps] == FrameTimingJumps(3e-7, 0.1, (5, 0)).steps_s(2).tolist()
    assert np.allclose([j["t_s"] for j in jumps], [0.1, 0.2], rtol=0, atol=5e-6)
