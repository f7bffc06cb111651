"""The generator's receiver LO: an offset and a drift common to every satellite, in the truth and in the samples."""

import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.signal.error_model import doppler_sigma_hz
from leosop.signal.iq import open_sigmf
from leosop.signal.multicomb import find_combs

SATS = ["71585", "70524"]  # above 40 deg from Xi'an at the default start, combs well apart
FS_HZ = 1e6
OFFSET_HZ, DRIFT_HZ_PER_S = 62_000.0, 25.0


def _generate(path, offset_hz, drift_hz_per_s):
    assert main(["generate", "-o", str(path), "--sat", *SATS, "--duration-s", "1.0", "--sample-rate-hz", str(FS_HZ),
                 "--cn0-model", "constant", "--cn0-dbhz", "45", "--seed", "3", "--rx-offset-hz", str(offset_hz),
                 "--rx-drift-hz-per-s", str(drift_hz_per_s), "--truth-step-s", "0.1", "--json"]) == 0
    return open_sigmf(path)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("lo")
    return _generate(d / "clean.sigmf-meta", 0.0, 0.0), _generate(d / "lo.sigmf-meta", OFFSET_HZ, DRIFT_HZ_PER_S)


def test_truth_holds_the_common_lo(pair, capsys):
    capsys.readouterr()
    clean, lo = pair
    meta = json.loads(lo.data_path.with_suffix(".sigmf-meta").read_text())["global"]
    assert meta["leosop:rx_offset_hz"] == OFFSET_HZ and meta["leosop:rx_drift_hz_per_s"] == DRIFT_HZ_PER_S
    # Same seed, same draws: the truth differs by the LO alone, offset + drift t at each block centre
    # (closed form; 1e-6 Hz is float rounding of ~1e5 Hz values).
    for a, b in zip(clean.annotations, lo.annotations):
        assert a["leosop:sat_id"] == b["leosop:sat_id"]
        t = b["leosop:t_s"]
        assert b["leosop:doppler_hz"] - a["leosop:doppler_hz"] == pytest.approx(OFFSET_HZ + DRIFT_HZ_PER_S * t,
                                                                                abs=1e-6)
        assert b["leosop:doppler_rate_hz_per_s"] - a["leosop:doppler_rate_hz_per_s"] == pytest.approx(
            DRIFT_HZ_PER_S, abs=1e-6)


def test_samples_follow_the_truth(pair):
    """Every comb measured in the drifting recording lands on its truth, drift included."""
    _, lo = pair
    n = int(0.1 * FS_HZ)
    bound = doppler_sigma_hz(45.0, 0.1, sample_rate_hz=FS_HZ)
    for start in range(0, lo.n_samples - n + 1, n):
        truth = {a["leosop:sat_id"]: a for a in lo.annotations if a["core:sample_start"] == start}
        found = find_combs(lo.read(start, n), FS_HZ)
        for sid, a in truth.items():
            j = int(np.argmin(np.abs(found.doppler_hz - a["leosop:doppler_hz"])))
            # Each satellite at the bound: 4.5 sigma (false failure ~7e-6 per value, 20 values).
            assert abs(found.doppler_hz[j] - a["leosop:doppler_hz"]) < 4.5 * bound, sid
            # Rate: the drift (25 Hz/s) is far above the rate's spread at 0.1 s (~2 Hz/s).
            assert abs(found.doppler_rate_hz_per_s[j] - a["leosop:doppler_rate_hz_per_s"]) < 8.0, sid


def test_drift_beyond_the_band_is_refused(tmp_path, capsys):
    status = main(["generate", "-o", str(tmp_path / "x.sigmf-meta"), "--sat", SATS[0], "--duration-s", "1",
                   "--sample-rate-hz", "1e6", "--rx-offset-hz", "4e5", "--rx-drift-hz-per-s", "2e5"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "--rx-drift-hz-per-s" in err
    assert list(tmp_path.iterdir()) == []
