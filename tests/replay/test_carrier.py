"""Carrier tracking (:mod:`leosop.replay.carrier`) on a continuous recording made by ``leosop generate``.

The truth is the recording's annotations: the central tone's Doppler and its
rate at every block centre (``--truth-step-s`` equal to the block), which the
tracker never sees; it starts from the comb search of the first block. The
truth phase between blocks is the Doppler's integral, by the cubic Hermite
rule on those nodes (error h^5 |f''''| / 720: ~1e-12 cycles at h = 20 ms).
"""

import csv
import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.replay.carrier import phase_rate_doppler, recording_blocks, track_carrier
from leosop.signal.iq import open_sigmf
from leosop.signal.multicomb import find_combs

BLOCK_S = 0.02
#: Three satellites whose combs stay >= 9 kHz from each other's tones (modulo the
#: 43.9 kHz spacing) over the recording: no tone of one leaks into another's correlation.
SATS = ("71607", "72129", "73465")
#: The phase differences' tolerance [cycles]: well inside the half cycle an
#: integer ambiguity needs, ~15 times one block's noise (~2e-3 cycles at 42 dB-Hz per tone; measured max 0.014).
PHASE_TOL_CYCLES = 0.03


SITE = "34.342,108.94,400"


@pytest.fixture(scope="module")
def recording_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("carrier") / "cont.sigmf-meta"
    argv = ["generate", "-o", str(path), "--site", SITE, "--start", "2025-01-01T19:40:00Z",
            "--duration-s", "2.2", "--sample-rate-hz", "1e6", "--sat", *SATS, "--truth-step-s", str(BLOCK_S),
            "--seed", "3"]
    assert main(argv) == 0
    return path


@pytest.fixture(scope="module")
def recording(recording_path):
    rec = open_sigmf(recording_path)
    ann = [a for a in rec.annotations if "leosop:sat_id" in a]
    truth = {s: np.array([[a["leosop:t_s"], a["leosop:doppler_hz"], a["leosop:doppler_rate_hz_per_s"]]
                          for a in ann if a["leosop:sat_id"] == s]) for s in SATS}
    blocks = list(recording_blocks(rec, BLOCK_S))
    combs = find_combs(blocks[0][1], rec.sample_rate_hz, max_combs=len(SATS))
    assert len(combs.doppler_hz) == len(SATS)
    order = [SATS[int(np.argmin([abs(truth[s][0, 1] - f) for s in SATS]))] for f in combs.doppler_hz]
    assert sorted(order) == sorted(SATS)
    return rec.sample_rate_hz, blocks, combs, [truth[s] for s in order]


def _track(recording, blocks=None):
    fs, rec_blocks, combs, _ = recording
    return track_carrier(rec_blocks if blocks is None else blocks, fs, combs.doppler_hz, combs.doppler_rate_hz_per_s,
                         doppler0_sigma_hz=3.0 * float(np.max(combs.sigma_hz)))


@pytest.fixture(scope="module")
def tracks(recording):
    return _track(recording)


def _truth_phase(truth, t_s):
    """Integral of the truth Doppler from the first node, at ``t_s`` (nodes at the block centres)."""
    t, f, r = truth.T
    h = np.diff(t)
    integ = np.concatenate([[0.0], np.cumsum(0.5 * h * (f[:-1] + f[1:]) + h**2 / 12.0 * (r[:-1] - r[1:]))])
    assert np.allclose(t[: t_s.size], t_s, atol=1e-9)
    return integ[: t_s.size]


def test_phase_follows_the_integral_of_the_true_doppler(recording, tracks):
    _, _, _, truth = recording
    assert tracks.lock.all() and not tracks.slip.any() and (tracks.arc == 0).all()
    for i, tr in enumerate(truth):
        err = tracks.phase_cycles[i] - _truth_phase(tr, tracks.t_s)
        err -= err[0]  # the arc's offset is arbitrary
        assert np.max(np.abs(err)) < PHASE_TOL_CYCLES, (i, np.max(np.abs(err)))
        # and the noise is what the sigmas say (rms within a factor 2 of it: phase noise of 110 blocks)
        assert 0.5 < np.std(np.diff(err)) / np.sqrt(2 * np.mean(tracks.phase_sigma_cycles[i] ** 2)) < 2.0


def test_phase_rate_matches_the_true_doppler_within_its_sigma(recording, tracks):
    _, _, combs, truth = recording
    dop, sig = phase_rate_doppler(tracks, window_s=0.6)
    for i, tr in enumerate(truth):
        f_true = tr[: tracks.t_s.size, 1]
        ok = np.isfinite(dop[i])
        assert ok.sum() > 0.5 * ok.size
        z = (dop[i, ok] - f_true[ok]) / sig[i, ok]
        assert np.max(np.abs(z)) < 4.5, np.max(np.abs(z))  # correlated windows: the max of ~50 dependent normals
        # far better than the block's own estimate, and the filter's frequency state within 4 sigma
        assert np.median(sig[i, ok]) < 0.1 * combs.sigma_hz[i]
        zf = (tracks.doppler_hz[i, 10:] - f_true[10:]) / tracks.doppler_sigma_hz[i, 10:]
        assert np.max(np.abs(zf)) < 4.0, np.max(np.abs(zf))


