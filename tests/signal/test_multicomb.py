"""find_combs: every comb in a block, by simulate-and-recover against the Cramér-Rao bound."""

import importlib.util

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.signal.channel import doppler_blocks
from leosop.signal.doppler import estimate_block
from leosop.signal.error_model import doppler_sigma_hz
from leosop.signal.multicomb import find_combs
from leosop.signal.pilot import PilotComb, add_noise

FS = 2.5e6
N = 125_000  # 0.05 s blocks
SPACING_HZ = PilotComb().tone_spacing_hz


def _block(rng, doppler_hz, rate_hz_per_s, cn0_dbhz, n=N):
    """Sum of noise-free combs scaled to their C/N0, plus noise for a unit tone at the highest C/N0."""
    cn0 = np.broadcast_to(np.asarray(cn0_dbhz, dtype=float), np.shape(doppler_hz))
    top = float(np.max(cn0))
    clean = doppler_blocks(FS, n, doppler_hz, rate_hz_per_s, None, rng=rng, dtype=np.complex128)
    amp = 10.0 ** ((cn0 - top) / 20.0)
    return add_noise(amp @ clean, top, FS, rng).astype(np.complex64)


def _match(found_hz, true_hz):
    """Index of the found comb nearest each true one."""
    return np.argmin(np.abs(found_hz[None, :] - np.asarray(true_hz)[:, None]), axis=1)


def test_single_comb_equals_estimate_block():
    rng = np.random.default_rng(1)
    x = _block(rng, [12345.6], [-3000.0], 45.0)
    ref = estimate_block(x, FS)
    got = find_combs(x, FS)
    assert got.n_found == 1
    # Same coarse search and Newton; the decimation keeps only the four aliased
    # bands either side of each channel (estimate_block sums all of them), so
    # ~4 % of the decimated noise power differs: estimates agree to a small
    # fraction of sigma (0.03 sigma rms over 40 blocks). The noise estimate sees
    # a different 4 % of the noise: C/N0 differs by ~0.1 dB per block (0.03 dB
    # in the mean over 40 blocks, both within 0.05 dB of the truth).
    tol = 0.1 * ref["sigma_hz"]
    assert abs(got.doppler_hz[0] - ref["doppler_hz"]) < tol
    assert abs(got.doppler_rate_hz_per_s[0] - ref["doppler_rate_hz_per_s"]) < 1.0
    assert got.cn0_dbhz[0] == pytest.approx(ref["cn0_dbhz"], abs=0.2)
    # find_combs fits every comb jointly, so its sigma is the Cramer-Rao bound;
    # the single-comb estimator's sigma may grow with unmodelled tones in its
    # residual, so the like-for-like number is its bound.
    assert got.sigma_hz[0] == pytest.approx(ref["crlb_sigma_hz"], rel=0.03)


def test_frequency_domain_decimation_is_integrate_and_dump():
    # Tones on the block's FFT bins within the kept aliases of a channel: the
    # frequency-domain decimation equals the integrate-and-dump sum written out
    # (segments of L samples, mixed at f_c). A channel on a bin: to float32
    # rounding of the input. A channel eps off the bin grid is rotated at the
    # segment centres: first-order error 2 pi eps (L / fs) times the tone's
    # offset times L / fs, here <= 2 pi 10 Hz 0.25 ms * 1 kHz 0.25 ms = 4e-3.
    from leosop.signal.comb_grid import ALIAS_BANDS, DecimationGrid

    n, fs = 125_000, 2.5e6
    df = fs / n
    rng = np.random.default_rng(3)
    t = np.arange(n) / fs
    n_seg = DecimationGrid(np.zeros(n, dtype=np.complex64), fs, 500.0).n_seg
    for f_c, reach, tol in ((200 * df, ALIAS_BANDS * n_seg, 1e-5), (-55_551.2, 50, 4e-3)):
        x = np.zeros(n, dtype=complex)
        for k in rng.integers(-reach, reach, 5):
            x += rng.normal() * np.exp(2j * np.pi * ((np.round(f_c / df) + k) * df * t + rng.uniform()))
        grid = DecimationGrid(x.astype(np.complex64), fs, 500.0)
        got = grid.channels([f_c])[:, 0]
        ref = (x * np.exp(-2j * np.pi * f_c * t)).reshape(n_seg, -1).sum(axis=1)
        assert np.max(np.abs(got - ref)) < tol * np.max(np.abs(ref))


def _seven(seed, n_blocks):
    rng = np.random.default_rng(seed)
    for _ in range(n_blocks):
        d = rng.uniform(-2.5e5, 2.5e5, 7)
        r = rng.uniform(-4500.0, 1000.0, 7)
        cn0 = rng.uniform(40.0, 50.0, 7)
        yield d, r, cn0, _block(rng, d, r, cn0)


