"""Benchmark of ``leosop study gdop-map``: footprints against brute force, and the full run.

1. Sample check and speed-up (same run, same epochs): brute force (every
   satellite x every sampled cell) on ``--sample-cells`` random cells at
   ``--sample-epochs`` epochs, extrapolated to the full grid; the footprint
   method on the full grid at the same epochs. Counts must be identical on the
   sampled cells; GDOP agrees to the stated relative tolerance.
2. ``--floor``: the floor over the whole span, one core: one SGP4 propagation
   per satellite and epoch (sgp4's ``SatrecArray`` over all satellites and the
   epochs of each task) plus the elevation tests of the (satellite, cell) pairs
   that pass the footprint screen (the table form of the numpy path; the screen
   itself is not counted). Prints the number of pairs per epoch, and, when
   numba is installed, the same tests compiled (the floor with them apart).
3. ``--full``: the whole map (default 1 deg, 24 h at 60 s, 40 deg mask), each
   run in a child process of its own: this tree (``--scheduler``, serial by
   default) with each of ``--kernel`` (default ``numba numpy``: numba twice,
   first with an empty ``NUMBA_CACHE_DIR`` so that its JIT compilation is
   counted, then with the cache it wrote; numpy with numba blocked in the
   child, as if it were not installed), the baseline ``--baseline-ref`` (default ``main``, exported with
   ``git archive``; ``none`` skips it) the same way, and with
   ``--dask-workers 1 2`` this tree on local clusters of that many
   single-threaded workers. Each prints its wall time and CPU time (user +
   system of the child and its workers, ``os.wait4``: robust to other load on
   the machine), the ``gdop_map`` call's own wall time (``map s``: without
   the child's start, imports and the saving of its maps, ~560 MB, which
   the serial and the Dask runs pay alike; with the local cluster's start
   and its workers' imports), its CPU time over the floor's (with ``--floor``), and whether
   its counts are identical to this tree's first run and how far its GDOP is.
   ``--warm-workers 2``: a local cluster of that many workers started by this
   script beforehand and warmed on a few epochs (imports, the snapshot, the
   JIT cache loaded), its address passed as ``--scheduler``: a running
   cluster, as ``leosop study gdop-map --scheduler tcp://...`` uses one.
   ``--split 2``: the same span cut into two halves of its epochs, each a
   serial child process of this tree, both started at once (no Dask): the
   speed-up two processes of this work get on this machine at best (no
   scheduler, no result transfer), which the Dask run is judged against.

    OPENBLAS_NUM_THREADS=1 python tools/bench_gdop_map.py \
        --tle ../shared/data/tle/starlink_3le_2026-04-08_Bochika.txt [--floor] [--full] [--dask-workers 1 2]
"""

import argparse
import contextlib
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from baseline_tree import REPO, export_package

