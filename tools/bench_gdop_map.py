"""Benchmark of ``leosop study gdop-map``: footprints against brute force, and the full run.

1. Sample check and speed-up (same run, same epochs): brute force (every
   satellite x every sampled cell) on ``--sample-cells`` random cells at
   ``--sample-epochs`` epochs, extrapolated to the full grid; the footprint
   method on the full grid at the same epochs. Counts must be identical on the
   sampled cells; GDOP agrees to the stated relative tolerance.
2. ``--floor``: the floor over the whole span, one core: one SGP4 propagation
   per satellite and epoch (sgp4's ``SatrecArray`` over all satellites and the
   epochs of each task) plus the elevation tests of the (satellite, cell) pairs
   that pass the footprint screen (the table form the map uses; the screen
   itself is not counted). Prints the number of pairs per epoch.
3. ``--full``: the whole map (default 1 deg, 24 h at 60 s, 40 deg mask) in one
   process (``--scheduler serial``, the default) or on a Dask scheduler;
   ``--dask-workers 1 2`` also runs it on local clusters of that many
   single-threaded workers and checks that every run's maps are identical to
   the first (SHA-256 of the arrays). Written to NetCDF in a temporary folder.

    OPENBLAS_NUM_THREADS=1 python tools/bench_gdop_map.py \
        --tle ../shared/data/tle/starlink_3le_2026-04-08_Bochika.txt [--floor] [--full] [--dask-workers 1 2]
"""

import argparse
import hashlib
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from leosop.orbits.gridcells import (
    _footprint_segments,
    _segment_pairs,
    _visible_segments,
    segment_batches,
)
from leosop.orbits.gridmap import (
    ConstellationSource,
    brute_force_epoch,
    epoch_maps,
    gdop_map,
    make_grid,
    satellite_carriers_hz,
    write_netcdf,
)
from leosop.orbits.propagate import state_ecef
from leosop.timebase import jd_utc

EPOCHS_PER_BLOCK = 60  # the map's largest task

GDOP_RTOL = 1e-5  # Cholesky on the normal matrix vs eigen-decomposition of H^T H


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tle", default="../shared/data/tle/starlink_3le_2026-04-08_Bochika.txt")
    ap.add_argument("--constellation", nargs="*", default=())
    ap.add_argument("--start", default="2026-04-08T12:00:00")
    ap.add_argument("--duration-s", type=float, default=86_400.0)
    ap.add_argument("--step-s", type=float, default=60.0)
    ap.add_argument("--grid-deg", type=float, default=1.0)
    ap.add_argument("--mask-deg", type=float, default=40.0)
    ap.add_argument("--sample-cells", type=int, default=400)
    ap.add_argument("--sample-epochs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--floor", action="store_true", help="measure the floor over the whole span")
    ap.add_argument("--full", action="store_true", help="also run the whole map")
    ap.add_argument("--scheduler", default="serial", help="of the --full run: serial, or a Dask address")
    ap.add_argument("--dask-workers", type=int, nargs="*", default=(),
                    help="--full also on local Dask clusters of these many workers")
    a = ap.parse_args()

    source = ConstellationSource(a.tle, tuple(a.constellation))
    const = source.load()
    grid = make_grid(a.grid_deg)
    n_epochs = int(np.floor(a.duration_s / a.step_s + 1e-9)) + 1
    times = np.datetime64(a.start, "ns") + (np.arange(n_epochs) * a.step_s * 1e9).astype("timedelta64[ns]")
    rng = np.random.default_rng(a.seed)
    sample_t = np.sort(rng.choice(n_epochs, a.sample_epochs, replace=False))
    cells = np.sort(rng.choice(grid.n_cells, a.sample_cells, replace=False))
    pos, vel, _ = state_ecef(const, times[sample_t])
    carrier = satellite_carriers_hz(const)
    print(f"{len(const)} satellites, {grid.shape[0]}x{grid.shape[1]} grid ({a.grid_deg:g} deg), "
          f"{n_epochs} epochs, mask {a.mask_deg:g} deg")

    t_brute = t_fast = 0.0
    same_counts, worst_rel, nan_mismatch = True, 0.0, 0
    for j in range(len(sample_t)):
        t0 = time.perf_counter()
        n_b, g_b = brute_force_epoch(pos[:, j], vel[:, j], carrier, grid, a.mask_deg, cells=cells)
        t_brute += time.perf_counter() - t0
        t0 = time.perf_counter()
        n_f, g_f = epoch_maps(pos[:, j], vel[:, j], carrier, grid, a.mask_deg)
        t_fast += time.perf_counter() - t0
        n_f, g_f = n_f.ravel()[cells], g_f.ravel()[cells]
        same_counts &= bool(np.array_equal(n_f, n_b))
        both = np.isfinite(g_b) & np.isfinite(g_f)
        nan_mismatch += int(np.sum(np.isfinite(g_b) != np.isfinite(g_f)))
        if both.any():
            worst_rel = max(worst_rel, float(np.max(np.abs(g_f[both] / g_b[both] - 1))))
    brute_epoch_s = t_brute / len(sample_t) * grid.n_cells / len(cells)
    fast_epoch_s = t_fast / len(sample_t)
    print(f"sample: {len(cells)} cells x {len(sample_t)} epochs: counts identical: {same_counts}; "
          f"GDOP NaN mismatches {nan_mismatch}, worst relative difference {worst_rel:.2e} (tolerance {GDOP_RTOL:g})")
    print(f"brute force (every satellite x every cell), extrapolated: {brute_epoch_s:.2f} s per epoch, "
          f"{brute_epoch_s * n_epochs / 3600:.1f} h for {n_epochs} epochs (one core)")
    print(f"footprints: {fast_epoch_s:.3f} s per epoch, {fast_epoch_s * n_epochs / 60:.1f} min for "
          f"{n_epochs} epochs (one core)")
    print(f"speed-up: {brute_epoch_s / fast_epoch_s:.0f}x")

    if a.floor:
        floor(const, grid, times, a.mask_deg)
    if a.full:
        runs = [(a.scheduler, None)] + [(None, n) for n in a.dask_workers]
        first = None
        for scheduler, n_workers in runs:
            label = f"{n_workers} local Dask worker(s)" if n_workers else f"scheduler {scheduler}"
            digest, t_map = full_map(source, times, a, scheduler, n_workers)
            first = first or (digest, t_map)
            print(f"full map, {label}: {t_map:.1f} s, speed-up {first[1] / t_map:.2f}x over the first run, "
                  f"maps identical to it: {digest == first[0]}")


