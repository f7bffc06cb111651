"""Unnamed fragments followed along their candidates' curves (leosop.replay.extend).

A generated snapshot recording is replayed; one named satellite's track is
then cut to three blocks and handed back unnamed, as a satellite near the
snapshot search's comb cap leaves it. Followed from the identification's
position and LO estimate, the fragment must grow back over the recording
with Dopplers that match the generator's truth (the SigMF annotations) at
the detections' sigmas; a fragment no satellite's curve runs through must
be left as it is.
"""

import json
from dataclasses import replace

import numpy as np
import pytest

from leosop.cli import main
from leosop.frames import C_e_n, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.replay import pipeline
from leosop.replay.extend import extend_fragments
from leosop.signal.iq import open_sigmf
from leosop.signal.pilot import PilotComb

SITE = (34.342, 108.940, 400.0)
START = "2025-01-01T19:40:00Z"


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    """30 s of snapshots (one a second; element sets ~300 m along track off) replayed with a prior 99 km off;
    the truth curves per satellite."""
    path = tmp_path_factory.mktemp("extend") / "snap.sigmf-meta"
    assert main(["generate", "-o", str(path), "--site", ",".join(map(str, SITE)), "--start", START,
                 "--sample-rate-hz", "2.5e6", "--seed", "7", "--duration-s", "30", "--snapshot-s", "0.02",
                 "--period-s", "1", "--mask-deg", "40", "--orbit-error-along-m", "300"]) == 0
    const = load_constellation()
    lat, lon = np.radians(SITE[0]), np.radians(SITE[1])
    init = geodetic_to_ecef(lat, lon, SITE[2]) + C_e_n(lat, lon) @ np.array([70e3, 70e3, 0.0])
    rec = open_sigmf(path)
    res = pipeline.replay(rec, const, init_pos_ecef_m=init, static=True)
    curves = {}
    for a in json.loads(path.read_text())["annotations"]:
        curves.setdefault(a["leosop:sat_id"], []).append((a["leosop:t_s"], a["leosop:doppler_hz"]))
    return rec, const, res, {k: np.array(sorted(v)) for k, v in curves.items()}


