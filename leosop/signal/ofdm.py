"""The Starlink Ku-band OFDM downlink frame, its reception, and PSS acquisition.

Frame [Humphreys 2023]: sample rate ``FS_HZ`` = 240 MHz (the channel
bandwidth), ``N_FFT`` = 1024 subcarriers ``F`` = 234.375 kHz apart, cyclic
prefix ``N_CP`` = 32, symbols of 1056 samples; a frame of 1/750 s (320,000
samples) holds 302 symbols (PSS, SSS, 300 data) and an empty 1088-sample
guard. Subcarriers are numbered k = -512 .. 511 about the OFDM centre, which
sits half a spacing above the channel centre of the 250 MHz raster
(``channel + F/2``, the published channel formula), so subcarrier k is at
``channel + (k + 1/2) F``. The four subcarriers k = -2 .. 1 (the "gutter",
+-1.5 F about the channel centre) are empty; the pilot comb (:mod:`.pilot`)
sits in it, at the channel centre, which is baseband 0 Hz of a recording
(DESIGN 4.2).

PSS [Humphreys 2023]: 127 chips of a 7-bit Fibonacci LFSR (taps 3 and 7,
initial state 0011010), reversed, a 0 prepended to make 128, mapped
0 -> -1, 1 -> +1, and turned into a unit-modulus segment whose phase starts at
-pi/4 and steps by -pi/2 times each mapped chip (a pi/2-step phase walk). The
useful part is 8 copies of the segment with the first negated; its cyclic
prefix is the negated last 32 samples. SSS: 4QAM on the N - 4 subcarriers
outside the gutter (its published values are not reproduced here: a seeded
random stand-in). Data: random 4QAM on the same subcarriers.

Normalisation: each active subcarrier is a unit-amplitude complex
exponential (unit-power 4QAM symbols, ``x[n] = sum_k X_k exp(j 2 pi k n / N)``),
so one subcarrier has the power of one unit pilot tone of :mod:`.pilot` and
C/N0 per unit-amplitude tone (:func:`.pilot.add_noise`) applies to each
subcarrier alike. The PSS is scaled by sqrt(N) = 32 to the same per-subcarrier
power (its samples have modulus 32; the data symbols' mean power is 1020).

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
"""

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.fft

from ..constants import STARLINK_PILOT_HZ
from ..errors import InputError
from ..orbits.constellation import CARRIERS
from .pilot import PilotComb, comb_baseband

__all__ = [
    "FS_HZ", "N_FFT", "N_CP", "N_SYMBOL", "N_SYMBOLS_PER_FRAME", "N_DATA_SYMBOLS", "N_GUARD",
    "FRAME_SAMPLES", "FRAME_PERIOD_S", "SUBCARRIER_SPACING_HZ", "OFDM_CENTER_OFFSET_HZ",
    "GUTTER_SUBCARRIERS", "N_PSS_SEGMENTS", "PSS_SEGMENT_LEN",
    "active_subcarriers", "pss_mseq", "pss_time", "sss_symbol", "data_symbols", "symbol_time", "frame",
    "OfdmDownlink", "ofdm_baseband", "PssAcquisition", "acquire_pss",
]

