"""A consumer receiver front end (LNB + SDR): its impairments modelled, for the generator.

People record Starlink with a satellite-TV LNB and a cheap SDR. Between the
antenna and the file the samples pass, in this order (:meth:`FrontEnd.apply`):

1. **Interferers**: CW / narrowband lines at fixed baseband frequencies
   (``cw``: frequency [Hz] and power [dB-Hz], the same unit as a pilot tone's
   C/N0, so a 70 dB-Hz line is 25 dB above a 45 dB-Hz tone).
2. **LO phase noise**, multiplying everything received: a random walk
   (Wiener phase of Lorentzian linewidth ``phase_noise_linewidth_hz``: the
   free-running or crystal part) plus a bounded part (first-order low-pass
   phase of flat level ``phase_noise_dbc_hz`` up to ``phase_noise_corner_hz``:
   a PLL's in-loop floor; variance ``pi * corner * 10^(dBc/10)`` rad^2).
   The LO's frequency offset and drift are not here: they are part of every
   satellite's Doppler (DESIGN 4.2) and :class:`~.channel.SiteChannel` draws them
   (``leosop generate --rx-offset-hz --rx-drift-hz-per-s``).
3. **IQ imbalance**: the Q branch ``iq_gain_db`` louder than I and
   ``iq_phase_deg`` off quadrature, ``Q' = g (Q cos phi - I sin phi)``:
   every line at f gets an image at -f, ``|K2/K1|^2`` below it
   (:func:`image_rejection_db`).
4. **DC offset**: a line at 0 Hz of ``dc_dbhz`` (mixer LO leakage).
5. **AGC**: the gain steps by a value drawn uniformly in ``+-agc_step_db``
   every ``agc_period_s`` of the signal's timeline (snapshots a period apart
   each get their own gain).
6. **Quantisation and clipping** (in the writer,
   :func:`~.iq_write.quantise`): ``bits`` of 8 (ci8 / cu8), 12 (ci16 with four
   zero LSBs) or 16; the full scale sits ``headroom_db`` above the RMS
   of a component at nominal gain, so a gain step up clips.

:data:`PRESETS` holds ``consumer``: an LNB 620 kHz off drifting 25 Hz/s, a
PLL floor of -75 dBc/Hz to 30 kHz (3.1 deg RMS) on a 0.01 Hz random walk,
0.5 dB / 2 deg IQ imbalance (29 dB image rejection), a 60 dB-Hz DC offset, a
70 dB-Hz CW line at +700 kHz, 8 bits.
"""

from dataclasses import asdict, dataclass, field

import numpy as np

from ..constants import C_MPS
from ..errors import InputError
from .pilot import noise_sigma

__all__ = ["FrontEnd", "PRESETS", "image_rejection_db", "wiener_doppler_sigma_hz"]

#: ADC resolutions the writer models: bits -> SigMF datatype (12 bits are stored as ci16).
BITS_DATATYPE = {8: "ci8", 12: "ci16_le", 16: "ci16_le"}

#: Named front ends: values for ``leosop generate --front-end NAME`` (options given explicitly win).
PRESETS = {
    "consumer": {"rx_offset_hz": 620e3, "rx_drift_hz_per_s": 25.0, "phase_noise_linewidth_hz": 0.01,
                 "phase_noise_dbc_hz": -75.0, "phase_noise_corner_hz": 30e3, "iq_gain_db": 0.5,
                 "iq_phase_deg": 2.0, "dc_dbhz": 60.0, "cw": ((700e3, 70.0),), "bits": 8},
}


def image_rejection_db(iq_gain_db, iq_phase_deg):
    """|K1|^2 / |K2|^2 of the IQ imbalance model (``y = K1 x + K2 conj(x)``) [dB]."""
    g = 10.0 ** (np.asarray(iq_gain_db, dtype=float) / 20.0)
    phi = np.radians(iq_phase_deg)
    k1 = 0.5 * (1.0 + g * np.exp(-1j * phi))
    k2 = 0.5 * (1.0 - g * np.exp(1j * phi))
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(np.abs(k1) ** 2 / np.abs(k2) ** 2)


