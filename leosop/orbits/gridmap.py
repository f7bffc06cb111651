"""Visible satellites and Doppler GDOP over a global latitude/longitude grid and time.

The maps of one epoch are :mod:`leosop.orbits.gridcells`'. :func:`gdop_map`
splits the epochs into tasks run by :mod:`leosop.parallel` on Dask (local
cluster, existing scheduler, or serial), optionally keeps each finished task
on disk so that an interrupted map resumes, and returns an ``xarray.Dataset``
with CF-style attributes (:mod:`leosop.orbits.gridmap_netcdf`);
:func:`write_netcdf` writes it atomically.
"""

import functools
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..parallel import shared_outputs
from ..constellations import REGISTRY, carriers_hz
from .gridcells import (FOOTPRINT_MARGIN_DEG, READABLE_GRID_DEG, Grid, brute_force_epoch, check_grid_deg, epoch_maps,
                        footprint_pairs, make_grid)
from .gridmap_netcdf import GDOP_UNITS, map_dataset, write_netcdf
from .propagate import state_ecef

#: The smallest task of a map's tail (:func:`_task_blocks`): ~0.1 s of work at 1 deg, against ~10 ms of Dask's
#: own cost per task.
_MIN_EPOCHS_PER_TASK = 2

__all__ = [
    "Grid", "make_grid", "check_grid_deg", "ConstellationSource", "satellite_carriers_hz",
    "footprint_pairs", "epoch_maps", "brute_force_epoch", "maps_for_times", "gdop_map", "write_netcdf",
    "FOOTPRINT_MARGIN_DEG", "READABLE_GRID_DEG", "GDOP_UNITS",
]

def satellite_carriers_hz(constellation):
    """Carrier of each satellite from its family; unknown families get Starlink's, (n_sats,)."""
    return carriers_hz(constellation.families)


@dataclass(frozen=True)
class ConstellationSource:
    """Where a worker gets the constellation (SGP4 records do not pickle).

    ``path`` None is the bundled Walker set; ``families`` empty keeps every satellite.
    """

    path: object = None
    families: tuple = ()
    skip_bad: bool = False

    def load(self):
        """The selected :class:`Constellation`; InputError when the selection is empty."""
        return _load_cached(self)


@functools.lru_cache(maxsize=2)
def _load_cached(source):
    from . import load_constellation

    const = load_constellation(source.path, skip_bad=source.skip_bad)
    if source.families:
        for key in source.families:
            if key not in REGISTRY:
                raise InputError(f"families {key}: unknown; expected one of {', '.join(REGISTRY)}", param="families")
        const = const.subset(np.isin(const.families, list(source.families)))
    if len(const) == 0:
        what = "/".join(source.families) if source.families else "any"
        raise InputError(f"families: no {what} satellites in {const.source or 'the TLE file'}", param="families")
    return const


def maps_for_times(constellation, times_utc, grid_deg, mask_deg):
    """Visible count and GDOP maps at the given epochs (one process).

    Parameters
    ----------
    constellation : Constellation or ConstellationSource
    times_utc : array_like of datetime64, (n_epochs,)
    grid_deg, mask_deg : float

    Returns
    -------
    n_visible : ndarray of int16, (n_epochs, n_lat, n_lon)
    gdop : ndarray of float32, (n_epochs, n_lat, n_lon)
    """
    const = constellation.load() if isinstance(constellation, ConstellationSource) else constellation
    grid = make_grid(grid_deg)
    pos, vel, _ = state_ecef(const, times_utc)
    carrier = satellite_carriers_hz(const)
    n_t = pos.shape[1]
    counts = np.empty((n_t,) + grid.shape, dtype=np.int16)
    gdops = np.empty((n_t,) + grid.shape, dtype=np.float32)
    for j in range(n_t):
        counts[j], gdops[j] = epoch_maps(pos[:, j], vel[:, j], carrier, grid, mask_deg)
    return counts, gdops


def _task(chunk, idx=None, into=None):
    """Worker entry: ``chunk = (source, times, grid_deg, mask_deg)``; the maps, or, with ``into`` (the
    :class:`~leosop.parallel.SharedArray` of the counts and of the GDOP), None once they are written there at
    epochs ``idx``."""
    source, times, grid_deg, mask_deg = chunk
    maps = maps_for_times(source, times, grid_deg, mask_deg)
    if into is None:
        return maps
    for out, values in zip(into, maps):
        out.put(idx, values)
    return None


