"""A consumer receiver front end (LNB + SDR): its impairments modelled, for the generator (cleaning: :mod:`.cleaning`).

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
    (a capture; ``a`` changes only where a snapshot gap starts).

    ``a = exp(-rate dt)`` with dt the difference of float sample times, which
    rounding moves by ~ulp(t): a relative 2 pi corner ulp(t), 1.3e-9 at 30 kHz
    past t = 32 s (a split every ~10 samples at 1e-9, the generator's former
    bottleneck), ~4e-7 after an hour. Runs are split where ``a`` moves by over
    1e-5 of itself (a snapshot gap: 4.7e-2 per missing sample at 30 kHz and
    4 MS/s) and each uses its first ``a``: x is then off by < 1e-5 of itself.
    """
    from scipy.signal import lfilter

    out = np.empty(drive.size)
    edges = np.flatnonzero(np.r_[True, ~np.isclose(a[1:], a[:-1], rtol=1e-5, atol=0.0), True])
    x = x0
    for i, j in zip(edges[:-1], edges[1:]):
        out[i:j], _ = lfilter([1.0], [1.0, -a[i]], drive[i:j], zi=[a[i] * x])
        x = out[j - 1]
    return out