def test_seven_combs_reach_the_bound():
    errors, found = [], []
    for d, r, cn0, x in _seven(seed=20, n_blocks=10):
        got = find_combs(x, FS)
        found.append(got.n_found)
        j = _match(got.doppler_hz, d)
        errors.append((got.doppler_hz[j] - d) / doppler_sigma_hz(cn0, N / FS))
    assert found == [7] * len(found)  # no missed or spurious comb
    z = np.concatenate(errors)
    # 70 normalised errors: their RMS has a standard error of ~1/sqrt(2*70) = 0.085;
    # the goal 1.2x the whole-comb bound plus two of those.
    assert np.sqrt(np.mean(z**2)) < 1.2 + 2 * 0.085
    assert np.max(np.abs(z)) < 4.5  # no outlier (P(|N(0,1)| > 4.5 in 70) ~ 5e-4)


def test_tracking_recovers_the_full_search():
    d, r, cn0, x = next(_seven(seed=21, n_blocks=1))
    full = find_combs(x, FS)
    rng = np.random.default_rng(4)
    # Predictions a few Hz and tens of Hz/s off (what the previous blocks give).
    pred = full.doppler_hz + rng.uniform(-5.0, 5.0, full.n_found)
    pred_rate = full.doppler_rate_hz_per_s + rng.uniform(-20.0, 20.0, full.n_found)
    track = find_combs(x, FS, predicted_hz=pred, predicted_rate_hz_per_s=pred_rate, search=False)
    assert list(track.predicted_index) == list(range(full.n_found))
    # Both approach the joint ML, from different decimations: tracking keeps a
    # band just wide enough for the predicted chirp (~100 segments, the search
    # ~500), so the two see different shares of the noise. Largest difference
    # over 7 combs in 9 such blocks: 0.16 sigma.
    assert np.all(np.abs(track.doppler_hz - full.doppler_hz) < 0.3 * full.sigma_hz)
    # A prediction where no comb is, is dropped; the search then finds nothing new.
    empty = find_combs(x, FS, predicted_hz=np.r_[pred, 280e3], predicted_rate_hz_per_s=np.r_[pred_rate, 0.0])
    assert empty.n_found == full.n_found
    assert np.all(np.abs(empty.doppler_hz - full.doppler_hz) < 0.3 * full.sigma_hz)


def test_batched_tracking_equals_one_at_a_time():
    # batch=True fits all predictions at once, then refines them all together
    # (Jacobi); batch=False fits them one after another, each cleaned of the ones
    # before (the search's order). Both approach the joint ML: 0.05 sigma apart
    # (measured <= 0.03 sigma at 0.1 s blocks, 0.01 at 0.05 s).
    d, r, cn0, x = next(_seven(seed=22, n_blocks=1))
    rng = np.random.default_rng(5)
    pred = d + rng.uniform(-5.0, 5.0, 7)
    pred_rate = r + rng.uniform(-20.0, 20.0, 7)
    kw = dict(predicted_hz=pred, predicted_rate_hz_per_s=pred_rate, search=False)
    one, batch = find_combs(x, FS, batch=False, **kw), find_combs(x, FS, **kw)
    assert list(batch.predicted_index) == list(one.predicted_index)
    assert np.all(np.abs(batch.doppler_hz - one.doppler_hz) < 0.05 * one.sigma_hz)
    rate_sigma = np.sqrt(60.0) * one.sigma_hz / (N / FS)  # the rate's bound, from the frequency's
    assert np.all(np.abs(batch.doppler_rate_hz_per_s - one.doppler_rate_hz_per_s) < 0.05 * rate_sigma)
    assert np.allclose(batch.cn0_dbhz, one.cn0_dbhz, atol=0.05)


def test_noise_only_false_alarms():
    rng = np.random.default_rng(6)
    blocks = [add_noise(np.zeros(25_000, dtype=complex), 45.0, FS, rng).astype(np.complex64) for _ in range(40)]
    loose = sum(find_combs(b, FS, pfa=0.5).n_found for b in blocks)
    strict = sum(find_combs(b, FS).n_found for b in blocks)
    # Documented: at most pfa per block (the detector's Bonferroni threshold is
    # conservative). Bin(40, 0.5) exceeds 29 with probability 1e-3; at least one
    # alarm shows the threshold is not infinite (measured rate ~0.3).
    assert 1 <= loose <= 29
    assert strict == 0  # pfa = 1e-3: P(any in 40) < 0.04


