"""Every pilot comb in a block: successive interference cancellation.

A Starlink recording carries the combs of several satellites interleaved in
one band. :func:`find_combs` finds them one at a time, strongest first, with
the single-comb ``fast`` machinery of :mod:`leosop.signal.fine`, cancelling
each comb once found [successive interference cancellation, as in the
multi-satellite Starlink receivers of Humphreys 2023 and Kozhaya 2023]:

1. One FFT of the block. The comb detector (:func:`~.doppler.coarse_fft`,
   false-alarm probability ``pfa`` per search) runs on the spectrum with every
   comb found so far subtracted.
2. A detected comb is decimated as ``fast`` does (integrate-and-dump into B
   segments per tone, mixed at the coarse frequency), here from the block's
   FFT (:class:`~.comb_grid.DecimationGrid`), the contributions of the combs already found are removed from
   its (B, tones) matrix, and rate search, frequency search and Newton on the
   joint ML cost follow (``fast``'s own helpers). The coherent tone powers
   at two more tone positions either side then fix the comb position (always:
   another satellite's strong tone next to an edge tone can make the
   spectrum prefer the comb shifted by one spacing; it does not follow this
   comb's chirp, so the coherent check sees through it).
3. Per tone, the complex amplitude by least squares on the chirp model.
   The comb is subtracted from the spectrum (tone by tone over a window of
   ``B_s`` bins, from ``B_s`` samples of the model and one short FFT; exact
   to the within-segment chirp curvature, ~1e-4 rad) and the search repeats.
4. After the last detection, ``n_refine`` passes re-estimate every comb
   (Newton from its estimate) with all the others removed from its decimated
   tones, so early estimates lose the bias of combs found later. Each pass
   treats all combs at once (one leakage product, one batched Newton), each
   cleaned with the others' estimates of the previous pass (Jacobi).

Tracking (``predicted_hz`` and ``predicted_rate_hz_per_s`` given,
``batch=True``): all predictions are decimated in one matrix product and
fitted at once from their own tones (dechirped peak, Newton, position
check), then the refinement passes clean them; with the compiled kernels
(``kernel``) a block that only tracks runs as a few compiled calls on arrays
(:func:`~.comb_fit.track_arrays`, the same steps). ``batch=False`` fits them
one after another as the search does; both end within ~0.03 sigma of each
other (tests/signal/test_multicomb.py). A replay that tracks should call with the
previous block's estimates propagated (``doppler_hz + rate * block_s``,
the rate) and ``search=False``, and with ``search=True`` every k-th block
(and whenever a track is lost) to pick up rising satellites: the search
costs ~2x the tracking fit.

Contributions of one comb to another's decimated tones are closed forms
(:mod:`~leosop.signal.comb_grid`); the fits are those of :mod:`~leosop.signal.comb_fit`.

Ambiguities
-----------
*Comb shifted by one spacing*: handled by the coherent check (step 2).
*Nearly coinciding tones* (Doppler difference ``m * spacing + delta``):
measured at 0.05 s blocks, 45 dB-Hz (tests/signal/test_multicomb.py): with
``delta`` = 150 Hz (7.5/T) and rates 2 kHz/s apart both combs are found
within 1 sigma; at the same rate and ``m = 0`` with ``delta`` = 0.5 Hz one
comb is reported (a candidate within 2/T, modulo the spacing, and 4/T^2 in
rate of a comb already found is taken as its residue, subtracted and not
reported; the search goes on, up to three residues per block).
Not handled: ``delta`` of ~2-3/T with similar rates gives biased estimates
(~6 sigma seen) or a third, spurious comb; ``m = +-1`` with ``delta`` below
~1/T gives spurious combs (the pair looks like one ten-tone comb).

Cost (tools/bench_multicomb.py; CPU time, one core, 7 combs, 0.1 s at 2.5 MS/s;
numbers in the commit log): one FFT of the block feeds every channel; in
tracking mode the decimated band covers only the gate and the predicted chirp
(B ~200 segments instead of ~500, and the leakage cost goes with B^2), the
cross-comb leakage is a Dirichlet kernel per pair of a tone and a channel
within reach at every segment, and Newton, amplitude fits and bookkeeping the
rest. Transcendentals are single precision (1e-7 rad).

Output order is detection order (strongest first in the full search;
predicted combs first, in the order given, in tracking mode).
"""

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from ..errors import InputError
from ..kernels import pick
from .coarse import MAX_DOPPLER_HZ, MAX_RATE_HZ_PER_S, PFA, coarse_fft, detection_threshold
from .comb_fit import (CombState, cleaned_tones, cn0_sigma, decimate, fit_comb, refine_arrays, refine_combs,
                       track_arrays, track_combs)
