"""Starlink OFDM frame, its reception, PSS acquisition and tracking (leosop.signal.ofdm).

References: [Humphreys 2023] for the frame layout and PSS construction;
m-sequence properties (balance, two-valued autocorrelation) are textbook
facts of maximal-length sequences.
"""

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.signal import ofdm
from leosop.signal.pss_track import REACQUIRE_SAMPLES
from leosop.signal.doppler import estimate_block
from leosop.signal.error_model import doppler_sigma_hz
from leosop.signal.pilot import PilotComb, add_noise

CH_HZ = 11.325e9


def test_mseq_is_maximal_length():
    c = ofdm.pss_mseq().astype(int)
    assert c.size == 127
    # Periodic recurrence of the taps (3, 7): c[i] = c[i-3] xor c[i-7] for all i mod 127,
    # so the sequence repeats with period 127 (prime, and c is not constant).
    i = np.arange(127)
    assert np.array_equal(c, c[(i - 3) % 127] ^ c[(i - 7) % 127])
    assert c.sum() == 64 and (c == 0).sum() == 63
    s = 1 - 2 * c
    acf = np.array([np.dot(s, np.roll(s, k)) for k in range(127)])
    assert acf[0] == 127 and np.all(acf[1:] == -1)


def test_pss_structure():
    pss = ofdm.pss_time()
    assert pss.shape == (ofdm.N_SYMBOL,)
    assert np.allclose(np.abs(pss), 1.0, atol=1e-12)
    useful = pss[ofdm.N_CP:]
    seg = useful.reshape(ofdm.N_PSS_SEGMENTS, ofdm.PSS_SEGMENT_LEN)
    assert np.allclose(seg[0], -seg[1], atol=1e-12)
    assert np.allclose(seg[1:], seg[1], atol=1e-12)
    assert np.allclose(pss[:ofdm.N_CP], -useful[-ofdm.N_CP:], atol=1e-12)
    # Phase walk: start -pi/4, step -pi/2 * (2b - 1) over b = [0, reversed m-sequence].
    b = np.concatenate(([0], ofdm.pss_mseq()[::-1])).astype(int)
    steps = seg[1] / np.concatenate(([np.exp(-1j * np.pi / 4)], seg[1][:-1]))
    assert np.allclose(steps, np.exp(-0.5j * np.pi * (2 * b - 1)), atol=1e-12)


def test_frame_layout_and_symbols():
    x = ofdm.frame(np.random.default_rng(3))
    assert x.shape == (320_000,) == (ofdm.FRAME_SAMPLES,)
    assert ofdm.N_SYMBOLS_PER_FRAME * ofdm.N_SYMBOL + ofdm.N_GUARD == 320_000
    assert ofdm.FRAME_PERIOD_S == pytest.approx(1 / 750, rel=1e-15)
    assert np.array_equal(x[-ofdm.N_GUARD:], np.zeros(ofdm.N_GUARD))
    assert np.allclose(x[:ofdm.N_SYMBOL], np.sqrt(ofdm.N_FFT) * ofdm.pss_time(), atol=1e-9)
    sym = x[ofdm.N_SYMBOL:302 * ofdm.N_SYMBOL].reshape(301, ofdm.N_SYMBOL)
    assert np.allclose(sym[:, :ofdm.N_CP], sym[:, -ofdm.N_CP:], atol=1e-9)  # cyclic prefix
    spec = np.fft.fft(sym[:, ofdm.N_CP:], axis=-1) / ofdm.N_FFT  # unit-amplitude subcarriers
    k = np.fft.fftfreq(ofdm.N_FFT, 1.0 / ofdm.N_FFT).astype(int)
    gutter = np.isin(k, ofdm.GUTTER_SUBCARRIERS)
    assert np.allclose(spec[:, gutter], 0.0, atol=1e-9)
    q = spec[:, ~gutter] * np.sqrt(2)
    assert np.allclose(np.abs(q.real), 1.0, atol=1e-9) and np.allclose(np.abs(q.imag), 1.0, atol=1e-9)
    assert (~gutter).sum() == ofdm.active_subcarriers().size == ofdm.N_FFT - 4


def _geometry(t, doppler_hz=3e5, rate_hz_per_s=-3e3):
    return doppler_hz * t + 0.5 * rate_hz_per_s * t**2


