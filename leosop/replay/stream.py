"""A recording's blocks read, narrowed and cleaned, in order, on several threads ahead of the comb search.

What a block needs before its comb search does not depend on the blocks
before it: the samples, their narrowing to the working rate (:func:`narrow`),
the check for NaN/inf and the front-end cleaning
(:func:`~leosop.signal.cleaning.clean_spectrum`: DC, IQ imbalance,
interferers). :func:`prepared_blocks` does that for the next blocks on
``threads - 1`` worker threads while the caller searches and tracks the
current one (which does depend on the blocks before it: the tracker's
predictions), and the caller's thread prepares the next block not yet
started whenever the one it needs is not ready, rather than wait. The
blocks come back in their order: the work of each block is the same as in
one thread, so are the results, bit for bit.

The preparation spends its time in numpy and FFTW (:mod:`leosop.signal.fft`,
per-thread plans), which release the GIL, as do the compiled comb fits; the
cleaned block's FFT, made here in place in the buffer the block was read
into, is handed to the comb search (``find_combs(None, ..., spectrum=)``), which needs
no more of the block. Measured on a continuous 2.5 MS/s
recording of 7 satellites (120 s, 0.1 s blocks, compiled kernels,
``tools/bench_replay.py``, idle cores), the preparation is about 60 % of the
streaming stage's processor time (2.28-2.60 of 3.84-3.93 s: ~2 ms a block,
of which ~1 ms the FFT), the comb search and tracking the rest. With one worker
thread the preparation alone set the pace (the caller waited ~1.2 ms a
block); with the caller preparing too, two threads replayed a 60 s
recording at 36-38x real time against 27-30x (alternating runs, idle
cores). A third thread is slower on two cores.
"""

import sys
import threading
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..signal.coarse import abs2
from ..signal.fft import empty_aligned, fft, ifft
from ..signal.cleaning import clean_spectrum
from ..signal.comb_grid import NonFiniteSamples

__all__ = ["PreparedBlock", "narrow", "narrowed_shift_s", "prepared_blocks", "spectrum_column", "track_times"]

#: Columns of the spectrogram kept for the figure, and its frequency bins.
SPECTRUM_COLUMNS = 600
SPECTRUM_BINS = 1024
#: Periodograms averaged per spectrogram column (a figure needs no more).
SPECTRUM_AVERAGES = 16
#: Blocks prepared ahead of the search per thread (the caller's too): the window bounds the memory to a few blocks.
LOOKAHEAD_PER_WORKER = 2
#: The interpreter's thread switch interval while worker threads prepare blocks [s]. A worker whose FFT
#: ended (GIL released) waits for the GIL until the comb search's thread gives it up, which CPython forces
#: only after the switch interval: its default 5 ms is two blocks' work. Measured (20 s at 2.5 MS/s, 7
#: satellites, two threads on idle cores, best of 5): streaming 0.92 s elapsed at 5 ms, 0.79 s at 2, 1 and
#: 0.5 ms; one thread unchanged.
SWITCH_INTERVAL_S = 0.001
_switch = {"users": 0, "saved": None}
_switch_lock = threading.Lock()