from leosop.kernels import compiled
from leosop.orbits.gridcells import (
    _EXACT_BAND_M,
    KERNEL_MODULE,
    _footprint_segments,
    _segment_tables,
    _segment_pairs,
    _visible_segments,
    segment_batches,
)
from leosop.orbits.gridmap import (
    ConstellationSource,
    brute_force_epoch,
    epoch_maps,
    make_grid,
    satellite_carriers_hz,
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
    ap.add_argument("--scheduler", default="serial",
                    help="of the --full run: serial, local (a local cluster) or a Dask address")
    ap.add_argument("--dask-workers", type=int, nargs="*", default=(),
                    help="--full also on local Dask clusters of these many workers")
    ap.add_argument("--kernel", nargs="+", choices=("numba", "numpy"), default=("numba", "numpy"),
                    help="per-pair kernels of this tree's --full runs")
    ap.add_argument("--warm-workers", type=int, nargs="*", default=(),
                    help="also run on a running local cluster of N workers, warmed beforehand")
    ap.add_argument("--split", type=int, nargs="*", default=(),
                    help="also run the span as N serial child processes at once, a 1/N of the epochs each")
    ap.add_argument("--baseline-ref", default="main", help="git ref of the code --full compares with ('none': skip)")
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
        t0 = time.process_time()
        n_b, g_b = brute_force_epoch(pos[:, j], vel[:, j], carrier, grid, a.mask_deg, cells=cells)
        t_brute += time.process_time() - t0
        t0 = time.process_time()
        n_f, g_f = epoch_maps(pos[:, j], vel[:, j], carrier, grid, a.mask_deg)
        t_fast += time.process_time() - t0
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
    print(f"brute force (every satellite x every cell), extrapolated: {brute_epoch_s:.2f} CPU s per epoch, "
          f"{brute_epoch_s * n_epochs / 3600:.1f} h for {n_epochs} epochs (one core)")
    print(f"footprints: {fast_epoch_s:.3f} CPU s per epoch, {fast_epoch_s * n_epochs / 60:.1f} min for "
          f"{n_epochs} epochs (one core)")
    print(f"speed-up: {brute_epoch_s / fast_epoch_s:.0f}x")

    floor_s = floor(const, grid, times, a.mask_deg) if a.floor else None
    if a.full:
        full_maps(a, floor_s)

def floor(const, grid, times, mask_deg):
    """CPU time of SGP4 alone over all satellites and epochs plus the elevation tests of the screened pairs [s].

    Also prints, apart, the CPU time of the scatter-adds that any per-cell normal matrix needs: one ``bincount``
    per entry of ``H^T H`` (27 besides the count) over the visible pairs.
    """
    sin_mask = math.sin(math.radians(mask_deg))
    kernels = compiled(KERNEL_MODULE)
    t_sgp4 = t_elev = t_scatter = t_compiled = 0.0
    n_pairs, n_visible = [], []
    n_lon = grid.shape[1]
    for a in range(0, len(times), EPOCHS_PER_BLOCK):
        block = times[a:a + EPOCHS_PER_BLOCK]
        jd, fr = jd_utc(block)
        t0 = time.process_time()
        const.satrec_array.sgp4(jd, fr)
        t_sgp4 += time.process_time() - t0
        pos, _, _ = state_ecef(const, block)
        for j in range(len(block)):
            sat, row, j0, n_cols = _footprint_segments(pos[:, j], grid, mask_deg)
            n_vis = 0
            for b0, b1 in segment_batches(n_cols):  # the map's batches
                seg, lon = _segment_pairs(j0[b0:b1], n_cols[b0:b1])
                t0 = time.process_time()
                vis, rng = _visible_segments(pos[:, j], grid, sat[b0:b1], row[b0:b1], seg, lon, sin_mask)
                t_elev += time.process_time() - t0
                if kernels:
                    t_compiled += compiled_elevation(kernels, pos[:, j], grid, sat[b0:b1], row[b0:b1], j0[b0:b1],
                                                     n_cols[b0:b1], sin_mask, vis)
                keep = np.flatnonzero(vis)
                cell = (row[b0:b1][seg[keep]] - row[b0]) * n_lon + lon[keep] % n_lon
                weights = rng[keep]
                t0 = time.process_time()
                for _ in range(27):
                    np.bincount(cell, weights=weights, minlength=(row[b1 - 1] - row[b0] + 1) * n_lon)
                t_scatter += time.process_time() - t0
                n_vis += len(keep)
            n_pairs.append(n_cols.sum())
            n_visible.append(n_vis)
    print(f"floor (CPU): SGP4 (SatrecArray) {t_sgp4:.1f} s for {len(const)} x {len(times)} satellite-epochs; "
          f"{np.mean(n_pairs) / 1e6:.2f} M pairs per epoch pass the footprint screen "
          f"({np.mean(n_pairs) / grid.n_cells:.1f} per cell), their elevation tests {t_elev:.1f} s; "
          f"floor {t_sgp4 + t_elev:.1f} s", flush=True)
    if kernels:
        print(f"the elevation tests compiled (numba): {t_compiled:.1f} s; floor with them {t_sgp4 + t_compiled:.1f} s",
              flush=True)
    print(f"not in the floor: the 27 scatter-adds of H^T H over the {np.mean(n_visible) / 1e6:.2f} M visible pairs "
          f"per epoch (bincount) {t_scatter:.1f} s CPU", flush=True)
    return t_sgp4 + t_elev


def compiled_elevation(kernels, pos_sv_ecef_m, grid, sat, row, j0, n_cols, sin_mask, vis_ref):
    """CPU time [s] of the compiled table elevation test of a batch of segments (its verdicts checked)."""
    n = int(n_cols.sum())
    vis, rng = np.empty(n, dtype=bool), np.empty(n)
    near_seg, near_lon = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    t0 = time.process_time()
    tables = _segment_tables(pos_sv_ecef_m, grid, sat, row)
    n_near = kernels.elevation_margins(*tables, j0, n_cols, grid.cos_lon, grid.sin_lon, sin_mask, _EXACT_BAND_M,
                                       vis, rng, near_seg, near_lon)
    cpu = time.process_time() - t0
    if n_near == 0 and not np.array_equal(vis, vis_ref):
        sys.exit("the compiled elevation test differs from numpy's")
    return cpu


# A child process's whole map: argv = tle, constellations (comma-separated), start, duration, step, grid, mask,
# scheduler ("local" for a local cluster), workers (0: the default), kernel ("numpy": numba blocked, "numba":
# required, "": the default), output .npz.
_CHILD = """
import sys
tle, fams, start, duration, step, grid, mask, scheduler, workers, kernel, out = sys.argv[1:]
if kernel == "numpy":
    sys.modules["numba"] = None  # as if numba were not installed
import numpy as np
from leosop.orbits.gridmap import ConstellationSource, gdop_map
if kernel == "numba":
    import numba  # noqa: F401 (the run is meant to use it: refuse where it is missing)
n = int(np.floor(float(duration) / float(step) + 1e-9)) + 1
times = np.datetime64(start, "ns") + (np.arange(n) * float(step) * 1e9).astype("timedelta64[ns]")
import time
t0 = time.perf_counter()
ds = gdop_map(ConstellationSource(tle, tuple(f for f in fams.split(",") if f)), times, float(grid), float(mask),
              scheduler=None if scheduler == "local" else scheduler, n_workers=int(workers) or None)
map_s = time.perf_counter() - t0
np.savez(out, n_visible=ds["n_visible"].values, gdop=ds["gdop"].values, map_s=map_s)
"""


def _part(out, k, n_split):
    """The map file of child ``k``: ``out`` itself when there is one child."""
    return str(out) if n_split == 1 else f"{out}.{k}.npz"


def run_map(code_dir, a, scheduler, n_workers, kernel, numba_cache, out, n_split=1):
    """Wall time, the ``gdop_map`` call's own wall time (the longest of the children's) and CPU time [s] of one
    whole map computed in a child process importing ``code_dir``'s leosop; with ``n_split`` > 1, in that many
    serial child processes at once, each a contiguous share of the epochs, their maps joined into ``out``."""
    env = dict(os.environ, PYTHONPATH=str(code_dir), OPENBLAS_NUM_THREADS="1", NUMBA_CACHE_DIR=str(numba_cache))
    n = int(np.floor(a.duration_s / a.step_s + 1e-9)) + 1
    edges = np.linspace(0, n, n_split + 1).round().astype(int)
    t0 = time.perf_counter()
    procs = []
    for k, (e0, e1) in enumerate(zip(edges[:-1], edges[1:])):
        start = str(np.datetime64(a.start, "ns") + np.timedelta64(int(round(e0 * a.step_s * 1e9)), "ns"))
        argv = [a.tle, ",".join(a.constellation), start, str((e1 - e0 - 1) * a.step_s), str(a.step_s),
                str(a.grid_deg), str(a.mask_deg), scheduler, str(n_workers or 0), kernel, _part(out, k, n_split)]
        procs.append(subprocess.Popen([sys.executable, "-c", _CHILD, *argv], cwd=code_dir, env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE))
    cpu = 0.0
    for proc in procs:
        stderr = proc.stderr.read()
        _, status, usage = os.wait4(proc.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            sys.exit(f"{code_dir}: the map failed: {stderr.decode().strip()[-2000:]}")
        cpu += usage.ru_utime + usage.ru_stime
    wall = time.perf_counter() - t0
    parts = [np.load(_part(out, k, n_split)) for k in range(n_split)]
    if n_split > 1:
        np.savez(out, **{key: np.concatenate([p[key] for p in parts]) for key in ("n_visible", "gdop")})
    return wall, max(float(p["map_s"]) for p in parts), cpu


@contextlib.contextmanager
def warm_cluster(a, n_workers, numba_cache):
    """The address of a local cluster of ``n_workers`` (the study's settings) warmed on 4 epochs; None for 0.

    Its workers' CPU time is not in the child's (they are not its children)."""
    if not n_workers:
        yield None
        return
    import dask
    from distributed import Client, LocalCluster

    from leosop.orbits.gridmap import gdop_map
    from leosop.parallel import _LOCAL_CLUSTER

    os.environ["NUMBA_CACHE_DIR"] = str(numba_cache)  # the workers inherit it
    with dask.config.set(_LOCAL_CLUSTER), LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=":0") as cluster, Client(cluster) as client:
        times = np.datetime64(a.start, "ns") + (np.arange(2 * n_workers) * a.step_s * 1e9).astype("timedelta64[ns]")
        gdop_map(ConstellationSource(a.tle, tuple(a.constellation)), times, a.grid_deg, a.mask_deg, scheduler=client,
                 epochs_per_task=1)
        yield cluster.scheduler_address


def full_maps(a, floor_s):
    """This tree, the baseline and the Dask runs, each in a child process; times, ratios and identical maps."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        numba_cache = tmp / "numba-cache"  # empty: the first numba run compiles
        runs = []
        for kernel in a.kernel:
            if kernel == "numba":
                runs += [(f"this tree, {a.scheduler}, numba (compiles)", REPO, a.scheduler, None, kernel),
                         (f"this tree, {a.scheduler}, numba (cached)", REPO, a.scheduler, None, kernel)]
            else:
                runs.append((f"this tree, {a.scheduler}, {kernel}", REPO, a.scheduler, None, kernel))
        if a.baseline_ref != "none":
            export_package(a.baseline_ref, tmp)
            runs.append((f"{a.baseline_ref}, serial", tmp, "serial", None, ""))
        runs += [(f"this tree, {n} local Dask worker(s)", REPO, "local", n, "") for n in a.dask_workers]
        runs += [(f"this tree, {n} warm Dask worker(s)", REPO, "warm", n, "") for n in a.warm_workers]
        runs += [(f"this tree, {n} serial processes, 1/{n} each", REPO, "serial", -n, "") for n in a.split]
        print(f"{'full map':>44} {'wall s':>7} {'map s':>7} {'CPU s':>7} {'CPU/floor':>9} | identical counts, "
              "max GDOP rel. diff (float32 maps) to the first", flush=True)
        first = best_serial = None
        for k, (label, code_dir, scheduler, n_workers, kernel) in enumerate(runs):
            split = -n_workers if n_workers and n_workers < 0 else 1
            with warm_cluster(a, n_workers if scheduler == "warm" else 0, numba_cache) as address:
                wall, map_s, cpu = run_map(code_dir, a, address or scheduler, None if split > 1 else n_workers, kernel,
                                           numba_cache, tmp / f"map{k}.npz", split)
            maps = np.load(tmp / f"map{k}.npz")
            first = first or (maps, wall)
            same = np.array_equal(maps["n_visible"], first[0]["n_visible"])
            g0, g = first[0]["gdop"].astype(float), maps["gdop"].astype(float)
            same_nan = np.array_equal(np.isnan(g), np.isnan(g0))
            rel = float(np.nanmax(np.abs(g / g0 - 1), initial=0.0)) if same_nan else math.inf
            ratio = f"{cpu / floor_s:>8.1f}x" if floor_s else f"{'-':>9}"
            cpu_note = " (the client only)" if scheduler == "warm" else ""
            bits = "bit-identical" if np.array_equal(g, g0, equal_nan=True) else f"{rel:.1e}"
            if scheduler == "serial" and split == 1 and code_dir == REPO:
                best_serial = (min(best_serial[0], wall), min(best_serial[1], map_s)) if best_serial else (wall, map_s)
            over = (f"; over this tree's fastest serial run {best_serial[0] / wall:.2f}x, the call alone "
                    f"{best_serial[1] / map_s:.2f}x" if best_serial else "")
            print(f"{label:>44} {wall:>7.1f} {map_s:>7.1f} {cpu:>7.1f} {ratio} | {same}, {bits} "
                  f"(wall speed-up over the first {first[1] / wall:.2f}x{over}){cpu_note}", flush=True)


if __name__ == "__main__":
    main()
