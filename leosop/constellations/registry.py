"""The constellation registry: every constellation-specific fact, one entry per family.

Each :class:`Family` holds what a stage needs to know of a constellation:
how its satellites are named in element sets (visibility, ``--constellation``
filters), its carrier and channels (Doppler models, GDOP, measurement files),
its signal model (a pilot comb that the signal chain generates and
estimates, or a single tone simulated at measurement level), its default
elevation mask and its measurement sigma model. Every stage reads
:data:`REGISTRY`; adding a constellation is adding one entry.

Clock model, the same for every family: a satellite's or the receiver's
oscillator has one fractional frequency error, so a clock-induced Doppler
offset scales with the carrier (:func:`clock_scale`, relative to the
reference family :data:`DEFAULT_FAMILY`).

Sigma model of a family simulated at measurement level: the Cramér-Rao
bound of the frequency of one tone of carrier-to-noise density C/N0 observed
for ``integration_s`` seconds (Rife and Boorstyn 1974, continuous-time
limit, which the estimators of :mod:`leosop.signal.fine` reach above
threshold)::

    sigma_hz = sqrt(6 / ((2 pi)^2 * C/N0 * T^3)),   C/N0 in Hz (linear)

The C/N0 and integration times of the entries are assumptions of this
toolkit, not published receiver figures: each is the order of magnitude of
what a small omnidirectional or patch antenna sees of that family's
downlink, and each can be overridden per scenario
(``leo.cn0_dbhz_by_family``):

- OneWeb (Ku, 11.7 GHz nominal): 45 dB-Hz, as Starlink's pilot, over the same
  10 ms block: 2.2 Hz (0.056 m/s).
- Iridium NEXT (L band, 1626.27 MHz ring-alert channel): bursts of about
  20 ms of unmodulated tone and BPSK frames; 50 dB-Hz over 20 ms: 0.44 Hz
  (0.081 m/s).
- Orbcomm (VHF, 137.5 MHz): a continuous 4800 bit/s downlink whose carrier
  is tracked after removing the modulation; 45 dB-Hz over 100 ms: 0.070 Hz
  (0.15 m/s).

A family with a pilot comb is measured through the comb estimators (signal
level) or their error model (:func:`leosop.signal.error_model.doppler_sigma_hz`)
at the scenario's ``leo.cn0_dbhz``; its ``cn0_dbhz``/``integration_s`` here
describe the comb's single tone.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["DEFAULT_FAMILY", "REGISTRY", "CombModel", "Family", "carriers_hz", "clock_scale", "family", "family_of",
           "tone_sigma_hz"]


@dataclass(frozen=True)
class CombModel:
    """A pilot comb: ``n_tones`` unmodulated tones ``tone_spacing_hz`` apart around the carrier.

    Attributes
    ----------
    n_tones : int
        Odd: the comb has a central tone at the carrier.
    tone_spacing_hz : float
    """

    n_tones: int
    tone_spacing_hz: float


@dataclass(frozen=True)
class Family:
    """Everything the toolkit knows of one constellation.

    Attributes
    ----------
    key : str
        Registry key, lower case (``"starlink"``); the name used by
        ``--constellation``, ``leo.constellations`` and output files.
    name_prefixes : tuple of str
        Satellite-name prefixes (upper case) that identify the family in
        element sets.
    carrier_hz : float
        Carrier of the Doppler models (central tone of the comb, if any).
    channels_hz : tuple of float
        Published channel centres.
    comb : CombModel or None
        Signal model: the pilot comb generated, estimated and replayed at
        signal level; None: a single tone, simulated at measurement level only.
    cn0_dbhz : float
        Default carrier-to-noise density of one tone [dB-Hz] (sigma model).
    integration_s : float
        Observation time of one Doppler measurement [s] (sigma model).
    mask_deg : float or None
        The family's own elevation mask [deg] (its antenna); None: the
        scenario's or command's mask.
    note : str
        Where the numbers come from.
    """

    key: str
    name_prefixes: tuple
    carrier_hz: float
    channels_hz: tuple
    comb: CombModel | None
    cn0_dbhz: float
    integration_s: float
    mask_deg: float | None
    note: str


#: Ku downlink raster: eight 240 MHz channels on 250 MHz centres from 10.7 GHz.
_KU_CHANNELS_HZ = tuple(10.7e9 + 250e6 * (k + 0.5) for k in range(8))

#: The families, by key; :func:`family_of` tries them in this order.
REGISTRY = {
    "starlink": Family(
        "starlink", ("STARLINK",), 11.325e9, _KU_CHANNELS_HZ,
        # Tone spacing: the published measurement of the comb ([Shen 2024] quotes "about 44 kHz"); N_c = 9.
        CombModel(n_tones=9, tone_spacing_hz=43_949.5), 45.0, 0.01, None,
        "Ku downlink channels 10.825-12.575 GHz on a 250 MHz raster; pilot comb at 11.325 GHz "
        "([Shen 2024] eq. 1, section 2.1)",
    ),
    "oneweb": Family(
        "oneweb", ("ONEWEB",), 11.7e9, _KU_CHANNELS_HZ, None, 45.0, 0.01, None,
        "Ku downlink 10.7-12.7 GHz; 11.7 GHz used as a nominal centre",
    ),
    "iridium": Family(
        "iridium", ("IRIDIUM",), 1626.2708e6, (1626.2708e6, 1626.1042e6, 1626.4375e6), None, 50.0, 0.02, None,
        "Iridium NEXT ring-alert channel 1626.2708 MHz (simplex band 1626.0-1626.5 MHz)",
    ),
    "orbcomm": Family(
        "orbcomm", ("ORBCOMM",), 137.5e6, (137.2e6, 137.25e6, 137.3125e6, 137.5e6, 137.6625e6, 137.7375e6, 137.8e6),
        None, 45.0, 0.1, None, "VHF subscriber downlink 137-138 MHz",
    ),
}

#: The family assumed when nothing says otherwise (a recording's comb, a file's
#: carrier, a nameless element set) and the reference of :func:`clock_scale`.
DEFAULT_FAMILY = "starlink"


def family(key, where=None):
    """The registry entry ``key``; InputError (naming ``where``, if given) when unknown."""
    if key not in REGISTRY:
        prefix = f"{where}: " if where else ""
        raise InputError(f"{prefix}unknown constellation {key!r}; expected one of {', '.join(REGISTRY)}")
    return REGISTRY[key]


def family_of(name):
    """Family key of a satellite name (``"starlink"``, ...) or ``""`` if unknown."""
    upper = name.strip().upper()
    return next((key for key, fam in REGISTRY.items() if upper.startswith(fam.name_prefixes)), "")


def carriers_hz(keys):
    """Carrier of each family key; unknown keys (``""``) get the default family's.

    Parameters
    ----------
    keys : array_like of str, (n,)

    Returns
    -------
    ndarray, (n,)
    """
    default = REGISTRY[DEFAULT_FAMILY].carrier_hz
    return np.array([REGISTRY[k].carrier_hz if k in REGISTRY else default for k in np.asarray(keys).tolist()],
                    dtype=float).reshape(np.shape(keys))


def clock_scale(key):
    """The family's carrier over the default family's: the scale of its clock-induced offsets."""
    return family(key).carrier_hz / REGISTRY[DEFAULT_FAMILY].carrier_hz


def tone_sigma_hz(cn0_dbhz, integration_s):
    """Cramér-Rao bound of a single tone's frequency [Hz] (module docstring).

    Parameters
    ----------
    cn0_dbhz, integration_s : float or array_like

    Returns
    -------
    ndarray, broadcast shape of the inputs
    """
    cn0 = 10.0 ** (np.asarray(cn0_dbhz, dtype=float) / 10.0)
    return np.sqrt(6.0 / ((2.0 * np.pi) ** 2 * cn0 * np.asarray(integration_s, dtype=float) ** 3))