def _follow(rec, const, res, raw, named):
    comb = PilotComb(carrier_hz=rec.center_hz or PilotComb.carrier_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    factor, _ = pipeline.search_band(rec.sample_rate_hz, comb, pipeline.LO_OFFSET_MAX_HZ)
    band_hz = (0.5 - pipeline.BAND_MARGIN) * rec.sample_rate_hz / factor - np.max(np.abs(comb.offsets_hz))
    ident = res.identification
    return extend_fragments(rec, raw, named, res.blocks, factor, comb, res.lo, ident.pos_ecef_m, ident.pos_cov_m2,
                            const, mask_deg=10.0, band_hz=band_hz, gate_hz=pipeline.TRACK_GATE_HZ)


def _cut(res, shift_hz=0.0):
    """The tracks with the longest named one cut to its middle three blocks (Doppler moved by ``shift_hz``),
    unnamed: (raw, named, the whole track)."""
    whole = max((tr for tr in res.tracks if tr.sat_id is not None), key=len)
    m = len(whole) // 2
    cut = slice(m - 1, m + 2)
    frag = replace(whole, t_s=whole.t_s[cut], time_utc=whole.time_utc[cut], doppler_hz=whole.doppler_hz[cut] + shift_hz,
                   doppler_rate_hz_per_s=whole.doppler_rate_hz_per_s[cut], cn0_dbhz=whole.cn0_dbhz[cut],
                   sigma_hz=whole.sigma_hz[cut], sat_id=None, match_rms_hz=None, id_status="poor_fit")
    others = [tr for tr in res.tracks if tr is not whole]
    return others + [frag], others + [frag], whole


def test_a_fragment_grows_back_along_its_satellite(replayed):
    rec, const, res, curves = replayed
    raw, named, whole = _cut(res)
    assert len(whole) >= 20
    out, n = _follow(rec, const, res, raw, named)
    assert n == 1 and all(a is b for a, b in zip(out[:-1], raw[:-1]))
    grown = out[-1]
    # Every capture the full search found it in, and no block twice (measured: all of them).
    assert len(grown) >= len(whole) and np.all(np.diff(grown.t_s) > 0)
    truth = curves[whole.sat_id]
    z = (grown.doppler_hz - np.interp(grown.t_s, truth[:, 0], truth[:, 1])) / grown.sigma_hz
    # The detections err at their sigmas (a tracking fit with the other combs alongside, as the refit's):
    # an RMS of 1 within the spread of ~30 draws, and none beyond 5 sigma.
    print(f"{len(grown)} blocks (whole track {len(whole)}), error / sigma RMS {np.sqrt(np.mean(z**2)):.2f}, "
          f"max {np.max(np.abs(z)):.2f}")
    assert np.sqrt(np.mean(z**2)) < 1.5 and np.max(np.abs(z)) < 5.0


def test_a_fragment_no_satellite_explains_is_left_alone(replayed):
    rec, const, res, curves = replayed
    raw, named, whole = _cut(res, shift_hz=2000.0)
    t_mid = whole.t_s[len(whole) // 2]
    f_mid = whole.doppler_hz[len(whole) // 2] + 2000.0
    assert min(abs(np.interp(t_mid, c[:, 0], c[:, 1]) - f_mid) for c in curves.values()) > 500.0
    out, n = _follow(rec, const, res, raw, named)
    assert n == 0 and all(a is b for a, b in zip(out, raw))


def test_two_fragments_of_one_satellite_become_one_track(replayed):
    """Cut into two 3-block fragments 15 blocks apart, a track comes back as one: every block once."""
    rec, const, res, curves = replayed
    whole = max((tr for tr in res.tracks if tr.sat_id is not None), key=len)
    frags = []
    for m in (6, 21):
        cut = slice(m - 1, m + 2)
        frags.append(replace(whole, t_s=whole.t_s[cut], time_utc=whole.time_utc[cut],
                             doppler_hz=whole.doppler_hz[cut], doppler_rate_hz_per_s=whole.doppler_rate_hz_per_s[cut],
                             cn0_dbhz=whole.cn0_dbhz[cut], sigma_hz=whole.sigma_hz[cut], sat_id=None,
                             match_rms_hz=None, id_status="too_short"))
    others = [tr for tr in res.tracks if tr is not whole]
    out, n = _follow(rec, const, res, others + frags, others + frags)
    assert n == 2 and len(out) == len(others) + 1
    grown = out[-1]
    assert len(grown) == len(whole) and np.array_equal(grown.t_s, whole.t_s)
    # The fragments' own blocks kept as they were, the rest found again.
    for f in frags:
        assert np.array_equal(grown.doppler_hz[np.isin(grown.t_s, f.t_s)], f.doppler_hz)


def test_the_fit_recovers_offset_and_time_offset_and_refuses_beyond_the_bounds():
    """Rows ``c + tau rate`` plus noise at their sigma: the fit gives back c and tau within 4 sigma of its own
    covariance (priors are broad against 60 rows); rows that need a time offset of 0.5 s (3.8 km along
    track, beyond the 1.5 km bound) lose the candidate."""
    from leosop.replay import extend

    rng = np.random.default_rng(3)
    n = 60
    rate = np.linspace(-2500.0, -1500.0, n)  # a pass's Doppler rate changing over a minute
    sigma = np.full(n, 0.5)
    for c_true, tau_true in ((7.0, 0.05), (-12.0, -0.1)):
        r = c_true + tau_true * rate + rng.normal(0, 1, n) * np.hypot(sigma, extend.MODEL_SIGMA_HZ)
        c, tau, chi2, resid = extend._fit(r[None, :], rate[None, :], sigma)
        # 2x2 normal matrix of the data alone bounds the sigmas (priors only shrink them).
        w = 1 / (sigma**2 + extend.MODEL_SIGMA_HZ**2)
        cov = np.linalg.inv(np.array([[w.sum(), (w * rate).sum()], [(w * rate).sum(), (w * rate**2).sum()]]))
        assert abs(c[0] - c_true) < 4 * np.sqrt(cov[0, 0]) + 0.5 and abs(tau[0] - tau_true) < 4 * np.sqrt(cov[1, 1])
        assert chi2[0] < n + 5 * np.sqrt(2 * n)
    off = 0.5 * rate + rng.normal(0, 0.5, n)
    cand = extend._Candidate(0, 0, np.zeros(n), rate, rate, np.ones(n, bool), (np.arange(3), off[:3], sigma[:3]),
                             (0, 2), extend.SAT_OFFSET_MAX_HZ)
    cand.rows = [(j, off[j], 0.0, 40.0, 0.5) for j in range(3, n)]
    extend._refit(cand, np.zeros(n))
    assert cand.lost and cand.rows == []


def test_a_comb_two_satellites_followed_into_is_left_to_neither():
    """Two fragments followed along two satellites whose detections share block 5 at one frequency (one comb
    taken by both): the merged tracks keep their other blocks and leave block 5 out of both."""
    from leosop.replay import extend
    from leosop.replay.tracks import Track

    n = 10
    t_blk = np.arange(n, dtype=float)
    utc_blk = np.datetime64("2025-01-01T00:00:00", "ns") + (t_blk * 1e9).astype("timedelta64[ns]")
    raw = [Track(t_blk[:2], utc_blk[:2], np.array([100.0, 90.0]), np.full(2, -10.0), np.full(2, 40.0), np.full(2, 0.5)),
           Track(t_blk[8:], utc_blk[8:], np.array([5.0, 4.0]), np.full(2, -1.0), np.full(2, 40.0), np.full(2, 0.5))]
    index = {t: j for j, t in enumerate(t_blk)}
    cands = []
    for track, sat, found in ((0, 11, {3: 70.0, 5: 50.0}), (1, 22, {5: 50.5, 6: 8.0})):
        c = extend._Candidate(track, sat, np.zeros(n), np.zeros(n), np.zeros(n), np.ones(n, bool), (), (0, 0), 30.0)
        c.rows = [(j, f, 0.0, 40.0, 0.5) for j, f in found.items()]
        cands.append(c)
    out, n_ext = extend._merged(raw, [0, 1], cands, index, t_blk, utc_blk, gate_hz=25.0)
    assert n_ext == 2
    assert list(out[0].t_s) == [0.0, 1.0, 3.0] and list(out[1].t_s) == [6.0, 8.0, 9.0]
