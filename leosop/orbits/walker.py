"""Walker constellations (delta and star) written as SGP4 element sets.

Used to make the bundled default constellation (``tools/make_walker_tle.py``)
from the published Starlink shell parameters, so that every command runs
offline. The satellites are ideal: near-circular, no drag (B* = 0).
"""

from dataclasses import dataclass
from datetime import datetime

import numpy as np
from sgp4.api import WGS72, Satrec
from sgp4.exporter import export_tle

from ..constants import DAY_S, WGS84_A_M
from .constellation import Constellation
from .tle import satrec_epoch_utc

__all__ = ["Shell", "STARLINK_GEN1_SHELLS", "walker_delta", "format_tle"]

# WGS72 GM, the constant SGP4's elements are defined with [m^3/s^2].
_GM_WGS72 = 398_600.8e9


@dataclass(frozen=True)
class Shell:
    """One Walker shell ``inclination: total/planes/phasing``.

    Attributes
    ----------
    alt_m : float
        Altitude above the equatorial radius [m].
    incl_deg : float
    n_planes, sats_per_plane, phasing : int
        Walker P, T/P and F.
    node_spread_deg : float
        Right ascensions of the nodes are ``k * node_spread_deg / n_planes``:
        360 for a Walker delta; about 180 for a near-polar Walker star, whose
        ascending and descending halves then interleave instead of
        overlapping (Iridium, OneWeb).
    """

    alt_m: float
    incl_deg: float
    n_planes: int
    sats_per_plane: int
    phasing: int = 1
    node_spread_deg: float = 360.0


#: Starlink first-generation shells as filed with the FCC (2018 filing as
#: modified in 2020): 550 km 53.0 deg 72x22, 540 km 53.2 deg 72x22,
#: 570 km 70 deg 36x20, 560 km 97.6 deg 6x58 and 4x43. The phasing factor is
#: not published; F = 1 is used.
STARLINK_GEN1_SHELLS = (
    Shell(550e3, 53.0, 72, 22),
    Shell(540e3, 53.2, 72, 22),
    Shell(570e3, 70.0, 36, 20),
    Shell(560e3, 97.6, 6, 58),
    Shell(560e3, 97.6, 4, 43),
)


def walker_delta(shells, epoch_utc, *, first_id=70001, name_prefix="STARLINK-W", ecc=1e-4):
    """Element sets of Walker shells at a common epoch.

    Parameters
    ----------
    shells : sequence of Shell
    epoch_utc : datetime64
        Epoch of every element set (mean anomalies are phased at it).
    first_id : int
        Catalogue number of the first satellite; the rest follow.
    name_prefix : str
        Names are ``f"{name_prefix}{k:04d}"``, k from 1.
    ecc : float
        Eccentricity of every orbit.

    Returns
    -------
    Constellation
    """
    epoch = np.datetime64(epoch_utc, "us").item()
    epoch_days = (epoch - datetime(1949, 12, 31)).total_seconds() / DAY_S
    names, satrecs = [], []
    for shell in shells:
        a_m = WGS84_A_M + shell.alt_m
        no_kozai_rad_per_min = np.sqrt(_GM_WGS72 / a_m**3) * 60.0
        total = shell.n_planes * shell.sats_per_plane
        for p in range(shell.n_planes):
            raan = np.radians(shell.node_spread_deg) * p / shell.n_planes
            for s in range(shell.sats_per_plane):
                mean_anom = 2 * np.pi * (s / shell.sats_per_plane + shell.phasing * p / total)
                sat = Satrec()
                sat.sgp4init(WGS72, "i", first_id + len(satrecs), epoch_days, 0.0, 0.0, 0.0, ecc, 0.0,
                             np.radians(shell.incl_deg), np.mod(mean_anom, 2 * np.pi), no_kozai_rad_per_min, raan)
                sat.classification = "U"
                sat.intldesg = "25001A"
                names.append(f"{name_prefix}{len(satrecs) + 1:04d}")
                satrecs.append(sat)
    return Constellation(
        tuple(names),
        np.array([str(s.satnum) for s in satrecs]),
        tuple(satrecs),
        np.array([satrec_epoch_utc(s) for s in satrecs], dtype="datetime64[ns]"),
        "walker",
    )


def format_tle(constellation):
    """3-line TLE text (name, line 1, line 2) of every satellite, LF endings."""
    lines = []
    for name, sat in zip(constellation.names, constellation.satrecs):
        l1, l2 = export_tle(sat)
        lines += [name[:24], l1, l2]
    return "\n".join(lines) + "\n"