from .comb_grid import DecimationGrid, NonFiniteSamples, cis, dirichlet
from .fft import empty_aligned, fft
from .fine import segment_grid
from .cleaning import clean_block
from .pilot import PilotComb

__all__ = ["Combs", "NonFiniteSamples", "find_combs"]

#: Tone positions decimated beyond each end of a comb for the coherent position check.
_EXTRA = 2
#: Decimated rate over the band a tracked tone can cover (the search uses 8).
_TRACK_OVERSAMPLE = 4.0
#: Residues of found combs removed in one search before it gives up.
_MAX_RESIDUES = 3


@dataclass(frozen=True)
class Combs:
    """Combs found in one block, arrays of shape (n_found,) unless stated.

    Attributes
    ----------
    doppler_hz : central-tone Doppler at the block centre [Hz].
    doppler_rate_hz_per_s : its rate [Hz/s].
    cn0_dbhz : mean C/N0 of the tones [dB-Hz].
    sigma_hz : Cramér-Rao sigma of ``doppler_hz`` from the fitted tone C/N0s [Hz]. Without the
        receiver LO's phase noise, which moves every comb of the block alike
        (:func:`~.frontend.wiener_doppler_sigma_hz`; a replay's static fix
        estimates it, :func:`leosop.replay.lo.lo_noise`).
    amplitudes : (n_found, n_tones) complex amplitude of each tone at the block
        centre (sample units; ``|a|^2 fs / N0`` is the tone's C/N0).
    statistic : coherent comb power over noise, mean over tones (~1 for noise only).
    predicted_index : index into ``predicted_hz`` of the prediction a comb was
        found at, -1 for a comb found by the search.
    """

    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray
    amplitudes: np.ndarray
    statistic: np.ndarray
    predicted_index: np.ndarray

    @property
    def n_found(self):
        return self.doppler_hz.size