def _epochs_per_task(n_sats, grid_deg, n_epochs, n_workers):
    """Epochs per task: bounded result size (~64 MB) and propagated states, several tasks per worker."""
    n_cells = (round(180 / grid_deg) + 1) * round(360 / grid_deg)
    by_result = max(1, (64 << 20) // (6 * n_cells))
    by_states = max(1, 2_000_000 // max(n_sats, 1))
    by_balance = max(1, -(-n_epochs // (4 * max(n_workers, 1))))
    return int(min(by_result, by_states, by_balance, 60))


def _task_blocks(todo, per, n_workers):
    """``todo``'s epoch indices cut into tasks of ``per`` epochs, the last ones shrinking so that the workers end
    together: a task takes at most the remaining epochs over twice the workers (guided self-scheduling
    [Polychronopoulos 1987]), at least ``_MIN_EPOCHS_PER_TASK``. With one worker, plain blocks of ``per``."""
    blocks, a = [], 0
    while a < len(todo):
        left = len(todo) - a
        size = per if n_workers <= 1 else min(per, max(-(-left // (2 * n_workers)), _MIN_EPOCHS_PER_TASK))
        blocks.append(todo[a:a + size])
        a += size
    return blocks


def gdop_map(source, times_utc, grid_deg, mask_deg, *, scheduler=None, n_workers=None, epochs_per_task=None,
             work_dir=None):
    """Visible count and Doppler GDOP over a global grid and time, as an ``xarray.Dataset``.

    Parameters
    ----------
    source : ConstellationSource or Constellation
        A :class:`Constellation` (SGP4 records do not pickle) only with ``scheduler="serial"``.
    times_utc : array_like of datetime64, (n_epochs,)
    grid_deg, mask_deg : float
    scheduler : None, "serial", str or distributed.Client
        As in :mod:`leosop.parallel`; an unreachable address raises ExternalError.
    n_workers : int, optional
        Workers of the local cluster (``scheduler=None``); default the cores.
    epochs_per_task : int, optional
        Every task that many epochs. Default: sized so that a task's output stays near 64 MB, the last
        tasks shrinking so that the workers end together (:func:`_task_blocks`).
    work_dir : path-like, optional
        Keep every finished task's maps there (:class:`leosop.chunkstore.ChunkStore`,
        keyed by their epochs) and take the epochs already there instead of
        computing them again: an interrupted map resumes. The caller names it
        after the satellites, grid and mask, and removes it when done.

    Returns
    -------
    xarray.Dataset
        ``n_visible(time, lat, lon)`` int16, ``gdop(time, lat, lon)`` float32.
    """
    times = np.atleast_1d(np.asarray(times_utc, dtype="datetime64[ns]"))
    grid = make_grid(grid_deg)
    const = source.load() if isinstance(source, ConstellationSource) else source
    specs = [((len(times),) + grid.shape, np.int16), ((len(times),) + grid.shape, np.float32)]
    with shared_outputs(scheduler, specs) as shared:
        (counts, gdops), into = shared or ([np.empty(shape, dtype) for shape, dtype in specs], None)
        _fill(source, const, times, grid, mask_deg, counts, gdops, scheduler=scheduler, n_workers=n_workers,
              epochs_per_task=epochs_per_task, work_dir=work_dir, into=into)
    return map_dataset(times, grid, mask_deg, counts, gdops, const)


def _fill(source, const, times, grid, mask_deg, counts, gdops, *, scheduler, n_workers, epochs_per_task, work_dir,
          into):
    """:func:`gdop_map`'s work: ``counts`` and ``gdops`` filled, by the tasks themselves when ``into`` is
    their shared handles."""
    import os

    from ..chunkstore import ChunkStore

    store = ChunkStore(work_dir) if work_dir is not None else None
    done = _resume(store, times, grid, counts, gdops) if store else np.zeros(len(times), bool)
    todo = np.flatnonzero(~done)
    workers = 1 if scheduler == "serial" else (n_workers or os.cpu_count() or 1)
    if epochs_per_task:
        blocks = _task_blocks(todo, epochs_per_task, 1)  # as asked, none shrinking
    else:
        blocks = _task_blocks(todo, _epochs_per_task(len(const), grid.step_deg, len(todo), workers), workers)

    def keep(idx, maps):
        if maps is not None:
            counts[idx], gdops[idx] = maps
        if store:
            store.save(f"epochs-{times[idx[0]].astype(np.int64)}", time_ns=times[idx].astype(np.int64),
                       n_visible=counts[idx], gdop=gdops[idx])

    if scheduler == "serial":
        from ..progress import progress

        for idx in progress(blocks, total=len(blocks), desc="gdop-map", unit="task"):
            keep(idx, maps_for_times(const, times[idx], grid.step_deg, mask_deg))
    elif blocks:
        if not isinstance(source, ConstellationSource):
            raise TypeError("a Dask run needs a ConstellationSource (SGP4 records do not pickle)")
        _run_dask(source, times, blocks, grid.step_deg, mask_deg, scheduler, n_workers, keep, into)


def _resume(store, times, grid, counts, gdops):
    """Fill ``counts`` and ``gdops`` from the chunks in ``store`` at matching epochs.

    Returns the (n_epochs,) bool of the epochs filled.
    """
    done = np.zeros(len(times), bool)
    times_ns = times.astype(np.int64)
    for name in store.names():
        data = store.load(name)
        if data is None or set(data) != {"time_ns", "n_visible", "gdop"} or data["n_visible"].shape[1:] != grid.shape:
            continue
        pos = np.searchsorted(times_ns, data["time_ns"]).clip(0, len(times) - 1)
        hit = times_ns[pos] == data["time_ns"]
        counts[pos[hit]], gdops[pos[hit]] = data["n_visible"][hit], data["gdop"][hit]
        done[pos[hit]] = True
    return done


def _run_dask(source, times, blocks, grid_deg, mask_deg, scheduler, n_workers, keep, into):
    """Run each block of epoch indices as a task; ``keep(idx, maps)`` as each finishes (``maps`` None when the
    task wrote them ``into`` the shared arrays)."""
    from ..parallel import run_tasks
    from ..progress import progress

    with progress(total=len(blocks), desc="gdop-map", unit="task") as bar:
        run_tasks(_task, (((source, times[idx], grid_deg, mask_deg), idx, into) for idx in blocks),
                  n_tasks=len(blocks),
                  scheduler=scheduler, n_workers=n_workers, on_result=lambda k, maps: keep(blocks[k], maps),
                  label=lambda k: f"the epochs from {times[blocks[k][0]]}", bar=bar)