def test_generator_frame_at_zero_doppler():
    link = ofdm.OfdmDownlink(ofdm.FS_HZ, comb=None, seed=7)
    t = np.arange(3 * ofdm.N_SYMBOL) / ofdm.FS_HZ
    y = link.samples(t, 0.0) * np.exp(-2j * np.pi * ofdm.OFDM_CENTER_OFFSET_HZ * t)
    assert np.allclose(y[:ofdm.N_SYMBOL], np.sqrt(ofdm.N_FFT) * ofdm.pss_time(), atol=1e-8)
    spec = np.fft.fft(y[ofdm.N_SYMBOL + ofdm.N_CP:2 * ofdm.N_SYMBOL]) / ofdm.N_FFT
    assert np.allclose(spec, link.frame_spectra(0)[1], atol=1e-9)


def test_direct_and_ifft_paths_agree():
    # Two implementations of the same sum: Horner in exp(j 2 pi u / N) over 42 in-band
    # subcarriers, and IFFTs with a 16-term Taylor series of the fractional sample
    # (remainder < 1e-11); with Doppler, code Doppler and a frame boundary inside.
    link = ofdm.OfdmDownlink(ofdm.FS_HZ, comb=None, band_hz=10e6, frame_offset_s=-1.3e-3)
    t = np.arange(0, 40_000) / ofdm.FS_HZ
    g = _geometry(t)
    pos = (t - link.frame_offset_s) * ofdm.FS_HZ + g * ofdm.FS_HZ / CH_HZ
    m = np.floor(pos / ofdm.FRAME_SAMPLES).astype(int)
    p = pos - m * ofdm.FRAME_SAMPLES
    sym = np.minimum(np.floor(p / ofdm.N_SYMBOL).astype(int), 302)
    u = p - sym * ofdm.N_SYMBOL - ofdm.N_CP
    live = sym < 302
    assert np.unique(m).size == 2
    k = link.subcarriers
    a = link._direct(m, sym, u, live, k)
    b = link._taylor(m, sym, u, live, k)
    assert np.max(np.abs(a - b)) < 1e-9 * np.max(np.abs(a))


