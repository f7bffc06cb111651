"""A set of satellites with their SGP4 elements, and the carriers they transmit.

A :class:`Constellation` is what the TLE and OMM readers return and what the
propagator takes. Satellites are grouped into families (Starlink, OneWeb,
Iridium NEXT, Orbcomm) by name, so that a mixed CelesTrak "active" snapshot can
be filtered by constellation; files without names (2-line TLEs) can be grouped
by catalogue number with :meth:`Constellation.select_ids`.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from sgp4.api import SatrecArray

from ..constants import STARLINK_PILOT_HZ
from ..errors import InputError

__all__ = ["Carrier", "CARRIERS", "Constellation", "family_of"]


@dataclass(frozen=True)
class Carrier:
    """Downlink carrier(s) of one satellite family.

    Attributes
    ----------
    family : str
        Key of :data:`CARRIERS`.
    name_prefixes : tuple of str
        Satellite-name prefixes (upper case) that identify the family.
    default_hz : float
        Carrier used when none is given.
    channels_hz : tuple of float
        Other published channel centres.
    note : str
        Where the numbers come from.
    """

    family: str
    name_prefixes: tuple
    default_hz: float
    channels_hz: tuple
    note: str


#: Starlink Ku downlink: eight 240 MHz channels on a 250 MHz raster from
#: 10.7 GHz; the pilot comb is seen at the channel centres 11.325 and
#: 11.575 GHz ([Shen 2024]).
_STARLINK_CHANNELS_HZ = tuple(10.7e9 + 250e6 * (k + 0.5) for k in range(8))

CARRIERS = {
    "starlink": Carrier(
        "starlink", ("STARLINK",), STARLINK_PILOT_HZ, _STARLINK_CHANNELS_HZ,
        "Ku downlink channels 10.825-12.575 GHz on a 250 MHz raster; pilot at 11.325 GHz ([Shen 2024])",
    ),
    "oneweb": Carrier(
        "oneweb", ("ONEWEB",), 11.7e9, tuple(10.7e9 + 250e6 * (k + 0.5) for k in range(8)),
        "Ku downlink 10.7-12.7 GHz; 11.7 GHz used as a nominal centre",
    ),
    "iridium": Carrier(
        "iridium", ("IRIDIUM",), 1626.2708e6, (1626.2708e6, 1626.1042e6, 1626.4375e6),
        "Iridium NEXT ring-alert channel 1626.2708 MHz (simplex band 1626.0-1626.5 MHz)",
    ),
    "orbcomm": Carrier(
        "orbcomm", ("ORBCOMM",), 137.5e6, (137.2e6, 137.25e6, 137.3125e6, 137.5e6, 137.6625e6, 137.7375e6, 137.8e6),
        "VHF subscriber downlink 137-138 MHz",
    ),
}


def family_of(name):
    """Family key of a satellite name (``"starlink"``, ...) or ``""`` if unknown."""
    upper = name.strip().upper()
    for key, carrier in CARRIERS.items():
        if upper.startswith(carrier.name_prefixes):
            return key
    return ""


@dataclass(frozen=True, eq=False)
class Constellation:
    """Satellites with SGP4 elements.

    Attributes
    ----------
    names : tuple of str, (n_sats,)
        Names from 3-line files or OMM; empty strings for 2-line files.
    sat_ids : ndarray of str, (n_sats,)
        NORAD catalogue numbers as strings.
    satrecs : tuple of sgp4.api.Satrec, (n_sats,)
    epochs_utc : ndarray of datetime64[ns], (n_sats,)
        Element-set epochs.
    source : str
        File the elements came from, for messages.
    """

    names: tuple
    sat_ids: np.ndarray
    satrecs: tuple
    epochs_utc: np.ndarray
    source: str = ""

    def __len__(self):
        return len(self.satrecs)

    @cached_property
    def satrec_array(self):
        """The vectorised propagator over all satellites."""
        return SatrecArray(list(self.satrecs))

    @cached_property
    def families(self):
        """Family key of each satellite (``""`` when unknown), ndarray of str."""
        return np.array([family_of(n) for n in self.names], dtype=object).astype(str)

    def subset(self, index):
        """Satellites at ``index`` (integer array, slice or boolean mask)."""
        idx = np.arange(len(self))[index]
        return Constellation(
            tuple(self.names[i] for i in idx),
            self.sat_ids[idx],
            tuple(self.satrecs[i] for i in idx),
            self.epochs_utc[idx],
            self.source,
        )

    def index_of(self, ids):
        """Indices of catalogue numbers ``ids``; InputError naming unknown ones."""
        lookup = {sid: i for i, sid in enumerate(self.sat_ids)}
        ids = [str(s).strip() for s in np.atleast_1d(ids)]
        missing = [s for s in ids if s not in lookup]
        if missing:
            shown = ", ".join(missing[:5]) + (" ..." if len(missing) > 5 else "")
            raise InputError(f"{self.source or 'constellation'}: no element set for satellite id(s) {shown}")
        return np.array([lookup[s] for s in ids], dtype=int)

    def select_ids(self, ids):
        """Satellites with the given NORAD catalogue numbers, in that order."""
        return self.subset(self.index_of(ids))

    def family(self, key):
        """Satellites of one family (a key of :data:`CARRIERS`)."""
        if key not in CARRIERS:
            raise InputError(f"unknown constellation {key!r}; expected one of {', '.join(CARRIERS)}")
        return self.subset(self.families == key)
