"""Measurement models of the LEO families a simulation can mix (Starlink, OneWeb, Iridium NEXT, Orbcomm).

Starlink's Doppler is simulated at signal level (the pilot comb through the
``fast`` estimator, :mod:`leosop.simulate`); the other families are simulated
at measurement level from a documented sigma model: the Cramér-Rao bound of
the frequency of one tone of carrier-to-noise density C/N0 observed for
``integration_s`` seconds (Rife and Boorstyn's bound in its continuous-time
limit, which the estimators of :mod:`leosop.signal.fine` reach above
threshold)::

    sigma_hz = sqrt(6 / ((2 pi)^2 * C/N0 * T^3)),   C/N0 in Hz (linear)

The C/N0 and integration times below are assumptions of this toolkit, not
published receiver figures: each is the order of magnitude of what a small
omnidirectional or patch antenna sees of that family's downlink, and each can
be overridden per scenario (``leo.cn0_dbhz_by_family``):

- OneWeb (Ku, 11.7 GHz nominal): 45 dB-Hz, as Starlink's pilot, over the same
  10 ms block: 2.2 Hz (0.056 m/s).
- Iridium NEXT (L band, 1626.27 MHz ring-alert channel): bursts of about
  20 ms of unmodulated tone and BPSK frames; 50 dB-Hz over 20 ms: 0.44 Hz
  (0.081 m/s).
- Orbcomm (VHF, 137.5 MHz): a continuous 4800 bit/s downlink whose carrier
  is tracked after removing the modulation; 45 dB-Hz over 100 ms: 0.070 Hz
  (0.15 m/s).

Clock terms scale with the carrier: a satellite's or the receiver's
oscillator has one fractional frequency error, so the same error gives a
Doppler offset proportional to the carrier (:func:`carrier_ratio`).
"""

from dataclasses import dataclass

import numpy as np

from .orbits import CARRIERS

__all__ = ["FamilyModel", "FAMILY_MODELS", "tone_sigma_hz", "carrier_ratio"]


@dataclass(frozen=True)
class FamilyModel:
    """Doppler measurement model of one family.

    Attributes
    ----------
    family : str
        Key of :data:`leosop.orbits.CARRIERS`.
    cn0_dbhz : float
        Default carrier-to-noise density [dB-Hz].
    integration_s : float
        Observation time of one Doppler measurement [s].
    """

    family: str
    cn0_dbhz: float
    integration_s: float


#: Measurement models by family (Starlink's C/N0 is the scenario's ``leo.cn0_dbhz``).
FAMILY_MODELS = {
    "starlink": FamilyModel("starlink", 45.0, 0.01),
    "oneweb": FamilyModel("oneweb", 45.0, 0.01),
    "iridium": FamilyModel("iridium", 50.0, 0.02),
    "orbcomm": FamilyModel("orbcomm", 45.0, 0.1),
}


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


def carrier_ratio(family):
    """The family's default carrier over Starlink's: the scale of its clock-induced offsets."""
    return CARRIERS[family].default_hz / CARRIERS["starlink"].default_hz