def test_resolvable_near_coincidence():
    # Second comb one spacing plus 150 Hz (7.5 bins) away, 2 kHz/s apart in rate:
    # eight tones overlap; the joint chirp model separates them.
    rng = np.random.default_rng(7)
    d = np.array([30e3, 30e3 + SPACING_HZ + 150.0])
    x = _block(rng, d, [-3000.0, -1000.0], 45.0)
    got = find_combs(x, FS)
    assert got.n_found == 2
    z = (got.doppler_hz[_match(got.doppler_hz, d)] - d) / doppler_sigma_hz(45.0, N / FS)
    assert np.all(np.abs(z) < 4.0)  # within 4 sigma of the single-comb bound


def test_coinciding_combs_are_reported_as_one():
    # Same rate, 0.5 Hz apart (0.025 / T): one comb, its Doppler between the two.
    rng = np.random.default_rng(8)
    d = np.array([30e3, 30e3 + 0.5])
    got = find_combs(_block(rng, d, [-3000.0, -3000.0], 45.0), FS)
    assert got.n_found == 1
    assert abs(got.doppler_hz[0] - 30e3) < 1.0  # midpoint 0.25 Hz off; sigma of the pair ~0.1 Hz


def test_bad_input():
    with pytest.raises(InputError, match="1-D complex"):
        find_combs(np.zeros(100), FS)
    with pytest.raises(InputError, match="predicted_hz"):
        find_combs(np.zeros(1000, dtype=complex), FS, predicted_hz=[np.nan])


NEEDS_NUMBA = pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed (leosop[fast])")