def wiener_doppler_sigma_hz(linewidth_hz, block_s):
    """Standard deviation of a block's frequency estimate caused by a Wiener LO phase [Hz].

    The least-squares slope of a Brownian phase of increment variance
    ``2 pi linewidth`` per second over a block of T seconds has variance
    ``6 / (5 T)`` times that; in Hz, ``sigma^2 = 3 linewidth / (5 pi T)``.
    It adds (in quadrature) to the estimator's Cramér-Rao sigma and is common
    to every satellite of the block, independent from block to block. A
    snapshot fix's clock state absorbs it; a static fix's clock polynomial
    does not, and the replay estimates the linewidth from the fix's
    residuals and solves again with one frequency state of this sigma per
    block (:func:`leosop.replay.lo.lo_noise`).
    0.31 Hz for the ``consumer`` preset's 0.01 Hz over a 20 ms snapshot.
    """
    return np.sqrt(3.0 * np.asarray(linewidth_hz, dtype=float) / (5.0 * np.pi * np.asarray(block_s, dtype=float)))


@dataclass
class FrontEnd:
    """Receiver front-end impairments (see the module docstring; all default to none).

    Attributes
    ----------
    phase_noise_linewidth_hz, phase_noise_dbc_hz, phase_noise_corner_hz : float
        Wiener linewidth [Hz]; PLL floor [dBc/Hz] (-inf: none) and its corner [Hz].
    iq_gain_db, iq_phase_deg : float
    dc_dbhz : float
        -inf: no DC offset.
    cw : tuple of (frequency_hz, power_dbhz)
    agc_step_db, agc_period_s : float
    bits : int or None
        8, 12, 16, or None (no quantisation: cf32).
    headroom_db : float
        Full scale over the RMS of one component at nominal gain.
    """

    phase_noise_linewidth_hz: float = 0.0
    phase_noise_dbc_hz: float = -np.inf
    phase_noise_corner_hz: float = 30e3
    iq_gain_db: float = 0.0
    iq_phase_deg: float = 0.0
    dc_dbhz: float = -np.inf
    cw: tuple = ()
    agc_step_db: float = 0.0
    agc_period_s: float = 1.0
    bits: int | None = None
    headroom_db: float = 12.0
    _state: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        self.cw = tuple((float(f), float(p)) for f, p in self.cw)
        checks = [("phase_noise_linewidth_hz", self.phase_noise_linewidth_hz >= 0),
                  ("phase_noise_corner_hz", self.phase_noise_corner_hz > 0),
                  ("iq_gain_db", abs(self.iq_gain_db) <= 6.0), ("iq_phase_deg", abs(self.iq_phase_deg) <= 30.0),
                  ("agc_step_db", 0 <= self.agc_step_db <= 40.0), ("agc_period_s", self.agc_period_s > 0),
                  ("headroom_db", 0 < self.headroom_db <= 60.0), ("bits", self.bits in (None, 8, 12, 16))]
        for name, ok in checks:
            if not ok:
                raise InputError(f"front end: {name} {getattr(self, name)!r} is out of range")

    @property
    def active(self):
        """True when anything is modelled (else the samples pass untouched)."""
        return bool(self.phase_noise_linewidth_hz > 0 or np.isfinite(self.phase_noise_dbc_hz) or self.iq_gain_db
                    or self.iq_phase_deg or np.isfinite(self.dc_dbhz) or self.cw or self.agc_step_db
                    or self.bits is not None)

    def metadata(self):
        """The parameters as JSON values (``leosop:front_end``; -inf as None)."""
        out = {k: v for k, v in asdict(self).items() if k != "_state"}
        out["cw"] = [{"frequency_hz": f, "power_dbhz": p} for f, p in self.cw]
        out["image_rejection_db"] = float(image_rejection_db(self.iq_gain_db, self.iq_phase_deg))
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in out.items()}

    def full_scale(self, rms_component):
        """Full scale of the quantiser for a signal of ``rms_component`` per component at nominal gain."""
        return float(rms_component) * 10.0 ** (self.headroom_db / 20.0)

    def agc_gain_db(self, segments, rng):
        """Gain of AGC segments ``segments`` (int array) [dB], drawn once per segment and kept."""
        gains = self._state.setdefault("agc", {})
        for s in np.unique(segments):
            if int(s) not in gains:
                gains[int(s)] = float(rng.uniform(-self.agc_step_db, self.agc_step_db)) if self.agc_step_db else 0.0
        return np.array([gains[int(s)] for s in segments])

    def agc_steps(self):
        """The AGC gains drawn so far: ``[{"start_s", "gain_db"}...]`` by segment start on the signal's timeline."""
        return [{"start_s": k * self.agc_period_s, "gain_db": g} for k, g in sorted(self._state.get("agc", {}).items())]

    def _phase_noise(self, t_s, fs, rng):
        """LO phase at ``t_s`` (increasing, continuing earlier calls) [rad], (n,)."""
        st = self._state
        n = t_s.size
        t_prev = st.get("t", t_s[0] - 1.0 / fs)
        dt = np.diff(np.concatenate([[t_prev], t_s]))  # the LO runs through snapshot gaps
        walk = st.get("walk", 0.0)
        phase = np.zeros(n)
        if self.phase_noise_linewidth_hz > 0:
            steps = rng.standard_normal(n) * np.sqrt(2.0 * np.pi * self.phase_noise_linewidth_hz * dt)
            phase = walk + np.cumsum(steps)
            st["walk"] = float(phase[-1])
        if np.isfinite(self.phase_noise_dbc_hz):
            # Ornstein-Uhlenbeck: exact discretisation of a first-order low-pass of white phase.
            var = np.pi * self.phase_noise_corner_hz * 10.0 ** (self.phase_noise_dbc_hz / 10.0)
            a = np.exp(-2.0 * np.pi * self.phase_noise_corner_hz * dt)
            drive = rng.standard_normal(n) * np.sqrt(var * (1.0 - a * a))
            ou = _ar1(a, drive, st.get("ou", rng.standard_normal() * np.sqrt(var)))
            st["ou"] = float(ou[-1])
            phase = phase + ou
        st["t"] = float(t_s[-1])
        return phase

    def apply(self, iq, t_s, fs, cn0_ref_dbhz, rng):
        """The front end's output for channel samples ``iq`` at signal times ``t_s``.

        Parameters
        ----------
        iq : ndarray of complex, (n,)
            Channel output (combs and noise) at amplitude 1 per tone of C/N0
            ``cn0_ref_dbhz``.
        t_s : ndarray, (n,)
            Sample times on the signal's timeline, increasing across calls.
        fs : float
        cn0_ref_dbhz : float
            C/N0 of a unit tone (sets the interferers' and DC's amplitudes).
        rng : numpy.random.Generator

        Returns
        -------
        ndarray of complex128, (n,)
        """
        x = np.asarray(iq, dtype=complex)
        for f_hz, p_dbhz in self.cw:
            x = x + 10.0 ** ((p_dbhz - cn0_ref_dbhz) / 20.0) * np.exp(2j * np.pi * _frac(f_hz * t_s))
        if self.phase_noise_linewidth_hz > 0 or np.isfinite(self.phase_noise_dbc_hz):
            x = x * np.exp(1j * self._phase_noise(t_s, fs, rng))
        if self.iq_gain_db or self.iq_phase_deg:
            g = 10.0 ** (self.iq_gain_db / 20.0)
            phi = np.radians(self.iq_phase_deg)
            x = x.real + 1j * g * (x.imag * np.cos(phi) - x.real * np.sin(phi))
        if np.isfinite(self.dc_dbhz):
            x = x + 10.0 ** ((self.dc_dbhz - cn0_ref_dbhz) / 20.0) * np.exp(0.25j * np.pi)
        if self.agc_step_db:
            x = x * 10.0 ** (self.agc_gain_db(np.floor(t_s / self.agc_period_s).astype(np.int64), rng) / 20.0)
        return x

    def rms_component(self, n_tones_total, cn0_ref_dbhz, fs):
        """RMS of one component of the output at nominal gain: noise, tones, lines (for the full scale)."""
        power = noise_sigma(cn0_ref_dbhz, fs) ** 2 + n_tones_total
        for _, p in self.cw:
            power += 10.0 ** ((p - cn0_ref_dbhz) / 10.0)
        if np.isfinite(self.dc_dbhz):
            power += 10.0 ** ((self.dc_dbhz - cn0_ref_dbhz) / 10.0)
        return float(np.sqrt(power / 2.0))


