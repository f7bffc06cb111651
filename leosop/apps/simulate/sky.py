"""Who transmits and who is tracked: the satellites of a scenario's families, their models and the tracked pairs.

:func:`transmitters` picks the satellites of ``leo.constellations`` from an
element-set file or the bundled sky, :func:`family_models` gives each family
its carrier, clock and signal models, and :func:`above_family_masks` and
:func:`tracked` keep the visible pairs the receiver tracks.
"""

import dataclasses
from importlib.resources import files
from pathlib import Path

import numpy as np

from ...constellations import DEFAULT_FAMILY, clock_scale, family, tone_sigma_hz
from ...errors import InputError
from ...orbits import Constellation, load_constellation
from ...orbits.propagate import drop_failing
from ...signal.pilot import PilotComb

__all__ = ["FAMILIES_TLE", "above_family_masks", "family_models", "tracked", "transmitters"]

#: The bundled sky of the other families (OneWeb, Iridium NEXT, Orbcomm Walker
#: shells at the bundled Starlink set's epoch; tools/make_family_walker_tle.py).
FAMILIES_TLE = Path(str(files("leosop") / "data" / "leo_families_walker.tle"))


def transmitters(families, tle, span_utc):
    """The transmitting satellites of ``families`` and each one's family index, (n_sats,) int.

    Without ``tle``: the bundled Starlink-like set, plus the bundled sky of
    the other families (:data:`FAMILIES_TLE`) when they are asked for. A file
    without names (2-line TLEs) is taken whole as Starlink when only Starlink
    is asked for. Satellites SGP4 cannot propagate over ``span_utc`` (first
    and last epoch; decayed) are left out with a warning
    (:func:`leosop.orbits.propagate.drop_failing`).

    Raises
    ------
    InputError
        Naming a requested family of which the file holds no satellite.
    """
    if tle is None:
        needs_families = bool(set(families) - {DEFAULT_FAMILY})
        parts = [load_constellation()] + ([load_constellation(FAMILIES_TLE)] if needs_families else [])
        every = Constellation(sum((c.names for c in parts), ()), np.concatenate([c.sat_ids for c in parts]),
                              sum((c.satrecs for c in parts), ()), np.concatenate([c.epochs_utc for c in parts]),
                              "bundled sky")
    else:
        every = load_constellation(tle)
    if tuple(families) == (DEFAULT_FAMILY,) and not (every.families != "").any():
        every = drop_failing(every, span_utc, what="the flight")
        return every, np.zeros(len(every), int)
    every = drop_failing(every.subset(np.isin(every.families, families)), span_utc, what="the flight")
    index = [np.flatnonzero(every.families == f) for f in families]
    for f, idx in zip(families, index):
        if idx.size == 0:
            raise InputError(f"{every.source or tle}: no satellite of constellation {f!r} (leo.constellations)")
    return every.subset(np.concatenate(index)), np.repeat(np.arange(len(families)), [i.size for i in index])


def family_models(leo):
    """Per family of ``leo.constellations``: carrier, clock scale, receiver offset, sigma and signal models.

    Returns
    -------
    dict
        ``carrier_hz``, ``clock_scale``, ``rx_offset_hz``, ``sigma_hz`` (the
        single-tone sigma model): ndarray (k,); ``comb``: tuple (k,) of each
        family's :class:`~leosop.signal.pilot.PilotComb`, None for a family
        without one. A comb family's C/N0 is the scenario's ``leo.cn0_dbhz``.
    """
    fams = [family(f) for f in leo.constellations]
    cn0 = [leo.cn0_dbhz if f.comb is not None else leo.cn0_dbhz_by_family.get(f.key, f.cn0_dbhz) for f in fams]
    scale = np.array([clock_scale(f.key) for f in fams])
    return {
        "carrier_hz": np.array([f.carrier_hz for f in fams]),
        "clock_scale": scale,
        "rx_offset_hz": np.array([leo.rx_freq_offsets_hz.get(f.key, leo.rx_freq_offset_hz * r)
                                  for f, r in zip(fams, scale)]),
        "sigma_hz": tone_sigma_hz(cn0, [f.integration_s for f in fams]),
        "comb": tuple(None if f.comb is None else PilotComb.of(f.key) for f in fams),
    }


def _keep_pairs(vis, keep):
    """The pairs of ``vis`` where ``keep`` (m,) is true."""
    return dataclasses.replace(vis, **{f: getattr(vis, f)[keep] for f in (
        "epoch_index", "sat_index", "az_rad", "elev_rad", "range_m", "pos_sv_ecef_m", "vel_sv_ecef_mps")})


def above_family_masks(vis, family_sat, masks_deg):
    """The pairs above their family's mask, from pairs found above the lowest mask.

    Parameters
    ----------
    vis : Visibility
        Found with the mask ``masks_deg.min()``.
    family_sat : ndarray of int, (n_sats,)
    masks_deg : ndarray, (k,)
        Each family's mask. The pairs of the families at the lowest mask are
        kept as found (one mask: ``vis`` itself).
    """
    mask_pair_deg = masks_deg[family_sat[vis.sat_index]]
    keep = (mask_pair_deg == masks_deg.min()) | (vis.elev_rad >= np.radians(mask_pair_deg))
    return vis if keep.all() else _keep_pairs(vis, keep)


def tracked(vis, t_s, outage_s, max_sats):
    """The visible pairs the receiver tracks: all, except in the outage ``[start, end]`` the ``max_sats`` highest."""
    if outage_s is None:
        return vis
    order = np.lexsort((-vis.elev_rad, vis.epoch_index))
    rank = np.empty(order.size, int)
    rank[order] = np.arange(order.size) - np.searchsorted(vis.epoch_index[order], vis.epoch_index[order])
    t = t_s[vis.epoch_index]
    keep = (t < outage_s[0]) | (t > outage_s[1]) | (rank < max_sats)
    return _keep_pairs(vis, keep)

