"""A downlink pilot comb as complex baseband (Starlink's: [Shen 2024], eq. 1).

The pilot is ``n_tones`` unmodulated tones spaced ``tone_spacing_hz`` around
the carrier ``carrier_hz`` (tone k = -(n-1)/2 .. (n-1)/2 at RF frequency
``carrier_hz + k * tone_spacing_hz``). At complex baseband, with the central
tone at 0 Hz, a receiver sees tone k at

    k * spacing + s_k * doppler_geom(t) + clock_offset(t),   s_k = f_k / f_c,

because a range rate shifts every tone in proportion to its own RF frequency
(DESIGN 4.2) while oscillator offsets shift all tones alike. The phase of each
tone is 2 pi times the integral of that frequency, so Doppler rate and its
change enter exactly.
"""

from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from ..constellations import DEFAULT_FAMILY, REGISTRY, CombModel, family
from ..errors import InputError

__all__ = ["PilotComb", "comb_baseband", "add_noise", "noise_sigma"]

#: The comb assumed when none is given: the default family's (Starlink's).
_DEFAULT = REGISTRY[DEFAULT_FAMILY]
# The reference family has a comb (the registry is written so); the cast tells mypy.
_DEFAULT_COMB = cast(CombModel, _DEFAULT.comb)


@dataclass(frozen=True)
class PilotComb:
    """Pilot comb parameters.

    ``amplitudes`` default to one (each tone then has the C/N0 given to
    :func:`add_noise`); ``phases_rad`` default to Newman phases
    ``pi k^2 / n_tones``, which keep the crest factor of the sum low (it
    matters for 16-bit recordings). The defaults are the comb of
    :data:`leosop.constellations.DEFAULT_FAMILY`; :meth:`of` builds any
    registered family's.
    """

    carrier_hz: float = _DEFAULT.carrier_hz
    n_tones: int = _DEFAULT_COMB.n_tones
    tone_spacing_hz: float = _DEFAULT_COMB.tone_spacing_hz
    amplitudes: tuple | None = None
    phases_rad: tuple | None = None

    def __post_init__(self):
        if int(self.n_tones) != self.n_tones or self.n_tones < 1 or self.n_tones % 2 == 0:
            raise InputError(f"n_tones={self.n_tones} must be an odd integer >= 1 (the comb has a central tone)")
        if not self.carrier_hz > 0 or not self.tone_spacing_hz > 0:
            raise InputError(f"carrier_hz={self.carrier_hz} and tone_spacing_hz={self.tone_spacing_hz} must be > 0")
        for name in ("amplitudes", "phases_rad"):
            value = getattr(self, name)
            if value is not None and len(value) != self.n_tones:
                raise InputError(f"{name} has {len(value)} values, expected n_tones={self.n_tones}")

    @classmethod
    def of(cls, key: str) -> "PilotComb":
        """The pilot comb of the registered family ``key``; InputError when it has none."""
        fam = family(key)
        if fam.comb is None:
            raise InputError(f"constellation {key!r} has no pilot comb in the registry (measurement level only)")
        return cls(carrier_hz=fam.carrier_hz, n_tones=fam.comb.n_tones, tone_spacing_hz=fam.comb.tone_spacing_hz)

    def through_lo(self, lo_offset_hz: float) -> "PilotComb":
        """The comb as a receiver whose LO is ``lo_offset_hz`` off sees it, for the estimators' tone model.

        An LO offset moves every tone alike while Doppler scales with each
        tone's RF frequency; with ``doppler_hz`` including the offset (DESIGN
        4.2) tone k sits at ``k sp (1 - lo / f_c) + s_k doppler_hz``: the tones
        of a comb of carrier ``f_c - lo`` and spacing ``sp (1 - lo / f_c)``
        (same ``sp / f_c``). Ignoring a 620 kHz offset misplaces the edge
        tones of the Starlink comb by 9.6 Hz, a bin of a 0.1 s block.
        """
        factor = 1.0 - float(lo_offset_hz) / float(self.carrier_hz)
        return PilotComb(carrier_hz=self.carrier_hz * factor, n_tones=self.n_tones,
                         tone_spacing_hz=self.tone_spacing_hz * factor, amplitudes=self.amplitudes,
                         phases_rad=self.phases_rad)

    @property
    def tone_index(self) -> npt.NDArray[np.int_]:
        """Tone numbers k, shape (n_tones,), central tone 0."""
        half = self.n_tones // 2
        return np.arange(-half, half + 1)

    @property
    def offsets_hz(self) -> npt.NDArray[np.float64]:
        """Nominal baseband frequency of each tone, k * spacing, shape (n_tones,)."""
        return self.tone_index * np.float64(self.tone_spacing_hz)

    @property
    def doppler_scale(self) -> npt.NDArray[np.float64]:
        """s_k = f_k / f_c: tone k's Doppler per unit central-tone Doppler, shape (n_tones,)."""
        return 1.0 + self.offsets_hz / float(self.carrier_hz)

    @property
    def tone_amplitudes(self) -> npt.NDArray[np.float64]:
        """Amplitude of each tone, shape (n_tones,)."""
        return np.ones(self.n_tones) if self.amplitudes is None else np.asarray(self.amplitudes, dtype=float)

    @property
    def tone_phases_rad(self) -> npt.NDArray[np.float64]:
        """Phase of each tone at zero Doppler phase, shape (n_tones,)."""
        if self.phases_rad is None:
            return np.pi * self.tone_index**2 / self.n_tones
        return np.asarray(self.phases_rad, dtype=float)