def _frac(cycles):
    return cycles - np.round(cycles)


def _ar1(a, drive, x0):
    """x[k] = a[k] x[k-1] + drive[k] from x0, (n,): one linear filter per run of equal ``a``
    (a capture; ``a`` changes only where a snapshot gap starts)."""
    from scipy.signal import lfilter

    out = np.empty(drive.size)
    edges = np.flatnonzero(np.r_[True, ~np.isclose(a[1:], a[:-1], rtol=1e-9, atol=0.0), True])
    x = x0
    for i, j in zip(edges[:-1], edges[1:]):
        out[i:j], _ = lfilter([1.0], [1.0, -a[i]], drive[i:j], zi=[a[i] * x])
        x = out[j - 1]
    return out


# ---------------------------------------------------------------------------------------------------------------
# What a recording's front end did, seen in its samples (leosop doctor; the comb search's cleaning).

#: False-alarm probability of the line detector per block (a noise bin passes its threshold this often).
LINE_PFA = 1e-3
#: A line grows from its peak while the power smoothed over this many bins exceeds twice the noise mean,
#: so what is left of a strong line after excision (sidelobes) lies below that level.
_LINE_SMOOTH_BINS = 8
#: A line with at least this many partners (strong bins at whole tone spacings from it, of comparable power)
#: is a comb tone.
_COMB_PARTNERS = 2
#: Partners are looked for within the line's half-width plus this many bins of the exact multiple of the spacing,
#: plus the spread of the received spacing: a comb arrives scaled by its Doppler, ``sp (1 + doppler / f_c)`` with
#: the LO offset taken out (:meth:`~.pilot.PilotComb.through_lo`), and ``|doppler| / f_c`` stays below a range rate
#: of 8 km/s over c (0.9 bins of a 0.1 s block at the edge tones). The half-width covers a chirped tone's smear.
_PARTNER_BINS = 2
_PARTNER_SPACING_SPREAD = 8e3 / C_MPS
#: A partner's strongest bin is within this of the line's peak [dB]: a comb's tones have one C/N0 and one smear,
#: their peak bins differ by scalloping (3.9 dB at most) and noise. A 70 dB-Hz CW line is 25 dB above a
#: 45 dB-Hz comb's tones (issue 26: counted without power, they made it a comb tone).
_PARTNER_DB = 10.0