#: Sample rate = channel bandwidth [Hz] [Humphreys 2023].
FS_HZ = 240e6
#: Subcarriers (FFT size).
N_FFT = 1024
#: Cyclic prefix [samples].
N_CP = 32
#: OFDM symbol with its cyclic prefix [samples].
N_SYMBOL = N_FFT + N_CP
#: Symbols per frame: PSS, SSS and the data symbols.
N_SYMBOLS_PER_FRAME = 302
#: Data symbols per frame.
N_DATA_SYMBOLS = N_SYMBOLS_PER_FRAME - 2
#: Empty guard at the end of each frame [samples].
N_GUARD = 1088
#: Samples per frame (302 * 1056 + 1088).
FRAME_SAMPLES = N_SYMBOLS_PER_FRAME * N_SYMBOL + N_GUARD
#: Frame period [s] (1/750 s).
FRAME_PERIOD_S = FRAME_SAMPLES / FS_HZ
#: Subcarrier spacing F [Hz].
SUBCARRIER_SPACING_HZ = FS_HZ / N_FFT
#: OFDM centre (subcarrier 0) above the channel centre [Hz]: F/2.
OFDM_CENTER_OFFSET_HZ = SUBCARRIER_SPACING_HZ / 2.0
#: Empty subcarriers about the OFDM centre (signed indices).
GUTTER_SUBCARRIERS = (-2, -1, 0, 1)
#: PSS: segments of the useful part and their length [samples].
N_PSS_SEGMENTS = 8
PSS_SEGMENT_LEN = N_FFT // N_PSS_SEGMENTS
#: PSS LFSR: feedback taps (1-based stage numbers) and initial state [Humphreys 2023].
PSS_LFSR_TAPS = (3, 7)
PSS_LFSR_STATE = (0, 0, 1, 1, 0, 1, 0)
#: Seed of the SSS stand-in: one SSS for every satellite, as in the real signal.
_SSS_SEED = 0x555
#: Frame indices are shifted by this before seeding (SeedSequence takes non-negative integers).
_FRAME_SEED_SHIFT = 2**40
#: Terms of the Taylor series of the fractional-sample phase in the wide-band path:
#: |pi kappa phi| <= pi/2, remainder (pi/2)^17 / 17! < 1e-11.
_N_TAYLOR = 16
#: Up to this many subcarriers in band, samples are summed directly (Horner's rule).
_MAX_DIRECT = 48