def _frac(cycles):
    """Cycles reduced to [-0.5, 0.5] so that exp() sees small arguments."""
    return cycles - np.round(cycles)


def comb_baseband(comb: PilotComb, t_s: npt.ArrayLike, geom_cycles: npt.ArrayLike, clock_cycles: npt.ArrayLike = 0.0, *,
                  phase_rad: npt.ArrayLike = 0.0) -> npt.NDArray[np.complex128]:
    """Complex baseband samples of the pilot comb.

    Parameters
    ----------
    comb : PilotComb
    t_s : array_like, shape (..., n)
        Sample times [s] (any origin; the comb's nominal tone phases refer to it).
    geom_cycles : array_like, broadcastable to t_s
        Integral of the central tone's geometric Doppler [cycles],
        ``-carrier_hz * (range - range0) / c``. Tone k gets ``s_k`` times it.
    clock_cycles : array_like, broadcastable to t_s
        Integral of the clock-induced frequency offset [cycles], common to all tones.
    phase_rad : array_like, broadcastable to t_s[..., :1]
        Common carrier phase.

    Returns
    -------
    iq : ndarray of complex128, shape of t_s
    """
    t = np.asarray(t_s, dtype=float)
    g = np.asarray(geom_cycles, dtype=float)
    # sum_k a_k exp(j(phi_k + 2 pi (k spacing t + s_k g))) = base * sum_k c_k z^k
    # with base = exp(j 2 pi g) and z = exp(j 2 pi (spacing t + spacing g / f_c)):
    # Horner's rule on z costs complex products instead of one exp per tone.
    base = np.exp(2j * np.pi * _frac(g + clock_cycles)) * np.exp(1j * np.asarray(phase_rad))
    spacing = float(comb.tone_spacing_hz)
    z = np.exp(2j * np.pi * _frac(spacing * t + spacing / float(comb.carrier_hz) * g))
    coef = comb.tone_amplitudes * np.exp(1j * comb.tone_phases_rad)
    acc = np.full(np.broadcast_shapes(z.shape, base.shape), coef[-1], dtype=complex)
    for c in coef[-2::-1]:
        acc *= z
        acc += c
    return base * acc * np.conj(z) ** (comb.n_tones // 2)


def noise_sigma(cn0_dbhz: npt.ArrayLike, sample_rate_hz: float) -> npt.NDArray[np.float64]:
    """Standard deviation of complex white noise per sample for a unit-amplitude tone at ``cn0_dbhz``.

    A tone of power 1 over noise of one-sided density N0 has C/N0 = 1/N0;
    sampled at ``sample_rate_hz`` the complex noise variance is N0 * fs.
    """
    return np.sqrt(float(sample_rate_hz) / 10.0 ** (np.asarray(cn0_dbhz, dtype=float) / 10.0))


def add_noise(iq: npt.NDArray[np.complexfloating], cn0_dbhz: npt.ArrayLike, sample_rate_hz: float,
              rng: np.random.Generator) -> npt.NDArray[np.complex128]:
    """``iq`` plus circular complex white noise at ``cn0_dbhz`` (per unit-amplitude tone).

    Parameters
    ----------
    iq : ndarray, shape (..., n)
    cn0_dbhz : float or array_like broadcastable to iq[..., :1]
    rng : numpy.random.Generator
    """
    sigma = noise_sigma(cn0_dbhz, sample_rate_hz) / np.sqrt(2.0)
    if sigma.ndim:
        sigma = sigma[..., None]
    return iq + sigma * (rng.standard_normal(iq.shape) + 1j * rng.standard_normal(iq.shape))
