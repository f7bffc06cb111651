"""One satellite's OFDM downlink as a recording sees it (:mod:`.ofdm_frame` frames, Doppler, band).

Reception (:class:`OfdmDownlink`): as :func:`.pilot.comb_baseband`, the
geometry enters as ``geom_cycles`` = ``-channel_hz * (range - range0) / c``.
The received signal is the transmitted baseband at transmit time
``t + geom_cycles / channel_hz`` (code Doppler: the frame timing moves with
the delay), times ``exp(j 2 pi geom_cycles)``, so subcarrier k's Doppler is
``(1 + (k + 1/2) F / channel_hz)`` times the channel centre's, exactly.
A recording at ``sample_rate_hz`` below 240 MHz contains only the subcarriers
whose nominal frequency lies in its band: they are synthesised directly at the
recording's sample instants (exact, and cheap: 2.5 MS/s holds 6 active
subcarriers), as an ideal anti-alias filter at the band edge would leave them.
Sidelobes of the rectangular symbol windows of subcarriers outside the band
are left out. Samples are evaluated at any instants, so chunks continue
exactly (frame data is seeded per frame index).

Frame-timing jumps (:class:`FrameTimingJumps`): Qin et al. (2025) measured
steps of hundreds of ns in the frame timing of Starlink v1.x satellites,
about once per second. Here a step delays the frame envelope (the samples
about the OFDM centre) from then on; the carrier runs on unchanged (the
measurement is of timing; a jump of the carrier phase is not modelled).
"""

from dataclasses import dataclass, field

import numpy as np
import scipy.fft

from ..constellations import REGISTRY
from ..errors import InputError
from .ofdm_frame import (
    FRAME_SAMPLES,
    FS_HZ,
    N_CP,
    N_DATA_SYMBOLS,
    N_FFT,
    N_SYMBOL,
    N_SYMBOLS_PER_FRAME,
    SUBCARRIER_SPACING_HZ,
    active_subcarriers,
    pss_spectrum,
    qam4_codes,
    sss_spectrum,
)
from .pilot import PilotComb, comb_baseband

__all__ = ["OfdmDownlink", "FrameTimingJumps", "ofdm_baseband"]

#: Frame indices are shifted by this before seeding (SeedSequence takes non-negative integers).
_FRAME_SEED_SHIFT = 2**40
#: Terms of the Taylor series of the fractional-sample phase in the wide-band path:
#: |pi kappa phi| <= pi/2, remainder (pi/2)^17 / 17! < 1e-11.
_N_TAYLOR = 16
#: Up to this many subcarriers in band, samples are summed directly (Horner's rule).
_MAX_DIRECT = 48


@dataclass(frozen=True)
class FrameTimingJumps:
    """Steps of a satellite's frame timing: at frame-clock time ``j * period_s`` (j = 1, 2, ...) a N(0, sigma_s) step.

    The frame clock is the transmit time from the start of frame 0
    (:class:`OfdmDownlink`'s ``pos / FS_HZ``); a positive step delays every
    later frame. Step j is drawn from ``default_rng((*seed, j))``, so any
    span of the signal can be evaluated alone.

    Attributes
    ----------
    sigma_s : float
        Standard deviation of a step [s] (Qin et al. 2025: hundreds of ns).
    period_s : float
        Time between steps [s] (about 1 s in that measurement).
    seed : tuple of int
    """

    sigma_s: float
    period_s: float = 1.0
    seed: tuple = (0,)

    def __post_init__(self):
        if not (np.isfinite(self.sigma_s) and self.sigma_s >= 0):
            raise InputError(f"frame-jump sigma_s={self.sigma_s} must be a finite number >= 0")
        if not (np.isfinite(self.period_s) and self.period_s > 0):
            raise InputError(f"frame-jump period_s={self.period_s} must be a finite number > 0")

    def steps_s(self, n):
        """The first ``n`` steps [s], (n,)."""
        seed = tuple(int(v) for v in np.atleast_1d(self.seed))
        return np.array([np.random.default_rng((*seed, j)).normal(0.0, self.sigma_s) for j in range(1, int(n) + 1)])

    def offset_s(self, frame_time_s):
        """Total delay of the frames [s] at frame-clock times ``frame_time_s``, shape of the input."""
        j = np.maximum(np.floor(np.asarray(frame_time_s, dtype=float) / self.period_s), 0).astype(np.int64)
        n = int(j.max(initial=0))
        return np.concatenate(([0.0], np.cumsum(self.steps_s(n))))[j]