def test_a_phase_jump_in_the_iq_is_flagged_and_starts_a_new_arc(recording):
    _, blocks, _, truth = recording
    jump_at = 40
    jumped = [(t0, iq * np.exp(2j * np.pi * 0.3) if j >= jump_at else iq) for j, (t0, iq) in enumerate(blocks)]
    tracks = _track(recording, jumped)
    assert np.array_equal(np.flatnonzero(tracks.slip.any(axis=0)), [jump_at])
    assert tracks.slip[:, jump_at].all()
    assert (tracks.arc[:, :jump_at] == 0).all() and (tracks.arc[:, jump_at:] == 1).all()
    # within the new arc the phase again follows the truth
    for i, tr in enumerate(truth):
        err = (tracks.phase_cycles[i] - _truth_phase(tr, tracks.t_s))[jump_at:]
        assert np.max(np.abs(err - err[0])) < PHASE_TOL_CYCLES


def test_replay_carrier_writes_phase_rate_doppler_within_its_sigma_and_feeds_the_static_fix(recording_path, tmp_path):
    out = tmp_path / "out"
    argv = ["replay", str(recording_path), "--init", SITE, "--block-s", str(BLOCK_S), "--static", "--carrier",
            "--out", str(out)]
    assert main(argv) == 0
    doc = json.loads((out / "replay.json").read_text())
    rows = list(csv.DictReader((out / "carrier.csv").open()))
    rec = open_sigmf(recording_path)
    ann = [a for a in rec.annotations if "leosop:sat_id" in a]
    truth = {s: np.array([[a["leosop:t_s"], a["leosop:doppler_hz"]] for a in ann if a["leosop:sat_id"] == s])
             for s in SATS}
    assert sorted({r["sat_id"] for r in rows}) == sorted(SATS)
    assert all(r["lock"] == "1" and r["slip"] == "0" and r["arc"] == "0" for r in rows)
    est = [r for r in rows if r["doppler_hz"]]
    assert len(est) > 0.5 * len(rows)
    z = []
    for r in est:
        t_true, f_true = truth[r["sat_id"]].T
        k = int(np.argmin(np.abs(t_true - float(r["t_s"]))))
        assert abs(t_true[k] - float(r["t_s"])) < 1e-6  # annotations at the block centres (1 MS/s: no narrowing)
        z.append((float(r["doppler_hz"]) - f_true[k]) / float(r["doppler_sigma_hz"]))
    assert np.max(np.abs(z)) < 4.5, np.max(np.abs(z))  # as above: the max of dependent normals
    sats = {c["sat_id"]: c for c in doc["carrier"]["satellites"]}
    assert set(sats) == set(SATS)
    for c in sats.values():
        assert (c["arcs"], c["slips"], c["locked_fraction"]) == (1, 0, 1.0)
        # the phase-rate Doppler is far less noisy than a 20 ms block's, so their difference is the block's noise
        assert c["phase_rate_sigma_median_hz"] < 0.1 * c["block_sigma_median_hz"]
        assert 0.5 < c["phase_rate_vs_block_rms_hz"] / c["block_sigma_median_hz"] < 2.0
    # the static fix took the rows marked in_fix (2 disjoint 1 s windows each), not the block rows
    assert doc["carrier"]["fix_doppler"] == "phase_rate"
    assert doc["solutions"][0]["n_used"] == sum(r["in_fix"] == "1" for r in rows) == 2 * len(SATS)
    assert doc["solutions_block_doppler"][0]["n_used"] == len(SATS) * 110


def test_replay_carrier_refuses_a_snapshot_recording(tmp_path, capsys):
    snap = tmp_path / "snap.sigmf-meta"
    assert main(["generate", "-o", str(snap), "--duration-s", "1.5", "--snapshot-s", "0.02", "--period-s", "0.5",
                 "--sample-rate-hz", "1e6", "--sat", SATS[0]]) == 0
    capsys.readouterr()
    assert main(["replay", str(snap), "--carrier"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "continuous recording" in err and "coherence is lost across a gap" in err
    assert err.endswith("; replay it without --carrier")  # the CLI's advice, not the library's
    assert main(["replay", str(snap), "--carrier", "--base", str(snap), "--base-site", SITE]) == 2
    assert "the differential carrier-phase fix is of a rover at rest: add --static" in capsys.readouterr().err
    assert main(["replay", str(snap), "--carrier", "--static", "--base", str(snap), "--base-site", SITE]) == 2
    assert "continuous recording" in capsys.readouterr().err