def narrow(iq, factor):
    """Band-limited decimation by an integer ``factor``: the central 1/factor of the spectrum.

    Output sample k is input sample ``k * factor`` of the band-limited
    signal, so times and phases carry over exactly.

    Parameters
    ----------
    iq : ndarray of complex, (n,)
    factor : int

    Returns
    -------
    ndarray of complex64, (n // factor,)
    """
    if factor == 1:
        return iq
    n = iq.size // factor * factor
    m = n // factor
    spec = fft(iq[:n], scratch=True)  # the plan's own buffer: only the kept bins are copied out of it
    keep = empty_aligned(m, dtype=spec.dtype)
    keep[: m - m // 2] = spec[: m - m // 2]
    keep[m - m // 2:] = spec[n - m // 2:]
    out = ifft(keep)
    out *= m / n
    return out.astype(np.complex64, copy=False)


def narrowed_shift_s(factor, sample_rate_hz):
    """How far before a block's centre its :func:`narrow` output's centre lies [s]: ``(factor - 1) / 2`` samples."""
    return 0.5 * (factor - 1) / sample_rate_hz


def track_times(blocks, factor, sample_rate_hz):
    """Where the tracks put each block: the centre of its narrowed samples (:func:`narrowed_shift_s` before
    the block's centre).

    Returns
    -------
    t_s : ndarray, (n_blocks,)
        Seconds from the recording's first sample.
    time_utc : ndarray of datetime64[ns], (n_blocks,)
    """
    shift_s = narrowed_shift_s(factor, sample_rate_hz)
    t_s = np.array([b.t_s for b in blocks], float) - shift_s
    time_utc = (np.array([b.time_utc for b in blocks], "datetime64[ns]")
                - np.timedelta64(int(round(shift_s * 1e9)), "ns"))
    return t_s, time_utc


def spectrum_column(iq):
    """Mean periodogram of (up to SPECTRUM_AVERAGES segments of) ``iq`` in SPECTRUM_BINS bins, DC in the middle.

    Parameters
    ----------
    iq : ndarray of complex, (n,)

    Returns
    -------
    ndarray of float, (SPECTRUM_BINS,)
    """
    m = min(SPECTRUM_AVERAGES, max(1, iq.size // SPECTRUM_BINS))
    seg = np.resize(iq, (m, SPECTRUM_BINS)) if iq.size < SPECTRUM_BINS else iq[: m * SPECTRUM_BINS].reshape(m, -1)
    return np.fft.fftshift(np.mean(abs2(fft(seg, scratch=True)), axis=0))


@dataclass(frozen=True)
class PreparedBlock:
    """One block ready for the comb search.

    Attributes
    ----------
    spectrum : ndarray of float, (SPECTRUM_BINS,) or None
        :func:`spectrum_column` of the narrowed block before cleaning, for
        the blocks the figure keeps; None for the others.
    iq_fft : ndarray of complex64, (n,)
        FFT of the narrowed block, cleaned (:func:`~leosop.signal.cleaning.clean_spectrum`), for
        ``find_combs(None, ..., clean=False, spectrum=iq_fft)``: made here, on the worker. The block in
        time is not kept (the search needs only its FFT): one buffer a block, not two.
    """

    spectrum: np.ndarray | None
    iq_fft: np.ndarray

    @property
    def n_samples(self):
        """Samples of the narrowed block."""
        return self.iq_fft.size


def _prepare(rec, factor, comb, spectrum_every, kernel, item):
    """Read, narrow, check and clean block ``item = (k, block)``: a PreparedBlock."""
    k, b = item
    # NaN/inf: the cleaning's block mean finds them (spares read() its own pass over the samples). The
    # samples are read into one aligned buffer that the cleaning turns into their FFT (narrow()'s output is
    # one too): a block's work touches one buffer of its size, in the cache it was read to.
    iq = rec.read(b.start, b.n_samples, check_finite=False, out=empty_aligned(b.n_samples) if factor == 1 else None)
    iq = narrow(iq, factor)
    spectrum = spectrum_column(iq) if spectrum_every and k % spectrum_every == 0 else None
    try:
        cleaning = clean_spectrum(iq, rec.sample_rate_hz / factor, comb, kernel=kernel, overwrite_iq=True)
    except NonFiniteSamples:
        raise InputError(f"{rec.data_path}: samples {b.start}..{b.start + b.n_samples - 1} hold NaN or inf") from None
    return PreparedBlock(spectrum, cleaning.spectrum)


@contextmanager
def _short_switch_interval():
    """:data:`SWITCH_INTERVAL_S` (or shorter, as it was) while any replay's workers run; then as it was."""
    with _switch_lock:
        if _switch["users"] == 0:
            _switch["saved"] = sys.getswitchinterval()
            sys.setswitchinterval(min(_switch["saved"], SWITCH_INTERVAL_S))
        _switch["users"] += 1
    try:
        yield
    finally:
        with _switch_lock:
            _switch["users"] -= 1
            if _switch["users"] == 0:
                sys.setswitchinterval(_switch["saved"])


def prepared_blocks(rec, blocks, factor, comb, *, threads=1, spectrum_every=0, kernel=None):
    """The blocks read, narrowed and cleaned, in order; with ``threads`` > 1 on worker threads, ahead.

    Parameters
    ----------
    rec : Recording
    blocks : list of Block
        (:func:`~leosop.replay.pipeline.block_plan`)
    factor : int
        Narrowing factor (:func:`~leosop.replay.pipeline.search_band`).
    comb : PilotComb
        The comb the cleaning keeps (its tones are not interferers).
    threads : int
        1: each block prepared when the caller asks for it. N > 1: N - 1
        worker threads prepare up to :data:`LOOKAHEAD_PER_WORKER` blocks per
        thread ahead of the caller, and the caller's thread, the N-th, takes
        the next block not yet started whenever the one it asks for is not
        ready (rather than wait).
    spectrum_every : int
        Every this-many-th block (0: none) carries its :func:`spectrum_column`.
    kernel : {None, "numba", "numpy"}
        The cleaning's (:func:`~leosop.signal.cleaning.clean_block`).

    Yields
    ------
    PreparedBlock
        One per block, in the order of ``blocks``. A block holding NaN or
        inf raises InputError when its turn comes, as in one thread.
    """
    def prepare(item):
        return _prepare(rec, factor, comb, spectrum_every, kernel, item)

    if threads <= 1:
        yield from map(prepare, enumerate(blocks))
        return
    work = _Shared(blocks, prepare, LOOKAHEAD_PER_WORKER * threads)
    workers = [threading.Thread(target=work.run, name=f"leosop-replay-{i}", daemon=True) for i in range(threads - 1)]
    try:
        with _short_switch_interval():
            for t in workers:
                t.start()
            for k in range(len(blocks) - 1):
                yield work.take(k)
            last = work.take(len(blocks) - 1) if blocks else None
        # The interval restored before the last block is handed over: a caller that takes every block
        # (``zip`` with the blocks first never asks for more) leaves nothing set behind.
        if last is not None:
            yield last
    finally:
        # An error (or a caller that stops early) leaves blocks unstarted: drop them, let the running ones end.
        work.stop()
        for t in workers:
            if t.is_alive():
                t.join()


class _Shared:
    """The blocks' preparation shared by worker threads and the caller: the next block to start, the
    blocks ready (or the error of one), and how far ahead of the caller the threads may run."""

    def __init__(self, blocks, prepare, ahead):
        self.blocks, self.prepare, self.ahead = blocks, prepare, ahead
        self.next = 0  # the next block to start
        self.taken = 0  # blocks handed to the caller
        self.ready = {}  # k -> (PreparedBlock, None) or (None, exception)
        self.stopped = False
        self.cond = threading.Condition()

    def _claim(self):
        """The next block to start within the window, or None (called holding the lock)."""
        if self.stopped or self.next >= min(len(self.blocks), self.taken + self.ahead):
            return None
        k, self.next = self.next, self.next + 1
        return k

    def _do(self, k, catch=Exception):
        """Prepare block ``k``; an error (``catch``) is kept for the caller, to raise when k's turn comes."""
        try:
            out = (self.prepare((k, self.blocks[k])), None)
        except catch as exc:
            out = (None, exc)
        with self.cond:
            self.ready[k] = out
            self.cond.notify_all()

    def run(self):
        """A worker thread: prepare blocks while there are any within the window, else wait. Whatever a
        block raises goes to the caller (a worker that died would leave its block never ready)."""
        while True:
            with self.cond:
                k = self._claim()
                while k is None:
                    if self.stopped or self.next >= len(self.blocks):
                        return
                    self.cond.wait()
                    k = self._claim()
            self._do(k, catch=BaseException)

    def take(self, k):
        """Block ``k`` for the caller; until it is ready the caller prepares the next unstarted block."""
        while True:
            with self.cond:
                if k in self.ready:
                    block, exc = self.ready.pop(k)
                    self.taken = k + 1
                    self.cond.notify_all()
                    break
                j = self._claim()
                if j is None:
                    self.cond.wait()
                    continue
            self._do(j)
        if exc is not None:
            raise exc
        return block

    def stop(self):
        with self.cond:
            self.stopped = True
            self.cond.notify_all()
