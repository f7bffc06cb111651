"""Constellations: element-set readers, SGP4 propagation, visibility.

``load_constellation(path)`` reads TLE (2-line or 3-line) and CelesTrak OMM
(JSON, CSV) files; without a path it returns the bundled default, a
Starlink-like Walker constellation (``leosop/data/starlink_walker.tle``, shipped
inside the package and linked from the top-level ``tle/``; epoch
2025-01-01T00:00:00Z, made by ``tools/make_walker_tle.py``).
"""

import os
from importlib.resources import files
from pathlib import Path

from .constellation import Constellation
from .omm import read_omm
from .tle import read_tle

__all__ = ["DEFAULT_TLE", "Constellation", "load_constellation", "read_tle", "read_omm"]

#: The bundled default constellation (package data, so found from any install).
DEFAULT_TLE = Path(str(files("leosop") / "data" / "starlink_walker.tle"))


def load_constellation(path: str | os.PathLike[str] | None = None, *, skip_bad: bool = False) -> Constellation:
    """Read an element-set file (TLE or OMM by suffix), or the bundled default.

    Parameters
    ----------
    path : str or Path, optional
        ``.json`` and ``.csv`` are read as OMM, anything else as TLE.
    skip_bad : bool
        Warn and skip bad TLE records instead of raising.

    Returns
    -------
    Constellation
    """
    path = Path(path) if path is not None else DEFAULT_TLE
    if path.suffix.lower() in (".json", ".csv"):
        return read_omm(path)
    return read_tle(path, skip_bad=skip_bad)