@dataclass(frozen=True)
class OfdmDownlink:
    """One satellite's OFDM downlink (and optionally its pilot comb) as a recording sees it.

    Attributes
    ----------
    sample_rate_hz : float
        The recording's sample rate; its band is centred on the channel centre.
    channel_hz : float
        Channel centre [Hz], one of ``REGISTRY["starlink"].channels_hz``;
        ``geom_cycles`` refer to it.
    frame_offset_s : float
        Receive time of the start of frame 0 at ``geom_cycles = 0``.
    seed : int
        Seeds the data of each frame (frame m from ``(seed, m)``).
    subcarrier_amplitude : float
        Amplitude of each subcarrier, in units of a unit pilot tone.
    comb : PilotComb or None
        Pilot comb added at the channel centre (its carrier must be ``channel_hz``).
    band_hz : float, optional
        Subcarriers with ``|(k + 1/2) F| < band_hz / 2`` are synthesised
        (default ``sample_rate_hz``). Doppler can carry an edge subcarrier
        past +-fs/2, where it wraps as in any complex sampler: take
        ``band_hz < sample_rate_hz - 2 max|Doppler|`` to avoid that.
    timing_jumps : FrameTimingJumps or None
        Steps of the frame timing (None: none).
    """

    sample_rate_hz: float
    channel_hz: float = REGISTRY["starlink"].carrier_hz
    frame_offset_s: float = 0.0
    seed: int = 0
    subcarrier_amplitude: float = 1.0
    comb: PilotComb | None = field(default_factory=PilotComb)
    band_hz: float | None = None
    timing_jumps: FrameTimingJumps | None = None

    def __post_init__(self):
        if not (np.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
            raise InputError(f"sample_rate_hz={self.sample_rate_hz} must be a finite number > 0")
        channels = REGISTRY["starlink"].channels_hz
        if not np.any(np.isclose(self.channel_hz, channels, rtol=0.0, atol=1.0)):
            raise InputError(f"channel_hz={self.channel_hz} is not a Starlink channel centre "
                             f"({', '.join(f'{c / 1e9:g}' for c in channels)} GHz)")
        if self.comb is not None and abs(self.comb.carrier_hz - self.channel_hz) > 1.0:
            raise InputError(f"comb carrier_hz={self.comb.carrier_hz} must equal channel_hz={self.channel_hz}")
        band = self.sample_rate_hz if self.band_hz is None else self.band_hz
        if not 0 < band <= self.sample_rate_hz:
            raise InputError(f"band_hz={self.band_hz} must be in (0, sample_rate_hz={self.sample_rate_hz}]")

    @property
    def subcarriers(self):
        """Signed indices of the subcarriers synthesised (gutter included if in band), increasing."""
        band = self.sample_rate_hz if self.band_hz is None else self.band_hz
        k = np.arange(-N_FFT // 2, N_FFT // 2)
        return k[np.abs((k + 0.5) * SUBCARRIER_SPACING_HZ) < band / 2.0]

    def frame_spectra(self, frame_index, bins=None):
        """Spectra of frame ``frame_index``'s 302 symbols, (302, n_bins), columns ``bins`` (FFT-bin order, default all).

        The PSS row is the spectrum of its useful part (its prefix is negated
        rather than cyclic; :meth:`samples` handles that). The data are those
        of :func:`data_symbols` with the frame's generator, decoded only for
        the bins asked for.
        """
        bins = np.arange(N_FFT) if bins is None else np.asarray(bins)
        rng = np.random.default_rng((int(self.seed), int(frame_index) + _FRAME_SEED_SHIFT))
        active = active_subcarriers()
        raw = np.frombuffer(rng.bytes((N_DATA_SYMBOLS * active.size + 3) // 4), dtype=np.uint8)
        column = np.full(N_FFT, -1)
        column[active % N_FFT] = np.arange(active.size)
        col = column[bins]
        is_active = col >= 0
        index = np.arange(N_DATA_SYMBOLS)[:, None] * active.size + col[is_active]
        data = np.zeros((N_DATA_SYMBOLS, bins.size), dtype=complex)
        data[:, is_active] = qam4_codes(raw, index)
        return np.vstack([pss_spectrum()[bins], sss_spectrum()[bins], data])

    def samples(self, t_s, geom_cycles, clock_cycles=0.0, *, phase_rad=0.0):
        """Received complex baseband at sample times ``t_s``, complex128, shape of ``t_s`` (1-D).

        Parameters
        ----------
        t_s : array_like, (n,)
            Sample times [s], e.g. ``(start + arange(count)) / sample_rate_hz``.
        geom_cycles : array_like, broadcastable to (n,)
            ``-channel_hz * (range - range0) / c`` [cycles] (as :func:`.pilot.comb_baseband`).
        clock_cycles : array_like, broadcastable to (n,)
            Integral of the clock-induced frequency offset [cycles], common to all subcarriers.
        phase_rad : float
            Common carrier phase.
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if t.ndim != 1:
            raise InputError(f"t_s must be 1-D, got shape {t.shape}")
        g = np.broadcast_to(np.asarray(geom_cycles, dtype=float), t.shape)
        clock = np.broadcast_to(np.asarray(clock_cycles, dtype=float), t.shape)
        # Transmit time in samples of FS_HZ from the start of frame 0.
        pos = (t - self.frame_offset_s) * FS_HZ + g * (FS_HZ / self.channel_hz)
        # OFDM centre at +F/2 on the carrier's clock: F/2 * FRAME_SAMPLES / FS_HZ = 156.25 cycles per frame.
        frame_idx = np.floor(pos / FRAME_SAMPLES).astype(np.int64)
        centre_cycles = 0.25 * np.mod(frame_idx, 4) + (pos - frame_idx * FRAME_SAMPLES) / (2.0 * N_FFT)
        if self.timing_jumps is not None:  # the envelope moves, the carrier does not
            pos = pos - FS_HZ * self.timing_jumps.offset_s(pos / FS_HZ)
            frame_idx = np.floor(pos / FRAME_SAMPLES).astype(np.int64)
        p = pos - frame_idx * FRAME_SAMPLES
        sym = np.minimum(np.floor(p / N_SYMBOL).astype(np.int64), N_SYMBOLS_PER_FRAME)
        u = p - sym * N_SYMBOL - N_CP
        live = sym < N_SYMBOLS_PER_FRAME
        sign = np.where((sym == 0) & (u < 0), -1.0, 1.0)
        k = self.subcarriers
        if k.size <= _MAX_DIRECT:
            body = self._direct(frame_idx, sym, u, live, k)
        else:
            body = self._taylor(frame_idx, sym, u, live, k)
        cycles = centre_cycles + g + clock
        iq = self.subcarrier_amplitude * sign * body * np.exp(2j * np.pi * (cycles - np.round(cycles)) + 1j * phase_rad)
        if self.comb is not None:
            iq += comb_baseband(self.comb, t, g, clock, phase_rad=phase_rad)
        return iq

    def _symbol_table(self, frame_idx, sym, live, columns):
        """Spectra (columns in FFT-bin order) of every symbol touched, and each sample's row."""
        frames = np.unique(frame_idx[live])
        table = np.zeros((frames.size * N_SYMBOLS_PER_FRAME + 1, columns.size), dtype=complex)
        for i, m in enumerate(frames):
            table[i * N_SYMBOLS_PER_FRAME:(i + 1) * N_SYMBOLS_PER_FRAME] = self.frame_spectra(m, columns)
        row = np.searchsorted(frames, frame_idx) * N_SYMBOLS_PER_FRAME + sym
        return table, np.where(live, row, table.shape[0] - 1)  # guard samples read the zero row

    def _direct(self, frame_idx, sym, u, live, k):
        """sum_k X_k exp(j 2 pi k u / N) over the in-band subcarriers by Horner's rule in z."""
        table, row = self._symbol_table(frame_idx, sym, live, k % N_FFT)
        z = np.exp(2j * np.pi * u / N_FFT)
        acc = table[row, -1]
        for i in range(k.size - 2, -1, -1):
            acc = acc * z + table[row, i]
        return acc * np.exp(2j * np.pi * k[0] * u / N_FFT)

    def _taylor(self, frame_idx, sym, u, live, k):
        """Same sum through IFFTs: u = i + phi with i integer, exp(j pi kappa phi) as a Taylor series.

        ``kappa = 2 k / N`` in [-1, 1); term p costs one IFFT of ``X_k kappa^p``,
        summed by Horner's rule in ``a = j pi phi``.
        """
        i = np.round(u).astype(np.int64)
        a = 1j * np.pi * (u - i)
        kappa = 2.0 * np.fft.fftfreq(N_FFT)
        in_band = np.zeros(N_FFT, dtype=bool)
        in_band[k % N_FFT] = True
        out = np.zeros(u.shape, dtype=complex)
        for m in np.unique(frame_idx[live]):
            sel = np.flatnonzero(live & (frame_idx == m))
            spec = np.where(in_band, self.frame_spectra(m), 0.0)
            flat = sym[sel] * N_FFT + np.mod(i[sel], N_FFT)
            a_sel = a[sel]

            def term(p):
                return (N_FFT * scipy.fft.ifft(spec * kappa**p, axis=-1)).ravel()[flat]

            acc = term(_N_TAYLOR)
            for p in range(_N_TAYLOR - 1, -1, -1):
                acc = term(p) + (a_sel / (p + 1)) * acc
            out[sel] = acc
        return out


def ofdm_baseband(t_s, geom_cycles, clock_cycles=0.0, *, sample_rate_hz, channel_hz=REGISTRY["starlink"].carrier_hz,
                  frame_offset_s=0.0, seed=0, subcarrier_amplitude=1.0, comb=None, band_hz=None, timing_jumps=None,
                  phase_rad=0.0):
    """Received OFDM downlink (plus the pilot comb if ``comb`` is given) at sample times ``t_s``.

    The functional form of :class:`OfdmDownlink` (see it for the parameters),
    beside :func:`.pilot.comb_baseband`. Returns complex128, shape (n,).
    """
    link = OfdmDownlink(sample_rate_hz, channel_hz, frame_offset_s, seed, subcarrier_amplitude, comb, band_hz,
                        timing_jumps)
    return link.samples(t_s, geom_cycles, clock_cycles, phase_rad=phase_rad)