@dataclass(frozen=True)
class Line:
    """A narrowband line found in a block's spectrum.

    Attributes
    ----------
    frequency_hz : float
        Peak, baseband.
    power_dbhz : float
        Its power in the unit of a tone's C/N0 (power over the noise density).
    lo_bin, hi_bin : int
        Bins (FFT order, may be negative) excised for it, inclusive.
    """

    frequency_hz: float
    power_dbhz: float
    lo_bin: int
    hi_bin: int


@dataclass(frozen=True)
class Cleaning:
    """What :func:`clean_block` found and removed in one block.

    Attributes
    ----------
    dc : complex
        Block mean removed (sample units).
    dc_dbhz : float
        Its power over the noise density (the unit of a tone's C/N0).
    iq_gain_db, iq_phase_deg : float
        IQ imbalance estimated (Q over I; the model of :class:`FrontEnd`).
    iq_corrected : bool
        True when the imbalance was significant and undone.
    lines : tuple of Line
        CW / narrowband interferers excised (lines not part of a comb).
    noise_density : float
        Noise power per Hz in sample units (N0), from the spectrum's median.
    spectrum : ndarray of complex64, (n,) or None
        The cleaned block's FFT (:func:`~.fft.fft`) when no line was
        excised (the FFT the cleaning made; the comb search can reuse it,
        :func:`~.multicomb.find_combs`); None when lines were excised.
    """

    dc: complex
    dc_dbhz: float
    iq_gain_db: float
    iq_phase_deg: float
    iq_corrected: bool
    lines: tuple
    noise_density: float
    spectrum: np.ndarray | None = field(default=None, compare=False, repr=False)


