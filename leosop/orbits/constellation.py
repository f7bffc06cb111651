"""A set of satellites with their SGP4 elements.

A :class:`Constellation` is what the TLE and OMM readers return and what the
propagator takes. Satellites are grouped into the families of
:data:`leosop.constellations.REGISTRY` by name, so that a mixed CelesTrak
"active" snapshot can be filtered by constellation; files without names
(2-line TLEs) can be grouped by catalogue number with
:meth:`Constellation.select_ids`.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt
from sgp4.api import SatrecArray

from ..constellations import family, family_of
from ..errors import InputError

__all__ = ["Constellation"]


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

    def __len__(self) -> int:
        return len(self.satrecs)

    @cached_property
    def satrec_array(self) -> SatrecArray:
        """The vectorised propagator over all satellites."""
        return SatrecArray(list(self.satrecs))

    @cached_property
    def families(self) -> npt.NDArray[np.str_]:
        """Family key of each satellite (``""`` when unknown), ndarray of str."""
        return np.array([family_of(n) for n in self.names], dtype=object).astype(str)

    def subset(self, index: npt.NDArray[np.integer] | npt.NDArray[np.bool_] | Sequence[int] | slice
               ) -> "Constellation":
        """Satellites at ``index`` (integer array, slice or boolean mask)."""
        idx = np.arange(len(self))[index]
        return Constellation(
            tuple(self.names[i] for i in idx),
            self.sat_ids[idx],
            tuple(self.satrecs[i] for i in idx),
            self.epochs_utc[idx],
            self.source,
        )

    def index_of(self, ids: npt.ArrayLike) -> npt.NDArray[np.int_]:
        """Indices of catalogue numbers ``ids``; InputError naming unknown ones."""
        lookup = {sid: i for i, sid in enumerate(self.sat_ids)}
        ids = [str(s).strip() for s in np.atleast_1d(ids)]
        missing = [s for s in ids if s not in lookup]
        if missing:
            shown = ", ".join(missing[:5]) + (" ..." if len(missing) > 5 else "")
            raise InputError(f"{self.source or 'constellation'}: no element set for satellite id(s) {shown}")
        return np.array([lookup[s] for s in ids], dtype=int)

    def select_ids(self, ids: npt.ArrayLike) -> "Constellation":
        """Satellites with the given NORAD catalogue numbers, in that order."""
        return self.subset(self.index_of(ids))

    def family(self, key: str) -> "Constellation":
        """Satellites of one family (a key of :data:`leosop.constellations.REGISTRY`)."""
        return self.subset(self.families == family(key).key)
