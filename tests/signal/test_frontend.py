"""Front-end impairments: each generated (leosop generate / FrontEnd), then detected and measured against the
generated truth; the comb search through them; leosop doctor end to end."""

import json
import warnings

import numpy as np
import pytest

from leosop.cli import main
from leosop.errors import InputError
from leosop.signal.cleaning import clean_block
from leosop.signal.frontend import FrontEnd, _ar1, image_rejection_db, wiener_doppler_sigma_hz
from leosop.signal.iq import open_sigmf
from leosop.signal.multicomb import find_combs
from leosop.signal.pilot import PilotComb, add_noise
from leosop.signal.channel import doppler_blocks
from leosop.signal.survey import survey

FS = 2.5e6
SAT = "71585"  # above 40 deg from Xi'an at the default start


def _generate(path, *options, duration_s=0.3, sats=(SAT,)):
    assert main(["generate", "-o", str(path), "--sat", *sats, "--duration-s", str(duration_s),
                 "--sample-rate-hz", str(FS), "--cn0-model", "constant", "--cn0-dbhz", "45", "--seed", "5",
                 *options]) == 0
    return open_sigmf(path)


@pytest.fixture(scope="module")
def consumer(tmp_path_factory):
    """Three satellites through the consumer preset (ci8, LO 620 kHz off drifting 25 Hz/s, ...)."""
    path = tmp_path_factory.mktemp("fe") / "consumer.sigmf-meta"
    return _generate(path, "--front-end", "consumer", sats=(SAT, "70524", "71563"))


def test_consumer_preset_truth(consumer, capsys):
    capsys.readouterr()
    meta = json.loads(consumer.data_path.with_suffix(".sigmf-meta").read_text())["global"]
    fe = meta["leosop:front_end"]
    assert consumer.datatype == "ci8" and fe["preset"] == "consumer" and fe["bits"] == 8
    assert meta["leosop:rx_offset_hz"] == 620e3 and meta["leosop:rx_drift_hz_per_s"] == 25.0
    # Closed form of the image rejection of 0.5 dB / 2 deg: |K1|^2/|K2|^2 with K = (1 +- g e^-+j phi)/2.
    g, phi = 10 ** (0.5 / 20), np.radians(2.0)
    irr = 10 * np.log10(abs(1 + g * np.exp(-1j * phi)) ** 2 / abs(1 - g * np.exp(1j * phi)) ** 2)
    assert fe["image_rejection_db"] == pytest.approx(irr, abs=1e-9)


def test_each_impairment_measured(consumer):
    """DC, IQ imbalance and the CW line of the preset, measured in every block against the truth."""
    n = int(0.1 * FS)
    for start in (0, n, 2 * n):
        _, c = clean_block(consumer.read(start, n), FS, PilotComb())
        # DC and the CW line: 60 and 70 dB-Hz lines over 0.1 s are 50-60 dB above the noise of a bin:
        # their powers come out within 0.5 dB (the noise density from the spectrum's median: ~0.05 dB).
        assert c.dc_dbhz == pytest.approx(60.0, abs=0.5)
        assert len(c.lines) == 1
        assert c.lines[0].frequency_hz == pytest.approx(700e3, abs=FS / n)  # within a bin
        assert c.lines[0].power_dbhz == pytest.approx(70.0, abs=0.5)
        # IQ moments over 2.5e5 samples: sigma 0.017 dB and 0.11 deg (1/sqrt(n)); 5 sigma.
        assert c.iq_corrected and c.iq_gain_db == pytest.approx(0.5, abs=0.09)
        assert c.iq_phase_deg == pytest.approx(2.0, abs=0.6)