@pytest.mark.parametrize("fs, n", [(2.5e6, 9_000), (ofdm.FS_HZ, 400_000)])
def test_chunked_equals_one_shot(fs, n):
    link = ofdm.OfdmDownlink(fs, seed=11, frame_offset_s=0.2e-3)
    t = np.arange(n) / fs
    whole = link.samples(t, _geometry(t), 250.0 * t)
    cuts = [0, 1234, n // 2 + 17, n]
    parts = [link.samples(t[a:b], _geometry(t[a:b]), 250.0 * t[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]
    # Every sample depends only on its own instant: equal to rounding.
    assert np.allclose(np.concatenate(parts), whole, rtol=0, atol=1e-12 * np.max(np.abs(whole)))


def test_comb_doppler_recovered_on_ofdm_recording():
    # A 2.5 MS/s recording centred on the comb holds 6 active subcarriers (+-2.5..4.5 F)
    # beside the comb in the gutter; estimate_block must still reach the comb's CRLB.
    fs, n, cn0 = 2.5e6, 300_000, 40.0
    link = ofdm.OfdmDownlink(fs, seed=2, frame_offset_s=0.5e-3)
    assert link.subcarriers.size == 10  # k = -5..4, of which -2..1 is the gutter
    rng = np.random.default_rng(5)
    errors = []
    for i in range(8):
        t = (i * n + np.arange(n)) / fs
        d0, rate, clock = -2.1e5 + 3e4 * i, -2.5e3, 1.7e3
        g = d0 * t + 0.5 * rate * t**2
        iq = add_noise(link.samples(t, g, clock * t), cn0, fs, rng)
        est = estimate_block(iq, fs)
        t_mid = t[0] + 0.5 * (n - 1) / fs
        errors.append(est["doppler_hz"] - (d0 + rate * t_mid + clock))
    sigma = doppler_sigma_hz(cn0, n / fs, sample_rate_hz=fs)
    # 8 draws of a CRLB-limited estimator: each within 4 sigma, rms within 1.6 sigma
    # (chi-square, 8 dof: P(rms > 1.6 sigma) ~ 0.3 %); OFDM leakage into the gutter is
    # >20 dB below the noise density at 40 dB-Hz.
    assert np.all(np.abs(errors) < 4 * sigma)
    assert np.sqrt(np.mean(np.square(errors))) < 1.6 * sigma


def _frame_starts_s(frame_time_s, doppler_hz, rate_hz_per_s):
    """Receive time where t + g(t)/f_ch reaches ``frame_time_s``, g = d t + r t^2 / 2 (the stable root)."""
    a, b = 0.5 * rate_hz_per_s / CH_HZ, 1 + doppler_hz / CH_HZ
    return 2 * frame_time_s / (b + np.sqrt(b * b + 4 * a * frame_time_s))


@pytest.fixture(scope="module")
def snippet():
    """4 ms at 240 MS/s (3 frames): +300 kHz Doppler and -2 kHz/s, +30 kHz receiver offset."""
    fs, n = ofdm.FS_HZ, 960_000
    t = np.arange(n) / fs
    link = ofdm.OfdmDownlink(fs, seed=4, frame_offset_s=0.41e-3)
    return link, t, link.samples(t, _geometry(t, 3e5, -2e3), 3e4 * t)


@pytest.mark.parametrize("snr_db", [10.0, -5.0])
def test_acquisition_recovers_timing_and_doppler(snippet, snr_db):
    link, t, clean = snippet
    rng = np.random.default_rng(int(snr_db) + 100)
    sigma = np.sqrt(1020 / 10 ** (snr_db / 10) / 2)  # OFDM power 1020 per sample
    iq = (clean + sigma * (rng.standard_normal(t.size) + 1j * rng.standard_normal(t.size))).astype(np.complex64)
    res = ofdm.acquire_pss(iq)
    assert res.detected and res.frame_number.tolist() == [0, 1, 2]
    truth_s = _frame_starts_s(link.frame_offset_s + res.frame_number * ofdm.FRAME_PERIOD_S, 3e5, -2e3)
    # Measured: within 0.02 samples at 30 dB (0.013 of it the PSS's code-Doppler stretch, 544 samples
    # times 2.6e-5), within 0.15 at -5 dB over 3 offsets x 3 frames; a parabola through |c|^2
    # was off by up to 0.33 samples.
    assert np.all(np.abs(res.frame_start_s - truth_s) * ofdm.FS_HZ < 0.25)
    # Doppler of the OFDM centre at the snippet's middle (a 2 ms mean of the chirp):
    truth_hz = (3e5 - 2e3 * 2e-3) * (1 + ofdm.OFDM_CENTER_OFFSET_HZ / CH_HZ) + 3e4
    # Measured rms error 1.9 kHz at 0 dB and 3.4 kHz at -5 dB over 10 seeds (3 frames):
    # 15 kHz is > 4 sigma at -5 dB, and 1/15 of the 234 kHz subcarrier spacing.
    assert abs(res.doppler_hz - truth_hz) < 15e3
    assert res.frame_period_s * (1 + 3e5 / CH_HZ) == pytest.approx(ofdm.FRAME_PERIOD_S, abs=2 / ofdm.FS_HZ)


def test_acquisition_on_noise_is_not_detected():
    rng = np.random.default_rng(9)
    iq = (rng.standard_normal(700_000) + 1j * rng.standard_normal(700_000)).astype(np.complex64)
    assert not ofdm.acquire_pss(iq).detected


def test_bad_input():
    with pytest.raises(InputError, match="sample_rate_hz"):
        ofdm.acquire_pss(np.zeros(400_000, complex), 2.5e6)
    with pytest.raises(InputError, match="at least"):
        ofdm.acquire_pss(np.zeros(1000, complex))
    with pytest.raises(InputError, match="channel"):
        ofdm.OfdmDownlink(2.5e6, channel_hz=11.3e9)
    with pytest.raises(InputError, match="comb"):
        ofdm.OfdmDownlink(2.5e6, channel_hz=11.575e9, comb=PilotComb())


def test_frame_timing_jumps_are_seeded_per_step_and_cumulative():
    jumps = ofdm.FrameTimingJumps(300e-9, period_s=0.5, seed=(7, 2))
    steps = jumps.steps_s(3)
    assert np.array_equal(steps[:2], jumps.steps_s(2))  # step j depends on j alone
    assert np.array_equal(jumps.offset_s([-1.0, 0.2, 0.5, 1.2, 1.6]), [0, 0, steps[0], steps[:2].sum(), steps.sum()])
    with pytest.raises(InputError, match="sigma_s"):
        ofdm.FrameTimingJumps(-1e-9)


def _jumping_recording(n_frames, jumps, snr_db, seed):
    """+300 kHz, -2 kHz/s, +30 kHz receiver offset at 240 MS/s with frame-timing jumps; truth starts [s].

    Samples are synthesised within REACQUIRE_SAMPLES + 64 of each PSS, noise
    elsewhere: the tracker reads nothing else, and the acquisition's lag-128
    metric sees no coherence in data symbols, as in noise (synthesising the
    frames whole would take ~0.4 s each).
    """
    link = ofdm.OfdmDownlink(ofdm.FS_HZ, seed=4, frame_offset_s=0.41e-3, timing_jumps=jumps)
    frame_time_s = link.frame_offset_s + np.arange(n_frames) * ofdm.FRAME_PERIOD_S
    truth_s = _frame_starts_s(frame_time_s + jumps.offset_s(frame_time_s - link.frame_offset_s), 3e5, -2e3)
    n = int(round((truth_s[-1] + ofdm.FRAME_PERIOD_S) * ofdm.FS_HZ))
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(1020 / 10 ** (snr_db / 10) / 2)
    iq = (sigma * (rng.standard_normal(n) + 1j * rng.standard_normal(n))).astype(np.complex64)
    margin = REACQUIRE_SAMPLES + 64
    near = np.unique(np.concatenate([np.arange(max(int(s * ofdm.FS_HZ) - margin, 0),
                                               min(int(s * ofdm.FS_HZ) + margin + ofdm.N_SYMBOL, n)) for s in truth_s]))
    t = near / ofdm.FS_HZ
    iq[near] += link.samples(t, _geometry(t, 3e5, -2e3), 3e4 * t).astype(np.complex64)
    return iq, truth_s


@pytest.fixture(scope="module")
def jumping():
    """Steps every 3.9 ms (seed 1: +160 ns before frame 3, -360 ns before frame 6, Qin et al. 2025's size),
    7 frames at -5 dB per sample: the jumps, the samples and the truth starts [s]."""
    jumps = ofdm.FrameTimingJumps(300e-9, period_s=3.9e-3, seed=(1,))
    return (jumps, *_jumping_recording(7, jumps, -5.0, 21))


def test_tracking_flags_frame_timing_jumps_and_keeps_the_doppler(jumping):
    jumps, iq, truth_s = jumping
    track = ofdm.track_pss(iq, channel_hz=CH_HZ)
    assert track.frame_number.tolist() == list(range(7)) and track.found.all()
    assert np.flatnonzero(track.jump).tolist() == [3, 6]
    # Steps measured as the start minus its prediction: timing noise ~0.05 sample (0.2 ns) rms each.
    assert np.allclose(track.jump_s[[3, 6]], jumps.steps_s(2), rtol=0, atol=1e-9)
    # Measured within 0.04 samples; 0.25 as for the acquisition.
    assert np.all(np.abs(track.frame_start_s - truth_s) * ofdm.FS_HZ < 0.25)
    # Code Doppler of the 3-frame segments: LS slope of 3 starts, sigma ~0.03 sample per frame = 1 kHz;
    # 4 kHz. Across a jump the same fit errs by f_ch x 160 ns / 2 frames, ~700 kHz.
    geometric_hz = 3e5 - 2e3 * track.frame_start_s
    assert np.all(np.abs(track.code_doppler_hz[:6] - geometric_hz[:6]) < 4e3)
    across = np.polyfit(np.arange(6), track.frame_start_s[:6], 1)[0]
    assert abs(CH_HZ * (ofdm.FRAME_PERIOD_S / across - 1) - geometric_hz[3]) > 1e5
    assert track.segment.tolist() == [0, 0, 0, 1, 1, 1, 2] and np.isnan(track.code_doppler_hz[6])
    # Carrier per frame from one PSS: the phase of its halves, sigma ~6 kHz at -5 dB; 25 kHz is > 4 sigma.
    carrier_hz = geometric_hz * (1 + ofdm.OFDM_CENTER_OFFSET_HZ / CH_HZ) + 3e4
    assert np.all(np.abs(track.doppler_hz - carrier_hz) < 25e3)


def test_tracking_bad_input():
    with pytest.raises(InputError, match="sample_rate_hz"):
        ofdm.track_pss(np.zeros(400_000, complex), sample_rate_hz=2.5e6)
    with pytest.raises(InputError, match="jump_threshold_s"):
        ofdm.track_pss(np.zeros(400_000, complex), jump_threshold_s=0.0)


def test_replay_tracks_the_first_capture_from_the_file(jumping, tmp_path):
    # The replay's PSS stage reads the recording window by window (SigMF, cf32): the same track as
    # from the array.
    from leosop.replay.pipeline import _pss
    from leosop.signal.iq import open_sigmf
    from leosop.signal.iq_write import write_sigmf

    _, iq, _ = jumping
    meta = tmp_path / "ofdm.sigmf-meta"
    write_sigmf(meta, [iq], sample_rate_hz=ofdm.FS_HZ, center_hz=CH_HZ,
                start_utc=np.datetime64("2025-01-01T19:40:00", "ns"))
    acq, _, track = _pss(open_sigmf(meta))
    assert np.flatnonzero(track.jump).tolist() == [3, 6]
    direct = ofdm.track_pss(iq, acq, channel_hz=CH_HZ)
    assert np.array_equal(track.frame_start_s, direct.frame_start_s)