def iq_imbalance(iq):
    """Q-over-I gain [dB] and phase error [deg] of a block (DC removed first), and their 1-sigma [dB, deg].

    For a circular received signal (noise, tones off 0 Hz) ``E[I^2] = E[Q^2]``
    and ``E[I Q] = 0``; the model ``Q' = g (Q cos phi - I sin phi)`` gives
    ``g^2 = E[Q'^2] / E[I^2]`` and ``sin phi = -E[I Q'] / sqrt(E[I^2] E[Q'^2])``.
    Each moment ratio has a spread of ~1/sqrt(n).
    """
    x = np.asarray(iq)
    i = x.real - x.real.mean()
    q = x.imag - x.imag.mean()
    pi, pq, piq = float(np.dot(i, i)), float(np.dot(q, q)), float(np.dot(i, q))
    if pi <= 0 or pq <= 0:
        return 0.0, 0.0, np.inf, np.inf
    gain_db = 10.0 * np.log10(pq / pi)
    phase_deg = float(np.degrees(np.arcsin(np.clip(-piq / np.sqrt(pi * pq), -1.0, 1.0))))
    n = x.size
    return gain_db, phase_deg, float(20.0 / np.log(10.0) / np.sqrt(n)), float(np.degrees(1.0 / np.sqrt(n)))


def correct_iq(iq, gain_db, phase_deg):
    """Undo the IQ imbalance of :class:`FrontEnd` (``Q = (Q'/g + I sin phi) / cos phi``), complex64 (n,)."""
    x = np.asarray(iq)
    g = 10.0 ** (gain_db / 20.0)
    phi = np.radians(phase_deg)
    q = (x.imag / g + x.real * np.sin(phi)) / np.cos(phi)
    return (x.real + 1j * q).astype(np.complex64)