def test_combs_found_through_the_consumer_front_end(consumer):
    """Every satellite found at its truth once the LO offset is stated; nothing else (no image, no CW)."""
    n = int(0.1 * FS)
    for start in (0, n, 2 * n):
        truth = np.array([a["leosop:doppler_hz"] for a in consumer.annotations if a["core:sample_start"] == start])
        found = find_combs(consumer.read(start, n), FS, lo_offset_hz=620e3)
        assert found.n_found == truth.size
        err = np.sort(found.doppler_hz) - np.sort(truth)
        # The 0.01 Hz random-walk LO moves every comb alike by ~0.14 Hz rms per 0.1 s block
        # (wiener_doppler_sigma_hz); the thermal sigma is ~0.03 Hz. The common part is 5 sigma within 0.7 Hz,
        # the differences between combs at the thermal level (5 sigma of a difference: 0.25 Hz).
        assert abs(np.mean(err)) < 5 * float(wiener_doppler_sigma_hz(0.01, 0.1))
        assert np.ptp(err) < 0.25


def test_without_cleaning_the_front_end_breaks_the_search(consumer):
    """The reason for cleaning: the raw block's DC, CW line and images give spurious or missed combs."""
    n = int(0.1 * FS)
    truth = np.array([a["leosop:doppler_hz"] for a in consumer.annotations if a["core:sample_start"] == 0])
    raw = find_combs(consumer.read(0, n), FS, lo_offset_hz=620e3, clean=False)
    matched = [np.min(np.abs(raw.doppler_hz - d)) < 1.0 for d in truth] if raw.n_found else [False]
    assert raw.n_found != truth.size or not all(matched)


def test_image_of_a_strong_comb_is_not_a_satellite():
    """A 60 dB-Hz comb through a 2 dB / 10 deg imbalance (image rejection 17 dB): its image, a 43 dB-Hz comb
    at minus its Doppler, is found without cleaning and not with it."""
    rng = np.random.default_rng(3)
    n = int(0.1 * FS)
    x = add_noise(doppler_blocks(FS, n, 123_456.0, -2000.0, None, rng=rng, dtype=np.complex128)[0], 60.0, FS, rng)
    fe = FrontEnd(iq_gain_db=2.0, iq_phase_deg=10.0)
    y = fe.apply(x, np.arange(n) / FS, FS, 60.0, rng).astype(np.complex64)
    assert float(image_rejection_db(2.0, 10.0)) == pytest.approx(17.0, abs=0.5)
    raw = find_combs(y, FS, clean=False)
    assert np.any(np.abs(raw.doppler_hz + 123_456.0) < 5.0)  # the image, at minus the Doppler
    cleaned = find_combs(y, FS)
    assert cleaned.n_found == 1 and cleaned.doppler_hz[0] == pytest.approx(123_456.0, abs=0.05)


def test_wiener_phase_noise_sigma_closed_form():
    """The LS frequency of blocks of a tone under a Wiener LO phase spreads as sqrt(3 B / (5 pi T))."""
    fs, block_s, linewidth = 2000.0, 0.1, 1.0
    n_blocks = 400
    n = int(fs * block_s)
    fe = FrontEnd(phase_noise_linewidth_hz=linewidth)
    t = np.arange(n * n_blocks) / fs
    phase = np.unwrap(np.angle(fe.apply(np.ones(t.size), t, fs, 100.0, np.random.default_rng(7))))
    tau = t[:n] - t[:n].mean()
    slopes = (phase.reshape(n_blocks, n) @ tau) / (tau @ tau) / (2 * np.pi)
    # 400 blocks: the sample sigma is good to ~3.5 % (1/sqrt(2 n)); 12 % is 3.4 of those.
    assert np.std(slopes) == pytest.approx(float(wiener_doppler_sigma_hz(linewidth, block_s)), rel=0.12)


def test_pll_floor_phase_variance():
    """The bounded part: phase variance pi * corner * 10^(dBc/10) (a first-order low-pass of flat level)."""
    fs = 1e6
    fe = FrontEnd(phase_noise_dbc_hz=-60.0, phase_noise_corner_hz=10e3)
    t = np.arange(400_000) / fs
    phase = np.angle(fe.apply(np.ones(t.size), t, fs, 100.0, np.random.default_rng(8)))
    # 400k samples, correlation time 16 us: ~25 000 independent values, the variance good to ~1 %; 5 %.
    assert np.var(phase) == pytest.approx(np.pi * 10e3 * 1e-6, rel=0.05)