@NEEDS_NUMBA
@pytest.mark.parametrize("extra", [0, 2])
def test_compiled_refinement_agrees_with_numpy(extra):
    # Second implementation: refine_combs compiled (leosop.signal.fitkernels) against its numpy path, on
    # seven tracked combs, their own channels (extra 0) and two more tone positions either side (the search's).
    # The compiled phasors are float64 where numpy's round the phase to float32 (~1e-7 rad), so the fits
    # differ by that rounding. Measured: Doppler 1.2e-6 sigma, rate 1.5e-5 Hz/s, C/N0 4e-7 dB, statistic
    # 1.2e-6, amplitudes 1.8e-6 and cleaned tones 2.2e-7 relative; the tolerances are ~50-100x that, far
    # below anything a track or a fix could see.
    import copy

    from leosop.signal.comb_fit import refine_combs, track_combs
    from leosop.signal.comb_grid import DecimationGrid

    d, r, cn0, x = next(_seven(seed=23, n_blocks=1))
    comb = PilotComb()
    grid = DecimationGrid(x, FS, 150.0 + 0.5 * 4500.0 * N / FS, oversample=4.0)
    combs = track_combs(grid, comb, d + 3.0, r + 10.0, comb.n_tones // 2 + extra, 5000.0, 1e-3)
    for clean in (False, True):
        a, b = copy.deepcopy(combs), copy.deepcopy(combs)
        refine_combs(grid, comb, a, clean, kernel="numpy")
        refine_combs(grid, comb, b, clean, kernel="numba")
        for p, q in zip(a, b):
            assert abs(p.doppler_hz - q.doppler_hz) < 1e-4 * p.sigma_hz
            assert abs(p.rate - q.rate) < 1e-3
            assert p.cn0_dbhz == pytest.approx(q.cn0_dbhz, abs=1e-4)
            assert p.sigma_hz == pytest.approx(q.sigma_hz, rel=1e-6)
            assert p.statistic == pytest.approx(q.statistic, rel=1e-4)
            assert np.max(np.abs(p.amp - q.amp)) < 1e-4 * np.max(np.abs(p.amp))
            assert np.max(np.abs(p.z_wide - q.z_wide)) < 1e-5 * np.max(np.abs(p.z_wide))
            assert np.max(np.abs(p.nu - q.nu)) < 1e-6
    with pytest.raises(ValueError, match="kernel 'fortran'"):
        refine_combs(grid, comb, combs, kernel="fortran")


@NEEDS_NUMBA
@pytest.mark.parametrize("n_refine", [1, 2])
def test_compiled_tracking_agrees_with_numpy(n_refine):
    # Second implementation: a tracking block compiled end to end (comb_fit.track_arrays: decimation, dechirped
    # peaks, fits) against the numpy path (track_combs, refine_combs), with a prediction where no comb is and a
    # second prediction of one comb (dropped as its duplicate). The compiled phasors are float64, numpy's
    # float32 (~1e-7 rad). Measured: Doppler 2.5e-6 sigma, rate 3.1e-5 Hz/s, C/N0 2.6e-6 dB, statistic 6e-7
    # and amplitudes 6e-8 relative; the tolerances are ~40x that, far below anything a track could see.
    d, r, cn0, x = next(_seven(seed=24, n_blocks=1))
    rng = np.random.default_rng(6)
    pred = np.r_[d + rng.uniform(-5.0, 5.0, 7), 280e3, d[2] + 1.0]
    pred_rate = np.r_[r + rng.uniform(-20.0, 20.0, 7), 0.0, r[2]]
    kw = dict(predicted_hz=pred, predicted_rate_hz_per_s=pred_rate, search=False, n_refine=n_refine)
    a, b = find_combs(x, FS, kernel="numpy", **kw), find_combs(x, FS, kernel="numba", **kw)
    assert list(a.predicted_index) == list(b.predicted_index) == list(range(7))
    assert np.all(np.abs(a.doppler_hz - b.doppler_hz) < 1e-4 * a.sigma_hz)
    assert np.all(np.abs(a.doppler_rate_hz_per_s - b.doppler_rate_hz_per_s) < 1e-3)
    assert np.allclose(a.cn0_dbhz, b.cn0_dbhz, atol=1e-4)
    assert np.allclose(a.sigma_hz, b.sigma_hz, rtol=1e-4)
    assert np.allclose(a.statistic, b.statistic, rtol=1e-5)
    assert np.max(np.abs(a.amplitudes - b.amplitudes)) < 3e-6 * np.max(np.abs(a.amplitudes))


@NEEDS_NUMBA
def test_compiled_subtraction_agrees_with_numpy():
    # Second implementation: found combs subtracted from a block's FFT (multicomb._subtract_spectrum), compiled
    # (phasors by products along the tones, segments and bins; single-precision FFT) against numpy, with two
    # combs 30 Hz apart (overlapping windows) and one near the band's edge (windows wrapping). Measured: the
    # two residual spectra differ by 1.2-2.9e-7 of the largest value removed (float32 rounding); bound 2e-6.
    from leosop.signal.multicomb import _subtract_spectrum

    rng = np.random.default_rng(8)
    comb, n = PilotComb(), N
    spectrum = (rng.standard_normal(n) + 1j * rng.standard_normal(n)).astype(np.complex64)
    d = np.r_[rng.uniform(-2.5e5, 2.5e5, 5), 0.0, 0.5 * FS - 5e3]
    d[5] = d[0] + 30.0
    r = rng.uniform(-4500.0, 1000.0, 7)
    amp = 30.0 * (rng.standard_normal((7, comb.n_tones)) + 1j * rng.standard_normal((7, comb.n_tones)))
    for n_seg_s in (1000, 1024):
        a, b = spectrum.copy(), spectrum.copy()
        _subtract_spectrum(a, comb, d, r, amp, n, FS, n_seg_s, kernel="numpy")
        _subtract_spectrum(b, comb, d, r, amp, n, FS, n_seg_s, kernel="numba")
        assert np.max(np.abs(a - b)) < 2e-6 * np.max(np.abs(spectrum - a))


def test_power_detections_confirmed_by_the_coherent_fit():
    """A new comb from the spectrum's power detector is kept only if its coherent fit passes the tracking
    detector (statistic ~4 at pfa 1e-3 over the block's rate-frequency cells). This draw's two 45 dB-Hz combs
    left a noise window at 1.214 against the power detector's 1.209: two spurious combs, coherent statistics
    2.2 and 3.6, were kept before. A comb the power detector finds at all is far above the second test: at
    23 dB-Hz, where it finds 10 of these 12 (as before), their coherent statistics are 18-25, held here to 8
    or more (11.8 the least seen at 22 dB-Hz over 30 draws)."""
    rng = np.random.default_rng(10)
    rng.uniform(-1e6, 1e6, size=2)  # the draw of the CW-line test's seed 10, without the line
    sats = [(rng.uniform(-250e3, 250e3), rng.uniform(-3000, 0)) for _ in range(2)]
    n = 250_000  # 0.1 s, as the draw was made
    x = sum(add_noise(doppler_blocks(FS, n, f, r, None, rng=rng, dtype=np.complex128)[0], 45.0, FS, rng) / 2
            for f, r in sats).astype(np.complex64)
    found = find_combs(x, FS, max_combs=4)
    assert found.n_found == 2
    np.testing.assert_allclose(np.sort(found.doppler_hz), np.sort([f for f, _ in sats]), atol=50.0)
    weak = [find_combs(_block(np.random.default_rng(200 + k), [1e3 * k], [-1500.0], 23.0, n), FS, max_combs=1)
            for k in range(12)]
    assert sum(w.n_found for w in weak) >= 9
    assert all(np.all(w.statistic >= 8.0) for w in weak)