def find_lines(power, fs, comb, *, pfa=LINE_PFA):
    """Strong narrow lines of a block's power spectrum that belong to no comb; the noise mean per bin.

    A bin beyond ``-ln(pfa / n)`` noise means (exponential power) starts a
    line; the line spans the run of bins around it whose power, smoothed over
    ``_LINE_SMOOTH_BINS``, exceeds twice the noise mean. A line with at least
    ``_COMB_PARTNERS`` partners is a comb's tone and kept: whole tone
    spacings m = +-1..+-(n_tones-1) from its peak (within the line's
    half-width plus ``_PARTNER_BINS`` and the spacing's Doppler spread)
    where a strong bin lies within ``_PARTNER_DB`` of the peak's power. A
    strong CW line among combs has strong bins at its spacings (other combs'
    tones) but none of its power.

    Parameters
    ----------
    power : ndarray, (n,)
        |FFT|^2 of the block, FFT order.
    fs : float
    comb : PilotComb

    Returns
    -------
    lines : list of Line
        Strongest first.
    noise_bin : float
        Noise mean per bin (median / ln 2 over a subsample).
    """
    n = power.size
    sub = power[::max(1, n // 16384)]
    noise = float(np.partition(sub, sub.size // 2)[sub.size // 2]) / np.log(2.0)
    if noise <= 0:
        return [], noise
    # Work in fftshift order (0 Hz in the middle: runs never wrap except at the band's edges), zero-padded
    # as np.convolve's "same" mode pads (the smoothing is computed only near the strong bins, _strong_runs).
    pad = _LINE_SMOOTH_BINS // 2
    padded = np.zeros(n + _LINE_SMOOTH_BINS - 1, dtype=power.dtype)
    padded[pad:pad + n // 2] = power[n - n // 2:]
    padded[pad + n // 2:pad + n] = power[:n - n // 2]
    p = padded[pad:pad + n]  # np.fft.fftshift(power)
    threshold = -np.log(pfa / n) * noise
    strong = np.flatnonzero(p > threshold)
    if not strong.size:
        return [], noise
    lo, hi = _strong_runs(padded, strong, 2.0 * noise)
    # Each run's peak: the first bin of its largest power (as argmax).
    idx, first = _ranges(lo, hi + 1)
    vals = p[idx]
    hit = np.flatnonzero(vals == np.repeat(np.maximum.reduceat(vals, first), hi - lo + 1))
    peak = idx[hit[np.searchsorted(hit, first)]]
    m = np.concatenate([np.arange(-(comb.n_tones - 1), 0), np.arange(1, comb.n_tones)])
    spacing_bins = comb.tone_spacing_hz * n / fs
    half = (hi - lo) // 2 + _PARTNER_BINS + int(np.ceil((comb.n_tones - 1) * spacing_bins * _PARTNER_SPACING_SPREAD))
    centre = np.round(peak[:, None] + m * spacing_bins).astype(np.int64)  # (runs, 2 K - 2)
    window_max = _window_max(p, centre - half[:, None], centre + half[:, None])
    floor = np.maximum(threshold, p[peak] * 10.0 ** (-_PARTNER_DB / 10.0))  # (runs,)
    partners = np.sum(window_max > floor[:, None], axis=1)
    lines = []
    for i in np.flatnonzero(partners < _COMB_PARTNERS):
        # A tone of amplitude A puts A^2 n^2 into its bins; the noise n N0 fs into each.
        power_dbhz = 10.0 * np.log10(float(np.sum(p[lo[i]:hi[i] + 1])) * fs / (n * noise))
        k0 = -(n // 2)  # signed frequency bin of shifted index 0
        lines.append(Line((peak[i] + k0) * fs / n, power_dbhz, int(lo[i] + k0), int(hi[i] + k0)))
    lines.sort(key=lambda ln: -ln.power_dbhz)
    return lines, noise


def _strong_runs(padded, strong, level):
    """The runs of bins holding a strong bin where the power smoothed over ``_LINE_SMOOTH_BINS`` exceeds ``level``.

    A run is a maximal range of bins each strong or above ``level`` once
    smoothed (``np.convolve(p, ones / L, mode="same")``, which
    zero-pads); only runs holding a strong bin are returned. The smoothing
    is computed in windows around the strong bins (a few percent of the
    spectrum), widened until every run ends inside its window: each
    smoothed bin is the same dot product of the same ``L`` bins as over the
    whole spectrum, so the runs are those of the whole spectrum.

    Parameters
    ----------
    padded : ndarray, (n + L - 1,)
        The power spectrum (fftshift order) with ``L // 2`` zeros before and ``L // 2 - 1`` after.
    strong : ndarray of int, (n_strong,)
        Indices of the strong bins, increasing (they are in runs whatever the smoothing).
    level : float

    Returns
    -------
    lo, hi : ndarray of int, (n_runs,)
        First and last bin of each run, increasing.
    """
    L = _LINE_SMOOTH_BINS
    n = padded.size - L + 1
    kernel = np.full(L, 1.0 / L)
    half = 4 * L
    while True:
        # Windows [a, b) round the strong bins, merged where they overlap.
        a, b = np.maximum(strong - half, 0), np.minimum(strong + half + 1, n)
        new = np.r_[True, a[1:] > b[:-1]]
        a, b = a[new], np.maximum.reduceat(b, np.flatnonzero(new))
        # Each window's bins with L - 1 more of padding, gathered: smoothed bin i of a window is the dot
        # product of padded[i:i + L] (np.convolve's "valid" outputs whose inputs lie in one window).
        rel, first = _ranges(a, b + L - 1)  # bins of padded; where each window starts in them
        smooth = np.convolve(padded[rel], kernel, mode="valid")
        keep = np.ones(smooth.size, bool)  # drop outputs that straddle two windows
        keep[(first[1:, None] - L + 1 + np.arange(L - 1)).ravel()] = False
        bins = rel[:smooth.size][keep]  # the smoothed bins
        above = smooth[keep] > level
        above[np.searchsorted(bins, strong)] = True
        # Runs of ``above`` within each window (a new window breaks a run).
        start = above & np.r_[True, ~above[:-1] | (np.diff(bins) != 1)]
        end = above & np.r_[~above[1:] | (np.diff(bins) != 1), True]
        lo, hi = bins[start], bins[end]
        holds = np.searchsorted(strong, lo) < np.searchsorted(strong, hi, side="right")
        lo, hi = lo[holds], hi[holds]
        # A run that reaches its window's edge (not the spectrum's) may go on beyond it: widen.
        w = np.searchsorted(a, lo, side="right") - 1  # each run's window
        if not np.any(((lo == a[w]) & (a[w] > 0)) | ((hi + 1 == b[w]) & (b[w] < n))):
            return lo, hi
        half *= 4


def _ranges(a, b):
    """The indices ``a[k] .. b[k] - 1`` of every range, concatenated, (sum(b - a),), and where each range
    starts among them, (n_ranges,); ``b >= a``."""
    size = b - a
    first = np.cumsum(size) - size
    return np.arange(first[-1] + size[-1] if size.size else 0) - np.repeat(first - a, size), first


def _window_max(p, a, b):
    """Largest ``p[a:b + 1]`` per window (0 where a window lies outside ``p``), shape of ``a``.

    Only the windows' own bins are read (they are a few percent of ``p``).
    """
    n, shape = p.size, np.shape(a)
    a, b = np.clip(a, 0, n).ravel(), np.clip(b + 1, 0, n).ravel()  # half-open, within [0, n]
    full = b > a
    out = np.zeros(a.size)
    if full.any():
        idx, first = _ranges(a[full], b[full])
        out[full] = np.maximum.reduceat(p[idx], first)
    return out.reshape(shape)


def clean_block(iq, fs, comb, *, pfa=LINE_PFA):
    """A block with its DC, IQ imbalance and CW / narrowband interferers removed, and what was removed.

    1. The block mean (DC offset) is subtracted.
    2. The IQ imbalance is estimated (:func:`iq_imbalance`) and undone when
       beyond 5 sigma of its estimate (a comb's image, ``image_rejection_db``
       below it, would otherwise look like a satellite at minus its Doppler).
    3. Lines that no comb explains (:func:`find_lines`) are zeroed in the
       block's spectrum (excision) and the block transformed back.

    A clean block comes back as it was, less its mean (one FFT spent).

    Parameters
    ----------
    iq : ndarray of complex, (n,)
    fs : float
    comb : PilotComb

    Returns
    -------
    iq : ndarray of complex64, (n,)
    cleaning : Cleaning
    """
    from .fft import fft

    x = np.asarray(iq, dtype=np.complex64)
    n = x.size
    dc = complex(x.mean())
    x = x - np.complex64(dc)
    gain_db, phase_deg, s_gain, s_phase = iq_imbalance(x)
    corrected = abs(gain_db) > 5.0 * s_gain or abs(phase_deg) > 5.0 * s_phase
    if corrected:
        x = correct_iq(x, gain_db, phase_deg)
    spectrum = fft(x)
    power = np.abs(spectrum) ** 2
    lines, noise_bin = find_lines(power, fs, comb, pfa=pfa)
    n0 = noise_bin / (n * fs) if noise_bin > 0 else np.nan  # |X|^2 of white noise: n * sigma^2 = n * N0 * fs
    dc_dbhz = 10.0 * np.log10(abs(dc) ** 2 / n0) if abs(dc) > 0 and n0 > 0 else -np.inf
    if lines:
        for ln in lines:
            spectrum[np.arange(ln.lo_bin, ln.hi_bin + 1) % n] = 0.0
        x = np.fft.ifft(spectrum).astype(np.complex64)
    return x, Cleaning(dc, dc_dbhz, gain_db, phase_deg, bool(corrected), tuple(lines), n0,
                       None if lines else spectrum)