def floor(const, grid, times, mask_deg):
    """Time of SGP4 alone over all satellites and epochs, and of the elevation tests of the screened pairs."""
    sin_mask = math.sin(math.radians(mask_deg))
    t_sgp4 = t_elev = 0.0
    n_pairs = []
    for a in range(0, len(times), EPOCHS_PER_BLOCK):
        block = times[a:a + EPOCHS_PER_BLOCK]
        jd, fr = jd_utc(block)
        t0 = time.perf_counter()
        const.satrec_array.sgp4(jd, fr)
        t_sgp4 += time.perf_counter() - t0
        pos, _, _ = state_ecef(const, block)
        for j in range(len(block)):
            sat, row, j0, n_cols = _footprint_segments(pos[:, j], grid, mask_deg)
            for b0, b1 in segment_batches(n_cols):  # the map's batches
                seg, lon = _segment_pairs(j0[b0:b1], n_cols[b0:b1])
                t0 = time.perf_counter()
                _visible_segments(pos[:, j], grid, sat[b0:b1], row[b0:b1], seg, lon, sin_mask)
                t_elev += time.perf_counter() - t0
            n_pairs.append(n_cols.sum())
    print(f"floor: SGP4 (SatrecArray) {t_sgp4:.1f} s for {len(const)} x {len(times)} satellite-epochs; "
          f"{np.mean(n_pairs) / 1e6:.2f} M pairs per epoch pass the footprint screen "
          f"({np.mean(n_pairs) / grid.n_cells:.1f} per cell), their elevation tests {t_elev:.1f} s; "
          f"floor {t_sgp4 + t_elev:.1f} s")


def full_map(source, times, a, scheduler, n_workers):
    """SHA-256 of the maps and the wall time of one whole run (NetCDF included)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        ds = gdop_map(source, times, a.grid_deg, a.mask_deg, scheduler=scheduler, n_workers=n_workers)
        write_netcdf(ds, Path(tmp) / "gdop_map.nc")
        t_all = time.perf_counter() - t0
    fix = np.isfinite(ds["gdop"].values)
    print(f"  mean visible {float(ds['n_visible'].mean()):.2f}, cell-epochs with a fix {fix.mean():.2%}")
    digest = hashlib.sha256(ds["n_visible"].values.tobytes() + ds["gdop"].values.tobytes()).hexdigest()
    return digest, t_all

if __name__ == "__main__":
    main()