@lru_cache(maxsize=16)
def _spectrum_grid(n, target):
    """Segments B_s dividing n, nearest to ``target`` (n itself when n has no divisor in range).

    Cached: a replay asks for the same few (n, target) in every search block, and the scan over
    the divisors is a Python loop (~0.5 ms).
    """
    div = [b for b in range(max(16, target // 2), min(4 * target, n // 4) + 1) if n % b == 0]
    return min(div, key=lambda b: abs(b - target)) if div else n


def _subtract_spectrum(spectrum, comb, doppler_hz, rate, amp, n, fs, n_seg_s, kernel=None):
    """Remove combs (central-tone Doppler ``doppler_hz`` and ``rate``, (C,), tone amplitudes ``amp``, (C, K))
    from the block's FFT (in place) over ``n_seg_s`` bins around each tone, all at once (the bins are
    subtracted in the combs' order, as one at a time). ``kernel``: as :func:`find_combs`' (compiled:
    :func:`.fitkernels.comb_segments` and :func:`.fitkernels.subtract_windows`, agreeing to float32 rounding)."""
    doppler_hz, rate = np.asarray(doppler_hz, dtype=float), np.asarray(rate, dtype=float)
    if not doppler_hz.size:
        return
    seg = n // n_seg_s
    df = fs / n
    _, _, tau, _ = segment_grid(n, fs, n_seg_s, seg)
    s = comb.doppler_scale
    nu0 = comb.offsets_hz + (doppler_hz + rate * tau[n_seg_s // 2])[:, None] * s  # (C, K) at the middle segment
    compiled = pick(kernel, "leosop.signal.fitkernels")
    if compiled is not None:
        tones = empty_aligned((doppler_hz.size, comb.n_tones, n_seg_s), dtype=np.complex64)
        compiled.comb_segments(tau, comb.offsets_hz, s, doppler_hz, rate, np.asarray(amp, dtype=complex), tones)
        compiled.subtract_windows(spectrum, fft(tones, scratch=True), nu0, float(fs), seg)
        return
    # :func:`~.comb_grid.tone_phases` of every comb, (C, B_s, K).
    ph = doppler_hz[:, None] * tau + (0.5 * rate)[:, None] * tau**2
    cycles = np.multiply.outer(tau, comb.offsets_hz) + ph[:, :, None] * s
    dft = fft((np.asarray(amp)[:, None, :] * cis(cycles)).transpose(0, 2, 1))  # (C, K, B_s)
    b = np.rint(nu0 / df).astype(int)[:, :, None] + np.arange(-(n_seg_s // 2), n_seg_s - n_seg_s // 2)
    # Sum over the segments of the segment-centre value times each segment's kernel and delay.
    weight = dirichlet(nu0[:, :, None] - b * df, seg, fs) * cis(-b * (0.5 * (seg - 1) / n))
    np.subtract.at(spectrum, (b % n).ravel(),
                   (weight * np.take_along_axis(dft, b % n_seg_s, axis=2)).astype(spectrum.dtype).ravel())


def _another_comb(iq, fs, comb, found, smear, max_doppler_hz, pfa, centre_hz, spectrum=None, kernel=None):
    """True when the block's spectrum (``fft(iq)``, or ``spectrum`` given), the combs ``found`` (Combs)
    removed, holds another comb.

    A detection within the coarse error (modulo the spacing) of a found comb
    is taken as its residue (the subtraction leaves a little of a strong,
    fast-chirping comb), not as another comb: a new comb hidden there is
    found by a later search, when the two have drifted apart.
    """
    spectrum = fft(iq) if spectrum is None else spectrum.copy()
    n = spectrum.shape[-1]
    if not np.isfinite(spectrum[0]):
        raise NonFiniteSamples("IQ samples contain NaN or inf")
    n_seg_s = _spectrum_grid(n, max(1024, int(8 * smear * n / fs)))
    _subtract_spectrum(spectrum, comb, found.doppler_hz, found.doppler_rate_hz_per_s, found.amplitudes, n, fs,
                       n_seg_s, kernel)
    coarse = coarse_fft(spectrum, fs, comb, max_doppler_hz=max_doppler_hz, smear_hz=smear, pfa=pfa,
                        centre_hz=centre_hz)
    if not coarse.detected:
        return False
    dd = coarse.doppler_hz - found.doppler_hz
    dd -= comb.tone_spacing_hz * np.round(dd / comb.tone_spacing_hz)
    return not np.any(np.abs(dd) <= 0.5 * smear + 2.0 * fs / n)


def _duplicate(comb, c, combs, dur):
    """True when ``c`` lies within 2/T (modulo the spacing) and 4/T^2 of a comb already found."""
    return _near_any(comb, c.doppler_hz, c.rate, [o.doppler_hz for o in combs], [o.rate for o in combs], dur)


def _near_any(comb, doppler_hz, rate, dopplers_hz, rates, dur):
    """True when a comb at ``doppler_hz``, ``rate`` lies within 2/T (modulo the spacing) and 4/T^2 of one of
    the combs at ``dopplers_hz``, ``rates`` (sequences of floats: a few, so scalar arithmetic)."""
    sp = comb.tone_spacing_hz
    for d, r in zip(dopplers_hz, rates):
        dd = doppler_hz - d
        # np.rint: np.round's rounding without its wrappers (on a scalar they cost 5x the rounding).
        if abs(dd - sp * np.rint(dd / sp)) < 2.0 / dur and abs(rate - r) < 4.0 / dur**2:
            return True
    return False


def _detection_threshold(grid, comb, max_rate_hz_per_s, pfa):
    """The tracking detector's threshold on a comb's statistic: ``pfa`` over the block's rate-frequency cells."""
    dur = grid.n / grid.fs
    return detection_threshold(comb.n_tones, grid.n_seg * max(1, int(np.ceil(2.0 * max_rate_hz_per_s * dur**2))),
                               pfa)


def _track_compiled(compiled, grid, comb, pred, pred_rate, gate, threshold, n_refine):
    """Tracking with the batch fit compiled (:func:`~.comb_fit.track_arrays`): the predictions that pass
    the detector near their prediction and are no other's duplicate, then ``n_refine`` cleaning passes.
    The same steps as :class:`_Finder`'s ``predictions`` and :func:`find_combs`' refinement; Combs."""
    fit, (z, f_c, mix, d_c) = track_arrays(compiled, grid, comb, pred, pred_rate)
    dur, df = grid.n / grid.fs, grid.fs / grid.n
    dopplers, rates = fit.doppler_hz.tolist(), fit.rate.tolist()  # Python floats: a few combs, scalar tests
    passed = (fit.statistic > threshold) & (np.abs(fit.doppler_hz - pred) <= gate + 2.0 * df)
    keep = []
    for j in np.flatnonzero(passed).tolist():
        if not _near_any(comb, dopplers[j], rates[j], [dopplers[i] for i in keep], [rates[i] for i in keep], dur):
            keep.append(j)
    if len(keep) < pred.size:
        z, f_c, mix, d_c, fit = z[:, keep], f_c[keep], mix[:, keep], d_c[keep], fit.subset(keep)
    for _ in range(n_refine if len(keep) > 1 else 0):
        fit = refine_arrays(compiled, grid, comb, z, 0, f_c, mix, d_c, fit.doppler_hz - d_c, fit.rate, fit.val, fit.nu)
    sigma_hz, cn0_dbhz = cn0_sigma(fit.w, fit.mean_cn0, grid.n, grid.fs)
    return Combs(fit.doppler_hz, fit.rate, cn0_dbhz, sigma_hz, fit.amp, fit.statistic, np.array(keep, dtype=int))


def _check(iq, fs, predicted_hz, predicted_rate):
    if not np.isfinite(fs) or fs <= 0:
        raise InputError(f"sample_rate_hz={fs} must be a finite number > 0")
    if iq is not None:
        iq = np.asarray(iq)
        if iq.ndim != 1 or not np.iscomplexobj(iq):
            raise InputError(f"IQ samples must be a 1-D complex array, got {iq.dtype} of shape {iq.shape}")
    p = np.atleast_1d(np.asarray([] if predicted_hz is None else predicted_hz, dtype=float))
    if p.ndim != 1:
        raise InputError(f"predicted_hz must be 1-D, got shape {p.shape}")
    pr = None
    if predicted_rate is not None:
        pr = np.broadcast_to(np.asarray(predicted_rate, dtype=float), p.shape)
    return iq, p, pr


class _Finder:
    """The combs of one block as they are found: the shared grid, the fitting options and the list so far."""

    def __init__(self, grid, comb, wide, max_rate_hz_per_s, pfa, kernel):
        self.grid, self.comb, self.wide = grid, comb, wide
        self.max_rate, self.pfa, self.kernel = max_rate_hz_per_s, pfa, kernel
        self.dur, self.df = grid.n / grid.fs, grid.fs / grid.n
        self.combs = []

    @cached_property
    def threshold(self):
        """The tracking detector's threshold (:func:`_detection_threshold`), which a new comb must pass too."""
        return _detection_threshold(self.grid, self.comb, self.max_rate, self.pfa)

    def fit_new(self, d_c, start, index):
        """Decimate at ``d_c``, append and fit a comb with the others removed; refit if its position shifts."""
        grid, comb, combs, wide = self.grid, self.comb, self.combs, self.wide
        c = CombState(d_c, None, predicted_index=index)
        decimate(grid, comb, c, wide)
        combs.append(c)
        j = len(combs) - 1
        shift, centre = fit_comb(grid, comb, c, cleaned_tones(grid, comb, combs, j), max_rate=self.max_rate,
                                 pfa=self.pfa, start=start)
        if shift:
            c.d_c = centre + shift * comb.tone_spacing_hz * (1.0 + centre / comb.carrier_hz)
            decimate(grid, comb, c, wide)
            fit_comb(grid, comb, c, cleaned_tones(grid, comb, combs, j), max_rate=self.max_rate, pfa=self.pfa,
                     start=(0.0, c.rate if np.isfinite(c.rate) else 0.0) if start is not None else None,
                     resolve=False)
        return c

    def predictions(self, pred, pred_rate, gate, batch, max_combs):
        """Tracking: each prediction from its own tones; kept if the coherent power passes the detector."""
        grid, comb, combs, dur, df = self.grid, self.comb, self.combs, self.dur, self.df
        thr = self.threshold
        if pred_rate is not None and pred.size and batch:
            for c in track_combs(grid, comb, pred[:max_combs], pred_rate[:max_combs], self.wide, self.max_rate,
                                 self.pfa, self.kernel):
                near = abs(c.doppler_hz - pred[c.predicted_index]) <= gate + 2.0 * df
                if c.statistic > thr and near and not _duplicate(comb, c, combs, dur):
                    combs.append(c)
        else:
            for i, p in enumerate(pred[:max_combs]):
                start = (None, float(pred_rate[i])) if pred_rate is not None else None
                c = self.fit_new(float(p), start, i)
                near = abs(c.doppler_hz - p) <= gate + 2.0 * df
                if not (c.statistic > thr and near) or _duplicate(comb, c, combs[:-1], dur):
                    combs.pop()

    def search(self, iq, block_fft, max_combs, max_doppler_hz, smear, lo):
        """Search the block's spectrum (``block_fft``, the FFT of ``iq``, if known), the combs found so far
        subtracted, for more combs, strongest first."""
        grid, comb, combs, dur = self.grid, self.comb, self.combs, self.dur
        n, fs = grid.n, grid.fs
        if grid.n_fft == n:
            spectrum = grid.spectrum.copy()
        else:
            spectrum = fft(iq) if block_fft is None else block_fft.copy()
        if not np.isfinite(spectrum[0]):
            raise NonFiniteSamples("IQ samples contain NaN or inf")
        n_seg_s = _spectrum_grid(n, max(1024, int(8 * smear * dur)))
        if combs:
            _subtract_spectrum(spectrum, comb, [c.doppler_hz for c in combs], [c.rate for c in combs],
                               [c.amp for c in combs], n, fs, n_seg_s, self.kernel)
        residues = 0
        while len(combs) < max_combs:
            coarse = coarse_fft(spectrum, fs, comb, max_doppler_hz=max_doppler_hz, smear_hz=smear, pfa=self.pfa,
                                centre_hz=lo)
            if not coarse.detected:
                break
            c = self.fit_new(coarse.doppler_hz, None, -1)
            if not c.statistic > self.threshold or _duplicate(comb, c, combs[:-1], dur):
                # Not a new comb: noise that the coherent fit does not confirm (a comb the power detector
                # finds at all scores ~10 or more), or the residue of a comb already found (nearly
                # coinciding tones are not cancelled exactly). Remove it too and search on, a few times
                # at most, rather than miss the weaker combs behind it.
                combs.pop()
                residues += 1
                if residues > _MAX_RESIDUES:
                    break
            _subtract_spectrum(spectrum, comb, [c.doppler_hz], [c.rate], [c.amp], n, fs, n_seg_s, self.kernel)

    def result(self):
        """The combs found, as :class:`Combs`."""
        combs = self.combs

        def col(name, dtype=float):
            return np.array([getattr(c, name) for c in combs], dtype=dtype)

        amps = np.array([c.amp for c in combs]) if combs else np.zeros((0, self.comb.n_tones), dtype=complex)
        return Combs(col("doppler_hz"), col("rate"), col("cn0_dbhz"), col("sigma_hz"), amps, col("statistic"),
                     col("predicted_index", int))


def find_combs(iq, sample_rate_hz, *, comb=None, max_combs=10, pfa=PFA, max_doppler_hz=MAX_DOPPLER_HZ,
               max_rate_hz_per_s=MAX_RATE_HZ_PER_S, predicted_hz=None, predicted_rate_hz_per_s=None,
               gate_hz=None, search=True, n_refine=2, batch=True, lo_offset_hz=0.0, clean=True, spectrum=None,
               kernel=None):
    """Doppler, rate and C/N0 of every pilot comb in one block.

    Parameters
    ----------
    iq : ndarray of complex, shape (n,), or None
        The block; None with ``clean=False`` and its ``spectrum`` given
        (as :func:`~.cleaning.clean_spectrum` leaves it).
    sample_rate_hz : float
    comb : PilotComb, optional
    max_combs : int
        Stop after this many combs.
    pfa : float
        False-alarm probability of each comb search (and of the rate
        transform's peak, as in ``fast``). A noise-only block gives a
        spurious comb with probability at most ``pfa``.
    max_doppler_hz, max_rate_hz_per_s : float
        Search limits (as :func:`~.doppler.estimate_block`).
    predicted_hz : array_like, shape (n_pred,), optional
        Tracking mode: central-tone Dopplers predicted from earlier blocks.
        Each is fitted from its own decimated tones (no spectrum search);
        kept when its coherent statistic passes the detector at ``pfa``.
    predicted_rate_hz_per_s : array_like, shape (n_pred,) or scalar, optional
        Predicted rates; given, the rate search is skipped (good to ~1/(2 T^2)).
    gate_hz : float, optional
        Half-width of the window around each prediction (default: the coarse
        error of the full search, half the rate smear plus 2 bins).
    search : bool
        Also search the spectrum for combs not predicted (costs one FFT of
        the block plus the searches).
    n_refine : int
        Re-estimation passes with all other combs removed.
    batch : bool
        Tracking with predicted rates: fit all predictions at once (default)
        rather than one at a time (see module docstring).
    lo_offset_hz : float
        The receiver's LO offset, common to all satellites (as well as it is
        known): the search is centred there (``max_doppler_hz`` either side)
        and the tone model scales only the Doppler beyond it
        (:meth:`~.pilot.PilotComb.through_lo`). Reported Dopplers include it.
    clean : bool
        Remove the block's DC offset, IQ imbalance and CW / narrowband
        interferers first (:func:`~.cleaning.clean_block`; one FFT more).
    spectrum : ndarray of complex64, shape (n,), optional
        With ``clean=False``: the FFT of ``iq`` (:func:`~.fft.fft`) if known,
        as the cleaning leaves it (:attr:`~.cleaning.Cleaning.spectrum`); the
        search then spares that FFT (the result is the same).
    kernel : {None, "numba", "numpy"}
        The batched re-estimation (:mod:`.fitkernels`; agrees to float32
        rounding) and the cleaning's line finding (:mod:`.cleankernels`)
        compiled, or numpy; None: numba when installed. A job of
        many blocks picks it with :func:`~.comb_fit.fit_kernel`.

    Returns
    -------
    Combs
        In detection order (see module docstring).
    """
    comb = comb or PilotComb()
    fs = float(sample_rate_hz)
    iq, pred, pred_rate = _check(iq, fs, predicted_hz, predicted_rate_hz_per_s)
    if not np.all(np.isfinite(pred)):
        raise InputError("predicted_hz contains NaN or inf")
    if iq is None and (clean or spectrum is None):
        raise InputError("iq=None needs the block's spectrum and clean=False")
    if clean:
        iq, cleaning = clean_block(iq, fs, comb, kernel=kernel)  # raises NonFiniteSamples
        spectrum = cleaning.spectrum
    lo = float(lo_offset_hz)
    if lo:
        comb = comb.through_lo(lo)
    n = spectrum.shape[-1] if iq is None else iq.shape[-1]
    dur = n / fs
    df = fs / n
    smear = max_rate_hz_per_s * dur
    error_hz = 0.5 * smear + 2.0 * df
    gate = error_hz if gate_hz is None else float(gate_hz)
    if search and pred_rate is not None and pred.size and batch:
        # The tracked combs first, in their narrow bands; the full search (wide
        # bands, every comb refitted) only when the spectrum without them holds
        # another comb, which is rare: a search block then costs little more
        # than a tracking one.
        kw = dict(comb=comb, max_combs=max_combs, pfa=pfa, max_doppler_hz=max_doppler_hz,
                  max_rate_hz_per_s=max_rate_hz_per_s, gate_hz=gate_hz, n_refine=n_refine, clean=False,
                  spectrum=spectrum, kernel=kernel)
        tracked = find_combs(iq, fs, predicted_hz=pred, predicted_rate_hz_per_s=pred_rate, search=False, **kw)
        if tracked.n_found >= max_combs or not _another_comb(iq, fs, comb, tracked, smear, max_doppler_hz, pfa, lo,
                                                                    spectrum, kernel):
            return tracked
    tracking = pred_rate is not None and pred.size > 0 and not search
    if tracking:
        # Every comb is near its prediction, chirping at its predicted rate: the
        # channels need only pass the gate and that chirp, and the comb position
        # (checked when the comb was found) needs no check.
        grid = DecimationGrid(iq, fs, gate + 0.5 * float(np.max(np.abs(pred_rate[:max_combs]))) * dur + 2.0 * df,
                              oversample=_TRACK_OVERSAMPLE, spectrum=spectrum)
    else:
        grid = DecimationGrid(iq, fs, max(error_hz, gate) + 0.5 * max_rate_hz_per_s * dur, spectrum=spectrum)
    half = comb.n_tones // 2
    compiled = pick(kernel, "leosop.signal.fitkernels")
    if tracking and batch and compiled is not None:
        return _track_compiled(compiled, grid, comb, pred[:max_combs], pred_rate[:max_combs], gate,
                               _detection_threshold(grid, comb, max_rate_hz_per_s, pfa), n_refine)
    finder = _Finder(grid, comb, half if tracking else half + _EXTRA, max_rate_hz_per_s, pfa, kernel)
    finder.predictions(pred, pred_rate, gate, batch, max_combs)
    if search and len(finder.combs) < max_combs:
        finder.search(iq, spectrum, max_combs, max_doppler_hz, smear, lo)
    for _ in range(n_refine if len(finder.combs) > 1 else 0):
        refine_combs(grid, comb, finder.combs, kernel=kernel)
    return finder.result()