def test_pll_floor_recursion_late_in_a_recording():
    """Past t = 32 s float sample times jitter dt by ~ulp(t): still one recursion per capture."""
    fs, rate = 4e6, 2 * np.pi * 30e3
    t = np.concatenate([100.0 + np.arange(3000) / fs, 101.0 + np.arange(3000) / fs])  # a snapshot gap
    a = np.exp(-rate * np.diff(t, prepend=t[0] - 1 / fs))
    assert np.ptp(a[1:3000]) > 1e-9 * a[1]  # the jitter that split the old runs (rtol 1e-9)
    drive = np.random.default_rng(9).standard_normal(t.size)
    ref = np.empty(t.size)  # second implementation: the recursion sample by sample, each sample its own a
    x = 0.3
    for k in range(t.size):
        ref[k] = x = a[k] * x + drive[k]
    # Runs share a to 1e-5 of itself (frontend._ar1); the state is a sum of drives decaying by a per
    # sample, each off by < 1e-5 relative: 1e-5 of the |x| scale (~1/sqrt(1 - a^2) ~ 5) is the bound.
    np.testing.assert_allclose(_ar1(a, drive, 0.3), ref, rtol=0, atol=1e-5 * np.max(np.abs(ref)))


def test_agc_steps_leave_cn0_alone(tmp_path):
    """Gains stepping by up to +-10 dB between snapshots: each block is estimated on its own scale.
    (24 dB of headroom keeps a +10 dB step from clipping; at -10 dB the 8-bit step is 0.4 of the RMS, its
    quantisation noise 19 dB below the thermal noise.)"""
    rec = _generate(tmp_path / "agc.sigmf-meta", "--snapshot-s", "0.1", "--period-s", "0.5", "--agc-step-db", "10",
                    "--bits", "8", "--headroom-db", "24", duration_s=2.0)
    steps = json.loads(rec.data_path.with_suffix(".sigmf-meta").read_text())["global"]["leosop:front_end"]["agc_steps"]
    gains = np.array([s["gain_db"] for s in steps])
    assert gains.size == 4 and np.ptp(gains) > 3.0  # the draws really step
    levels = []
    for cap, gain in zip(rec.captures, gains):
        x = rec.read(cap.sample_start, cap.n_samples)
        found = find_combs(x, FS)
        truth = [a for a in rec.annotations if a["core:sample_start"] == cap.sample_start][0]
        assert found.n_found == 1
        # C/N0 of a 45 dB-Hz comb over 0.1 s: spread ~0.1 dB; the quantisation noise at most ~0.05 dB.
        assert found.cn0_dbhz[0] == pytest.approx(truth["leosop:cn0_dbhz"], abs=0.5)
        levels.append(10 * np.log10(np.mean(np.abs(x) ** 2)))
    # The recorded level follows the drawn gains (the noise dominates the power): within 0.2 dB
    # (8-bit rounding, and the noise power of 2.5e5 samples is good to 0.01 dB).
    assert np.allclose(np.diff(levels), np.diff(gains), atol=0.2)


