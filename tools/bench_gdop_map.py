"""Benchmark of ``leosop study gdop-map``: footprints against brute force, and the full run.

1. Sample check and speed-up (same run, same epochs): brute force (every
   satellite x every sampled cell) on ``--sample-cells`` random cells at
   ``--sample-epochs`` epochs, extrapolated to the full grid; the footprint
   method on the full grid at the same epochs. Counts must be identical on the
   sampled cells; GDOP agrees to the stated relative tolerance.
2. ``--full``: the whole map (default 1 deg, 24 h at 60 s, 40 deg mask) through
   the Dask local cluster, wall time, written to NetCDF in a temporary folder.

    OPENBLAS_NUM_THREADS=1 python tools/bench_gdop_map.py \
        --tle ../shared/data/tle/starlink_3le_2026-04-08_Bochika.txt [--full]
"""

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from leosop.orbits.gridmap import (
    ConstellationSource, brute_force_epoch, epoch_maps, gdop_map, make_grid, satellite_carriers_hz, write_netcdf,
)
from leosop.orbits.propagate import state_ecef

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
    ap.add_argument("--full", action="store_true", help="also run the whole map on a local Dask cluster")
    ap.add_argument("--scheduler", default=None)
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

    if a.full:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            ds = gdop_map(source, times, a.grid_deg, a.mask_deg, scheduler=a.scheduler)
            t_map = time.perf_counter() - t0
            write_netcdf(ds, Path(tmp) / "gdop_map.nc")
            t_all = time.perf_counter() - t0
            size = (Path(tmp) / "gdop_map.nc").stat().st_size
        fix = np.isfinite(ds["gdop"].values)
        print(f"full map: {t_map:.0f} s computing, {t_all:.0f} s with the NetCDF ({size / 1e6:.0f} MB); "
              f"mean visible {float(ds['n_visible'].mean()):.1f}, cell-epochs with a fix {fix.mean():.1%}")


if __name__ == "__main__":
    main()
