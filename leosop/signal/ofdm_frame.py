"""The Starlink Ku-band OFDM downlink frame: numerology, PSS, SSS stand-in, data symbols.


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
"""

from functools import lru_cache

import numpy as np
import scipy.fft

__all__ = [
    "FS_HZ", "N_FFT", "N_CP", "N_SYMBOL", "N_SYMBOLS_PER_FRAME", "N_DATA_SYMBOLS", "N_GUARD",
    "FRAME_SAMPLES", "FRAME_PERIOD_S", "SUBCARRIER_SPACING_HZ", "OFDM_CENTER_OFFSET_HZ",
    "GUTTER_SUBCARRIERS", "N_PSS_SEGMENTS", "PSS_SEGMENT_LEN",
    "active_subcarriers", "pss_mseq", "pss_time", "sss_symbol", "data_symbols", "symbol_time", "frame",
    "qam4_codes", "pss_spectrum", "sss_spectrum",
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


def qam4_codes(raw, index):
    """Unit-power 4QAM symbols numbered ``index`` from random bytes (two bits per symbol)."""
    b = ((raw[index // 4] >> (2 * (index % 4)).astype(np.uint8)) & 3).astype(np.int8)
    return ((1 - 2 * (b & 1)) + 1j * (1 - 2 * (b >> 1))) / np.sqrt(2.0)


def _qam4(rng, shape):
    """Unit-power 4QAM symbols of ``shape`` from ``rng``'s bytes."""
    n = int(np.prod(shape))
    raw = np.frombuffer(rng.bytes((n + 3) // 4), dtype=np.uint8)
    return qam4_codes(raw, np.arange(n)).reshape(shape)


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
def pss_spectrum():
    """Spectrum of the PSS's useful part in the frame's normalisation, FFT-bin order, (1024,)."""
    return np.fft.fft(pss_time()[N_CP:]) / np.sqrt(N_FFT)


@lru_cache(maxsize=1)
def sss_spectrum():
    return sss_symbol(np.random.default_rng(_SSS_SEED))