def active_subcarriers():
    """Signed indices k of the N - 4 active subcarriers, increasing, shape (1020,)."""
    k = np.arange(-N_FFT // 2, N_FFT // 2)
    return k[~np.isin(k, GUTTER_SUBCARRIERS)]


def pss_mseq():
    """The 127 PSS chips (0/1, int8, shape (127,)) of the 7-bit Fibonacci LFSR.

    Each step outputs the XOR of stages 3 and 7 and shifts it into stage 1.
    """
    state = list(PSS_LFSR_STATE)
    chips = np.empty(127, dtype=np.int8)
    for i in range(127):
        bit = state[PSS_LFSR_TAPS[0] - 1] ^ state[PSS_LFSR_TAPS[1] - 1]
        state = [bit] + state[:-1]
        chips[i] = bit
    return chips


def pss_time():
    """Time-domain PSS with its (negated) cyclic prefix, unit modulus, complex128 (1056,)."""
    bits = np.concatenate(([0], pss_mseq()[::-1]))
    steps = 2.0 * bits - 1.0
    segment = np.exp(-1j * np.pi / 4.0 - 0.5j * np.pi * np.cumsum(steps))
    useful = np.concatenate([-segment, np.tile(segment, N_PSS_SEGMENTS - 1)])
    return np.concatenate([-useful[-N_CP:], useful])


def _qam4_codes(raw, index):
    """Unit-power 4QAM symbols numbered ``index`` from random bytes (two bits per symbol)."""
    b = ((raw[index // 4] >> (2 * (index % 4)).astype(np.uint8)) & 3).astype(np.int8)
    return ((1 - 2 * (b & 1)) + 1j * (1 - 2 * (b >> 1))) / np.sqrt(2.0)


def _qam4(rng, shape):
    """Unit-power 4QAM symbols of ``shape`` from ``rng``'s bytes."""
    n = int(np.prod(shape))
    raw = np.frombuffer(rng.bytes((n + 3) // 4), dtype=np.uint8)
    return _qam4_codes(raw, np.arange(n)).reshape(shape)


def data_symbols(rng, n_symbols=N_DATA_SYMBOLS):
    """Random 4QAM on the active subcarriers, FFT-bin order, zero in the gutter, (n_symbols, 1024)."""
    x = np.zeros((int(n_symbols), N_FFT), dtype=complex)
    k = active_subcarriers()
    x[:, k % N_FFT] = _qam4(rng, (int(n_symbols), k.size))
    return x


def sss_symbol(rng):
    """SSS stand-in: 4QAM on the active subcarriers, FFT-bin order, (1024,)."""
    return data_symbols(rng, 1)[0]


def symbol_time(spectrum):
    """OFDM symbols with cyclic prefix from spectra in FFT-bin order, (..., 1024) -> (..., 1056).

    ``x[n] = sum_k X_k exp(j 2 pi k n / N)``: each subcarrier a tone of amplitude |X_k|.
    """
    x = N_FFT * scipy.fft.ifft(spectrum, axis=-1)
    return np.concatenate([x[..., -N_CP:], x], axis=-1)


def frame(rng):
    """One frame at 240 MS/s about the OFDM centre, complex128 (320000,).

    PSS (scaled by sqrt(N)), SSS and 300 data symbols drawn from ``rng`` (SSS
    first), then the empty guard.
    """
    sss = sss_symbol(rng)
    data = data_symbols(rng)
    out = np.zeros(FRAME_SAMPLES, dtype=complex)
    out[:N_SYMBOL] = np.sqrt(N_FFT) * pss_time()
    out[N_SYMBOL:N_SYMBOLS_PER_FRAME * N_SYMBOL] = symbol_time(np.vstack([sss, data])).ravel()
    return out


@lru_cache(maxsize=1)
def _pss_spectrum():
    """Spectrum of the PSS's useful part in the frame's normalisation, FFT-bin order, (1024,)."""
    return np.fft.fft(pss_time()[N_CP:]) / np.sqrt(N_FFT)


@lru_cache(maxsize=1)
def _sss_spectrum():
    return sss_symbol(np.random.default_rng(_SSS_SEED))


@dataclass(frozen=True)
class OfdmDownlink:
    """One satellite's OFDM downlink (and optionally its pilot comb) as a recording sees it.

    Attributes
    ----------
    sample_rate_hz : float
        The recording's sample rate; its band is centred on the channel centre.
    channel_hz : float
        Channel centre [Hz], one of ``CARRIERS["starlink"].channels_hz``;
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
    """

    sample_rate_hz: float
    channel_hz: float = STARLINK_PILOT_HZ
    frame_offset_s: float = 0.0
    seed: int = 0
    subcarrier_amplitude: float = 1.0
    comb: PilotComb | None = field(default_factory=PilotComb)
    band_hz: float | None = None

    def __post_init__(self):
        if not (np.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
            raise InputError(f"sample_rate_hz={self.sample_rate_hz} must be a finite number > 0")
        channels = CARRIERS["starlink"].channels_hz
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
        data[:, is_active] = _qam4_codes(raw, index)
        return np.vstack([_pss_spectrum()[bins], _sss_spectrum()[bins], data])

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
        # OFDM centre at +F/2: F/2 * FRAME_SAMPLES / FS_HZ = 156.25 cycles per frame.
        centre_cycles = 0.25 * np.mod(frame_idx, 4) + p / (2.0 * N_FFT)
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


def ofdm_baseband(t_s, geom_cycles, clock_cycles=0.0, *, sample_rate_hz, channel_hz=STARLINK_PILOT_HZ,
                  frame_offset_s=0.0, seed=0, subcarrier_amplitude=1.0, comb=None, band_hz=None, phase_rad=0.0):
    """Received OFDM downlink (plus the pilot comb if ``comb`` is given) at sample times ``t_s``.

    The functional form of :class:`OfdmDownlink` (see it for the parameters),
    beside :func:`.pilot.comb_baseband`. Returns complex128, shape (n,).
    """
    link = OfdmDownlink(sample_rate_hz, channel_hz, frame_offset_s, seed, subcarrier_amplitude, comb, band_hz)
    return link.samples(t_s, geom_cycles, clock_cycles, phase_rad=phase_rad)


#: Sign pattern of the lag-128 products x[n + 128] conj(x[n]) over a PSS from its first
#: sample: + over the prefix, - over segment 0 (its successor is not negated), + over segments 1-6.
_PSS_PRODUCT_RUNS = ((N_CP, 1.0), (PSS_SEGMENT_LEN, -1.0), ((N_PSS_SEGMENTS - 2) * PSS_SEGMENT_LEN, 1.0))
_PSS_PRODUCT_LEN = sum(n for n, _ in _PSS_PRODUCT_RUNS)
#: Detection threshold on the normalised lag-128 metric. On noise alone a frame's
#: metric is Rayleigh with scale 1/sqrt(2 * 928) = 0.023; its largest value over
#: the ~1000 independent cells of a frame is ~0.09, averaged over frames less.
PSS_DETECT_THRESHOLD = 0.15


@dataclass(frozen=True)
class PssAcquisition:
    """PSS acquisition result.

    ``frame_start_s`` (n_frames,): receive time of each frame's first sample
    (the PSS's prefix) from the first sample of the snippet, sub-sample by
    parabolic interpolation of the PSS correlation; ``frame_number`` (n_frames,):
    frame count from the first found; ``frame_period_s``: least-squares slope
    (NaN for one frame); ``doppler_hz``: frequency offset of the OFDM centre
    from its nominal place (Doppler plus clock offsets, ambiguity +-Fs/256 =
    +-937.5 kHz); ``metric``: normalised lag-128 coherence at the PSS, mean over
    frames (1 noise-free, ~0.03 on noise); ``detected``: metric above
    :data:`PSS_DETECT_THRESHOLD`.
    """

    frame_start_s: np.ndarray
    frame_number: np.ndarray
    frame_period_s: float
    doppler_hz: float
    metric: float
    detected: bool


def _window_sums(cum, starts, runs):
    """sum of sign * values over consecutive runs from each start, from a leading-zero cumsum."""
    total = 0.0
    offset = 0
    for n, s in runs:
        total = total + s * (cum[starts + offset + n] - cum[starts + offset])
        offset += n
    return total


#: Zero-padded length of the PSS periodograms of the frequency refinement.
_CFO_FFT = 16 * N_FFT
#: Half-width of the residual frequency search after the lag-128 estimate [Hz]
#: (its error is ~4 kHz rms at 0 dB SNR and 8 frames, ~25 kHz at -10 dB).
_CFO_SEARCH_HZ = 100e3


def _residual_cfo_hz(x, starts, cfo_hz):
    """Residual frequency from the PSS's useful parts with the known sequence wiped off.

    Sum over frames of the zero-padded periodograms of ``x conj(pss)``
    (1024 samples each), peak within +-_CFO_SEARCH_HZ, parabolic interpolation.
    """
    ref = np.conj(np.sqrt(N_FFT) * pss_time()[N_CP:])
    first = np.round(starts).astype(np.int64) + N_CP
    first = first[first + N_FFT <= x.size]
    n = first[:, None] + np.arange(N_FFT)
    wiped = x[n] * ref * np.exp(-2j * np.pi * (cfo_hz / FS_HZ) * n)
    power = np.sum(np.abs(scipy.fft.fft(wiped, _CFO_FFT, axis=-1)) ** 2, axis=0)
    f_hz = scipy.fft.fftfreq(_CFO_FFT, 1.0 / FS_HZ)
    power[np.abs(f_hz) > _CFO_SEARCH_HZ] = 0.0
    peak = int(np.argmax(power))
    y0, y1, y2 = power[peak - 1], power[peak], power[(peak + 1) % _CFO_FFT]
    denom = y0 - 2.0 * y1 + y2
    frac = 0.5 * (y0 - y2) / denom if denom < 0 else 0.0
    return float(f_hz[peak] + frac * FS_HZ / _CFO_FFT)


def acquire_pss(iq, sample_rate_hz=FS_HZ, *, center_offset_hz=OFDM_CENTER_OFFSET_HZ, refine_samples=48):
    """Frame timing and carrier frequency offset from the PSS of a 240 MS/s snippet.

    Timing: the products ``x[n + 128] conj(x[n])`` are constant over a PSS
    but for the sign of segment 0 (:data:`_PSS_PRODUCT_RUNS`); their signed
    sum over 928 samples, ``M(tau)``, has a magnitude independent of the
    frequency offset. ``|M|`` over the energy of the window is folded modulo
    the frame length (noise averages down; code Doppler moves frames by at
    most ~9 samples per frame at 350 kHz, well inside the metric's ~100-sample
    peak); its maximum gives the first frame, and each next one is searched
    +-``refine_samples`` from the previous one plus a frame. The frequency
    offset is the phase of the sum of ``M`` at the frames over 2 pi 128 / Fs.
    Each frame's start is then refined by correlating the frequency-corrected
    snippet with the known PSS (1056 samples) over +-``refine_samples``.

    Parameters
    ----------
    iq : ndarray of complex, (n,)
        At least one frame plus a symbol; 10 ms (2.4e6 samples) holds 7 frames.
    sample_rate_hz : float
        Must be ``FS_HZ``.
    center_offset_hz : float
        Nominal OFDM centre in the snippet's baseband (default: the channel
        centre at 0 Hz, as recordings are, so +F/2).
    refine_samples : int

    Returns
    -------
    PssAcquisition
    """
    if sample_rate_hz != FS_HZ:
        raise InputError(f"acquire_pss: sample_rate_hz={sample_rate_hz} must be {FS_HZ:g} (the full channel)")
    x = np.asarray(iq)
    if x.ndim != 1 or not np.iscomplexobj(x):
        raise InputError(f"IQ samples must be a 1-D complex array, got {x.dtype} of shape {x.shape}")
    lag = PSS_SEGMENT_LEN
    n_metric = x.size - lag - _PSS_PRODUCT_LEN + 1
    if n_metric < FRAME_SAMPLES:
        raise InputError(f"acquire_pss needs at least {FRAME_SAMPLES + lag + _PSS_PRODUCT_LEN - 1} samples, "
                         f"got {x.size}")
    x = x.astype(np.complex64, copy=False)
    prod = np.empty(x.size - lag + 1, dtype=np.complex128)
    prod[0] = 0.0
    np.cumsum(x[lag:] * np.conj(x[:-lag]), out=prod[1:])
    power = np.abs(x).astype(np.float64) ** 2
    energy = np.concatenate(([0.0], np.cumsum(power)))
    starts = np.arange(n_metric)
    m_tau = _window_sums(prod, starts, _PSS_PRODUCT_RUNS)
    e_tau = 0.5 * ((energy[starts + _PSS_PRODUCT_LEN] - energy[starts])
                   + (energy[starts + lag + _PSS_PRODUCT_LEN] - energy[starts + lag]))
    rho = np.abs(m_tau) / np.maximum(e_tau, np.finfo(float).tiny)
    n_fold = n_metric // FRAME_SAMPLES
    folded = rho[:n_fold * FRAME_SAMPLES].reshape(n_fold, FRAME_SAMPLES).mean(axis=0)
    tau = [int(np.argmax(folded))]
    while tau[-1] + FRAME_SAMPLES + refine_samples < n_metric:
        lo = tau[-1] + FRAME_SAMPLES - refine_samples
        tau.append(lo + int(np.argmax(rho[lo:lo + 2 * refine_samples + 1])))
    tau = np.array(tau)
    metric = float(np.mean(rho[tau]))
    cfo_hz = float(np.angle(np.sum(m_tau[tau]))) * FS_HZ / (2.0 * np.pi * lag)
    # Refinement: correlation with the known PSS over +-refine_samples.
    ref = np.sqrt(N_FFT) * pss_time()
    starts, numbers = [], []
    for j, t0 in enumerate(tau):
        lo = t0 - refine_samples
        hi = t0 + refine_samples + N_SYMBOL
        if lo < 0 or hi > x.size:
            continue
        n = np.arange(lo, hi)
        seg = x[lo:hi] * np.exp(-2j * np.pi * (cfo_hz / FS_HZ) * n)
        corr = np.abs(np.correlate(seg, ref, mode="valid")) ** 2
        peak = int(np.clip(np.argmax(corr), 1, corr.size - 2))
        y0, y1, y2 = corr[peak - 1:peak + 2]
        denom = y0 - 2.0 * y1 + y2
        frac = 0.5 * (y0 - y2) / denom if denom < 0 else 0.0
        starts.append(lo + peak + frac)
        numbers.append(int(round((t0 - tau[0]) / FRAME_SAMPLES)))
    cfo_hz += _residual_cfo_hz(x, np.array(starts), cfo_hz)
    starts_s = np.array(starts) / FS_HZ
    numbers = np.array(numbers, dtype=np.int64)
    period = float(np.polyfit(numbers, starts_s, 1)[0]) if numbers.size > 1 else float("nan")
    return PssAcquisition(starts_s, numbers, period, cfo_hz - center_offset_hz, metric,
                          metric > PSS_DETECT_THRESHOLD)
