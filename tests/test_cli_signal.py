"""leosop generate / leosop doppler end to end: contract keys, truth recovery, bad inputs."""

import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.signal.doppler import doppler_sigma_hz
from leosop.signal.iq import write_sigmf

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
    assert doc["estimates"][0]["time_utc"] == "2025-01-01T19:40:00.049999Z"  # microseconds, truncated
    err = np.array([e["doppler_hz"] - e["truth_doppler_hz"] for e in doc["estimates"]])
    bound = doppler_sigma_hz(45.0, 0.1, sample_rate_hz=1e6)
    # Four blocks at the bound: |error| < 4.5 sigma each (false failure ~3e-5 per run).
    assert np.all(np.abs(err) < 4.5 * bound)
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"doppler.csv", "doppler.json", "spectrogram.png"}


def test_paper_method_on_recording(recording, capsys):
    status, out, _ = _run(capsys, ["doppler", str(recording), "--json", "--method", "fmlef",
                                   "--resolution-hz", "0.01"])
    assert status == 0
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
    elif case == "raw rate":
        raw = tmp_path / "rec.cf32"
        data.rename(raw)
        args = ["doppler", str(raw), "--dtype", "cf32", "--sample-rate-hz", "-1"]
    return args


@pytest.mark.parametrize("case", ["missing data", "datatype", "truncated", "rate", "block", "nan", "raw rate"])
def test_bad_input(recording, tmp_path, capsys, case):
    args = _bad(tmp_path, recording, case) + ["--out", str(tmp_path / "out")]
    status, out, err = _run(capsys, args)
    assert status == 2 and out == ""
    assert err.count("\n") == 1 and "error:" in err  # one line
    assert not (tmp_path / "out").exists()  # no partial outputs


def test_bundled_example(capsys):
    from pathlib import Path

    meta = Path(__file__).resolve().parents[1] / "signals" / "starlink_71585_xian.sigmf-meta"
    status, out, _ = _run(capsys, ["doppler", str(meta), "--json"])
    assert status == 0
    doc = json.loads(out)
    assert doc["n_detected"] == doc["n_blocks"] == 5
    # Five blocks at the bound (0.023 Hz at 45 dB-Hz, 0.1 s, 1 MHz): RMS below
    # 2.5 sigma fails by chance with probability ~1e-5 (chi-square, 5 dof).
    assert doc["truth_rms_error_hz"] < 2.5 * doppler_sigma_hz(45.0, 0.1, sample_rate_hz=1e6)