@pytest.mark.parametrize("headroom_db, clip_expected", [(3.0, 0.1585), (12.0, 6.3e-5)])
def test_clipping_fraction(tmp_path, headroom_db, clip_expected):
    """Full scale at the headroom over the RMS: Gaussian components clip at 2 Q(10^(h/20)) (the noise dominates)."""
    rec = _generate(tmp_path / "c.sigmf-meta", "--bits", "8", "--headroom-db", str(headroom_db), duration_s=0.2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        doc = survey(rec, lo_offset_hz=0.0, n_blocks=2)
    # The reader warns once when a read clips (a Gaussian at 12 dB clips 6e-5: below its 1e-4 threshold).
    assert len([w for w in caught if "clipped" in str(w.message)]) == (1 if headroom_db < 6 else 0)
    # 2e5 samples x 2 components per block: binomial spread 1e-3 at 16 %, 1.3e-5 at 6e-5.
    assert doc["clipped_fraction"] == pytest.approx(clip_expected, abs=max(0.01, 5 * np.sqrt(clip_expected / 4e5)))
    assert (any("clipped" in f for f in doc["findings"])) == (headroom_db < 6)


def test_quantisation_bits_cost(tmp_path):
    """8, 12 and 16 bits at 12 dB headroom: the comb's C/N0 as measured in cf32, within 0.3 dB."""
    ref = None
    for bits in (None, 16, 12, 8):
        rec = _generate(tmp_path / f"b{bits}.sigmf-meta", *(["--bits", str(bits)] if bits else []), duration_s=0.1)
        found = find_combs(rec.read(0, rec.n_samples), FS)
        assert found.n_found == 1
        ref = found.cn0_dbhz[0] if ref is None else ref
        # 8 bits at 12 dB headroom: quantisation noise step^2/12 is ~-29 dB below the thermal noise.
        assert found.cn0_dbhz[0] == pytest.approx(ref, abs=0.3)


def test_doctor_on_the_consumer_preset(consumer, tmp_path, capsys):
    capsys.readouterr()
    status = main(["doctor", str(consumer.data_path.with_suffix(".sigmf-meta")), "--json", "--blocks", "3",
                   "--out", str(tmp_path / "doc")])
    out = capsys.readouterr().out
    assert status == 0
    doc = json.loads(out)
    assert doc["datatype"] == "ci8" and doc["status"] == "warnings"
    assert doc["dc_dbhz"] == pytest.approx(60.0, abs=0.5)
    assert doc["iq_gain_db"] == pytest.approx(0.5, abs=0.09) and doc["iq_phase_deg"] == pytest.approx(2.0, abs=0.6)
    assert [round(ln["frequency_hz"]) for ln in doc["interferers"]] == [700_000]
    assert doc["usable_satellites"] == 3 and doc["clipped_fraction"] == 0.0
    # Three satellites' geometric Dopplers spread over ~+-200 kHz: their median is within 250 kHz of the LO.
    assert abs(doc["lo_offset_hz_rough"] - 620e3) < 250e3
    assert {p.name for p in (tmp_path / "doc").iterdir()} == {"doctor.json", "spectrum.png"}


def test_band_cannot_hold_the_combs_at_the_stated_offset(consumer, capsys):
    status = main(["doctor", str(consumer.data_path.with_suffix(".sigmf-meta")), "--lo-offset-hz", "1.0e6"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "beyond the recording's band" in err


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_or_inf_samples_are_refused_by_the_cleaning(bad):
    """The cleaning's block mean is the NaN/inf check of the comb search and the replay's blocks (they no longer
    sum the samples themselves): one bad sample among 2e4 must raise, through find_combs too."""
    from leosop.signal.comb_grid import NonFiniteSamples

    x = add_noise(np.zeros(20_000, complex), 45.0, FS, np.random.default_rng(2)).astype(np.complex64)
    x[12_345] = bad
    with pytest.raises(NonFiniteSamples, match="NaN or inf"):
        clean_block(x, FS, PilotComb())
    with pytest.raises(NonFiniteSamples, match="NaN or inf"):
        find_combs(x, FS)


@pytest.mark.parametrize("cw_hz, off_hz, rate_hz_per_s", [(700e3, 50.0, 0.0), (700e3, 200.0, 0.0),
                                                          (700e3, 50.0, -3000.0), (700e3, -30.0, -3000.0),
                                                          (700_025.0, 2000.0, -3000.0)])
def test_cw_line_among_combs_is_excised(cw_hz, off_hz, rate_hz_per_s):
    """A 70 dB-Hz CW line whose whole tone spacings hold 45 dB-Hz comb tones is a line, not a comb tone.

    Issue 26: the consumer preset's line at +700 kHz, inside the span of dozens of combs, was kept. Here a
    comb sits ``off_hz`` from the line's multiples of the spacing (m = -2..-8), a second one 3 bins the
    other way (m = +1..+8); a 20 ms block has 50 Hz bins, so both are within the line's window of partners
    (its half-width, 4 bins, plus 3). Half a bin off (700 025 Hz) the line's sinc sidelobes stay above twice
    the noise for ~100 bins, and so does its window: a comb 2 kHz off is inside it. The combs must stay: their
    tones are each other's partners, chirped (-3 kHz/s smears a tone over 1.2 bins) or not."""
    fs, n = 4e6, 80_000
    sp = PilotComb().tone_spacing_hz
    rng = np.random.default_rng(11)
    dopplers = (cw_hz - 6 * sp + off_hz, cw_hz + 5 * sp - 150.0)
    x = sum(doppler_blocks(fs, n, d, rate_hz_per_s, None, rng=rng, dtype=np.complex128)[0] for d in dopplers)
    x = add_noise(x, 45.0, fs, rng)
    x = FrontEnd(cw=((cw_hz, 70.0),)).apply(x, np.arange(n) / fs, fs, 45.0, rng)
    _, c = clean_block(x, fs, PilotComb())
    # The line alone, 53 dB above a bin's noise: its power within 0.5 dB, its frequency within a bin.
    assert len(c.lines) == 1
    assert c.lines[0].frequency_hz == pytest.approx(cw_hz, abs=fs / n)
    assert c.lines[0].power_dbhz == pytest.approx(70.0, abs=0.5)


def test_line_runs_found_near_the_strong_bins_are_those_of_the_whole_spectrum():
    """find_lines smooths the spectrum only round its strong bins (cleaning._strong_runs); the runs must be
    exactly those of the smoothing of the whole spectrum (np.convolve "same", its former code): CW lines on
    the bin grid, half a bin off (sinc sidelobes above the level for ~100 bins: the windows must widen), at
    both edges of the spectrum, and a comb."""
    from leosop.signal.cleaning import _LINE_SMOOTH_BINS, _strong_runs, _window_max

    fs, n = 2.5e6, 250_000
    rng = np.random.default_rng(5)
    t = np.arange(n) / fs
    x = add_noise(np.zeros(n, complex), 45.0, fs, rng)
    for f_hz, cn0_dbhz in ((300e3, 70.0), (-410_005.0, 110.0), (fs / 2 - 20.0, 65.0), (-fs / 2 + 5.0, 75.0)):
        x = x + np.sqrt(10.0 ** (cn0_dbhz / 10.0) / fs) * np.exp(2j * np.pi * f_hz * t)
    x = x + doppler_blocks(fs, n, 20e3, -3000.0, None, rng=rng, dtype=np.complex128)[0]
    power = np.fft.fftshift(np.abs(np.fft.fft(x)) ** 2).astype(np.float32)
    for level in (2.0, 20.0):  # noise means (the exponential bins' mean is 1 here after scaling)
        p = power / np.median(power) * np.log(2.0)
        strong = np.flatnonzero(p > 30.0)
        smooth = np.convolve(p, np.full(_LINE_SMOOTH_BINS, 1.0 / _LINE_SMOOTH_BINS), mode="same")
        above = np.zeros(n, bool)
        above[strong] = True
        above |= smooth > level
        edges = np.diff(np.concatenate([[0], above.view(np.int8), [0]]))
        lo, hi = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        cs = np.concatenate([[0], np.cumsum(above & (p > 30.0))])
        held = cs[hi + 1] - cs[lo] > 0
        padded = np.concatenate([np.zeros(_LINE_SMOOTH_BINS // 2, p.dtype), p,
                                 np.zeros(_LINE_SMOOTH_BINS // 2 - 1, p.dtype)])
        got_lo, got_hi = _strong_runs(padded, strong, level)
        assert held.sum() >= 8 and np.max(hi[held] - lo[held]) > 100  # the wide sidelobes are there
        assert np.array_equal(got_lo, lo[held]) and np.array_equal(got_hi, hi[held])
    # The partners' windows read only their own bins: each window's max as a plain max (0 outside p).
    a = rng.integers(-50, n + 50, (40, 6))
    b = a + rng.integers(-3, 30, a.shape)
    want = [max(p[max(x, 0):max(min(y + 1, n), 0)], default=0.0) for x, y in zip(a.ravel(), b.ravel())]
    assert np.array_equal(_window_max(p, a, b), np.reshape(want, a.shape))


@pytest.mark.parametrize("seed", range(4))
def test_compiled_line_finding_gives_the_numpy_lines(seed):
    """cleankernels.line_runs (numba) against find_lines' numpy path: the same lines, bin for bin, on spectra
    with CW lines on and off the bin grid (wide sidelobe runs), at both edges, beside and among combs of
    7 satellites whose tones partner each other, and on noise alone; their powers to float rounding."""
    pytest.importorskip("numba")
    from leosop.signal.cleaning import find_lines

    fs, n = 2.5e6, 250_000
    comb = PilotComb()
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    x = add_noise(np.zeros(n, complex), 45.0, fs, rng)
    for d in rng.uniform(-0.4 * fs, 0.4 * fs, 7):
        x = x + doppler_blocks(fs, n, d, rng.uniform(-3000.0, 0.0), None, rng=rng, dtype=np.complex128)[0]
    if seed:  # seed 0: combs and noise alone
        for f_hz in rng.uniform(-fs / 2, fs / 2, 4 * seed).tolist() + [fs / 2 - 20.0, -fs / 2 + 5.0]:
            x = x + np.sqrt(10.0 ** (rng.uniform(55.0, 110.0) / 10.0) / fs) * np.exp(2j * np.pi * f_hz * t)
    power = (np.abs(np.fft.fft(x)) ** 2).astype(np.float32)
    lines = [find_lines(power, fs, comb, kernel=k) for k in ("numpy", "numba")]
    assert lines[0][1] == lines[1][1]  # the same noise estimate
    got = [[(ln.lo_bin, ln.hi_bin, ln.frequency_hz) for ln in found] for found, _ in lines]
    assert got[0] == got[1] and (len(got[0]) >= 4 * seed + 2 if seed else got[0] == [])
    np.testing.assert_allclose([ln.power_dbhz for ln in lines[1][0]], [ln.power_dbhz for ln in lines[0][0]],
                               rtol=0, atol=1e-9)


def test_excised_block_spectrum_is_the_fft_of_the_cleaned_block():
    """With a line excised the cleaning hands on its spectrum, the line's bins zeroed, as the cleaned block's FFT
    (the replay's comb search takes it instead of a second FFT): numpy's FFT of the cleaned samples agrees to
    the float32 rounding of the samples (~1e-7 of the largest bin, 1e-6 with margin)."""
    fs, n = 2.5e6, 50_000
    rng = np.random.default_rng(12)
    x = add_noise(doppler_blocks(fs, n, 40e3, -2000.0, None, rng=rng, dtype=np.complex128)[0], 45.0, fs, rng)
    x = FrontEnd(cw=((300e3, 75.0),)).apply(x, np.arange(n) / fs, fs, 45.0, rng)
    y, c = clean_block(x, fs, PilotComb())
    (line,) = c.lines
    bins = np.arange(line.lo_bin, line.hi_bin + 1) % n
    assert np.all(c.spectrum[bins] == 0)
    ref = np.fft.fft(y.astype(complex))
    np.testing.assert_allclose(c.spectrum, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    # The line's bins of the cleaned block hold what rounding leaves: far below its 75 dB-Hz.
    assert np.max(np.abs(ref[bins])) < 1e-5 * np.abs(np.fft.fft(x)[bins]).max()


def test_cw_skirt_taken_out_beside_the_run():
    """A 75 dB-Hz CW line between two bins leaks up to E / (pi^2 m^2) into the bin m bins away: twice the noise
    still 5 kHz out, past the run that is excised. After cleaning, the 2,000 bins beside the run (10 kHz either
    side) hold the noise alone: their mean power within 5 sigma of the noise mean (sigma 1 / sqrt(2000) of an
    exponential mean); before, the same bins held 1.3x it or more (the test's own check that the skirt was
    there)."""
    fs, n = 2.5e6, 250_000
    rng = np.random.default_rng(7)
    x = FrontEnd(cw=((300_004.0, 75.0),)).apply(add_noise(np.zeros(n, complex), 45.0, fs, rng), np.arange(n) / fs,
                                                 fs, 45.0, rng).astype(np.complex64)
    _, c = clean_block(x, fs, PilotComb())
    (line,) = c.lines
    noise_bin = c.noise_density * n * fs
    beside = np.concatenate([np.arange(line.lo_bin - 1000, line.lo_bin),
                             np.arange(line.hi_bin + 1, line.hi_bin + 1001)])
    after = np.mean(np.abs(c.spectrum[beside % n].astype(complex)) ** 2) / noise_bin
    before = np.mean(np.abs(np.fft.fft(x.astype(complex))[beside % n]) ** 2) / noise_bin
    assert before > 1.3
    assert abs(after - 1.0) < 5.0 / np.sqrt(beside.size)


@pytest.mark.parametrize("seed", [7, 8, 15, 18])
def test_no_spurious_comb_beside_a_cw_line(seed):
    """Two combs at 45 dB-Hz and a 64-80 dB-Hz CW line anywhere in the band (off the bin grid), as a real
    front end's spur: find_combs on the cleaned block finds the two combs and nothing else. These draws
    gave one or two spurious combs (statistic ~3, a tone on the line's skirt) before the skirt was taken
    out (:func:`leosop.signal.cleaning._subtract_skirt`); excising the skirt instead (+-25 kHz holes) put
    combs with a tone in the hole one tone spacing off."""
    fs, n = 2.5e6, 250_000
    rng = np.random.default_rng(seed)
    f_cw, p_cw = rng.uniform(-1e6, 1e6), rng.uniform(60, 80)
    sats = [(rng.uniform(-250e3, 250e3), rng.uniform(-3000, 0)) for _ in range(2)]
    x = sum(add_noise(doppler_blocks(fs, n, f, r, None, rng=rng, dtype=np.complex128)[0], 45.0, fs, rng) / 2
            for f, r in sats)
    x = FrontEnd(cw=((f_cw, p_cw),), dc_dbhz=60.0, iq_gain_db=0.5, iq_phase_deg=2.0).apply(
        x, np.arange(n) / fs, fs, 45.0, rng).astype(np.complex64)
    y, c = clean_block(x, fs, PilotComb())
    found = find_combs(y, fs, clean=False, spectrum=c.spectrum, max_combs=4)
    assert found.n_found == 2
    # Within a few bins of the truth (10 Hz each): neither a spurious comb nor one a tone spacing off.
    np.testing.assert_allclose(np.sort(found.doppler_hz), np.sort([f for f, _ in sats]), atol=50.0)


def test_clean_spectrum_is_clean_blocks_spectrum():
    """clean_spectrum (the replay's preparation: the FFT in place, no block in time) against clean_block on a block
    with a CW line, DC and IQ imbalance: the same DC, imbalance and lines, and the same spectrum to FFTW's rounding
    (in and out of place take different codelets; the rounding scales with the largest bin before excision, the
    line's: ~1e-7 of it seen, 1e-6 with margin). find_combs
    from that spectrum alone (iq=None) finds the combs the block does, to the spectrum's rounding (the same
    bound on Doppler over its sigma as the compiled path's test, 1e-4)."""
    from leosop.signal.cleaning import clean_spectrum

    fs, n = 2.5e6, 250_000
    rng = np.random.default_rng(3)
    x = sum(add_noise(doppler_blocks(fs, n, f, r, None, rng=rng, dtype=np.complex128)[0], 45.0, fs, rng) / 2
            for f, r in ((40e3, -2000.0), (-120e3, -1500.0)))
    x = FrontEnd(cw=((300e3, 75.0),), dc_dbhz=60.0, iq_gain_db=0.5, iq_phase_deg=2.0).apply(
        x, np.arange(n) / fs, fs, 45.0, rng).astype(np.complex64)
    y, a = clean_block(x, fs, PilotComb())
    b = clean_spectrum(x, fs, PilotComb())
    assert (a.dc, a.iq_gain_db, a.iq_phase_deg, a.iq_corrected) == (b.dc, b.iq_gain_db, b.iq_phase_deg, b.iq_corrected)
    assert len(b.lines) == 1 and b.iq_corrected
    assert [(ln.frequency_hz, ln.lo_bin, ln.hi_bin) for ln in a.lines] == \
        [(ln.frequency_hz, ln.lo_bin, ln.hi_bin) for ln in b.lines]
    assert b.lines[0].power_dbhz == pytest.approx(a.lines[0].power_dbhz, abs=1e-4)  # the bins' float32 rounding
    # FFTW's rounding scales with the block's largest bin before excision (the CW line's).
    top = np.abs(np.fft.fft(x)).max()
    np.testing.assert_allclose(b.spectrum, a.spectrum, rtol=0, atol=1e-6 * top)
    with_iq = find_combs(y, fs, clean=False, spectrum=a.spectrum, max_combs=4)
    alone = find_combs(None, fs, clean=False, spectrum=b.spectrum, max_combs=4)
    assert with_iq.n_found == alone.n_found == 2
    np.testing.assert_array_less(np.abs(alone.doppler_hz - with_iq.doppler_hz), 1e-4 * with_iq.sigma_hz)
    # A block whose decimation grid pads (n_seg * seg > n): the block in time comes from the spectrum.
    y, a = clean_block(x[:249_997], fs, PilotComb())
    b = clean_spectrum(x[:249_997], fs, PilotComb())
    with_iq = find_combs(y, fs, clean=False, spectrum=a.spectrum, max_combs=4)
    alone = find_combs(None, fs, clean=False, spectrum=b.spectrum, max_combs=4)
    assert with_iq.n_found == alone.n_found == 2  # no spurious comb beside the CW line off this size's bin grid
    np.testing.assert_array_less(np.abs(alone.doppler_hz - with_iq.doppler_hz), 1e-4 * with_iq.sigma_hz)
    with pytest.raises(InputError, match="iq=None"):
        find_combs(None, fs, spectrum=b.spectrum)


def test_iq_moments_against_float64():
    """The imbalance from two complex64 dot products against the same moments summed in float64: their float32
    sums lose ~4e-6 of the moments over 2.5e5 samples, 1e-3 dB and 3e-4 deg (2x the worst seen on the consumer
    preset), 1/17 and 1/400 of the estimate's own sigma. The correction with the true parameters undoes the
    front end's model (to the float32 rounding of the samples), in place or not to the same bits."""
    from leosop.signal.cleaning import correct_iq, iq_imbalance

    n = 250_000
    rng = np.random.default_rng(13)
    x0 = add_noise(np.zeros(n, complex), 45.0, FS, rng) + 0.3 * np.exp(0.7j)
    x = FrontEnd(iq_gain_db=0.5, iq_phase_deg=2.0).apply(x0, np.arange(n) / FS, FS, 45.0, rng).astype(np.complex64)
    gain_db, phase_deg, s_gain, s_phase = iq_imbalance(x)
    y = x.astype(complex) - x.astype(complex).mean()
    pi, pq, piq = y.real @ y.real, y.imag @ y.imag, y.real @ y.imag
    assert gain_db == pytest.approx(10 * np.log10(pq / pi), abs=1e-3)
    assert phase_deg == pytest.approx(np.degrees(np.arcsin(-piq / np.sqrt(pi * pq))), abs=3e-4)
    assert s_gain == pytest.approx(20 / np.log(10) / np.sqrt(n)) and s_phase == pytest.approx(np.degrees(n ** -0.5))
    got = correct_iq(x, 0.5, 2.0)
    np.testing.assert_allclose(got, x0, rtol=0, atol=1e-6 * np.abs(x0).max())  # float32: ~6e-8 of the largest
    assert np.array_equal(correct_iq(x, 0.5, 2.0, out=x), got) and np.array_equal(x, got)
