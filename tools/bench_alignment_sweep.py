"""Benchmark: the vectorised alignment Monte Carlo against a per-shot loop, and Dask.

Times, in one run:
* baseline: the three alignment methods called shot by shot in a Python loop
  (one attitude, 100 shots), scaled to the default grid;
* ours, serial: the vectorised sweep of the default ``align-fig2`` grid;
* ours, Dask: the same sweep on a local cluster (includes cluster start-up).
Prints the ratios and checks that serial and Dask give identical numbers.

Usage: python tools/bench_alignment_sweep.py
"""

import time

import numpy as np

from leosop.ins.alignment import align
from leosop.apps.repro.alignment import _grid, sweep


def _per_shot_loop(n_shots, rng):
    lat = np.radians(30.0)
    f = np.array([0.0, 0.0, 9.79]) + rng.normal(0, 1e-2, (n_shots, 3))
    w = np.array([0.0, 6.3e-5, 3.6e-5]) + rng.normal(0, 5e-7, (n_shots, 3))
    for k in range(n_shots):
        for m in ("1", "2", "wahba"):
            align(f[k], w[k], lat, method=m)


def main():
    pitch, yaw, roll = _grid(False)
    n_attitudes = pitch.size * yaw.size * roll.size
    rng = np.random.default_rng(0)

    t0 = time.perf_counter()
    _per_shot_loop(100, rng)
    loop_s = (time.perf_counter() - t0) * n_attitudes

    t0 = time.perf_counter()
    serial = sweep(pitch, yaw, roll, seed=0, scheduler="serial")
    serial_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    parallel = sweep(pitch, yaw, roll, seed=0, scheduler=None)
    dask_s = time.perf_counter() - t0

    print(f"default grid: {n_attitudes} attitudes x 100 shots x 3 methods")
    print(f"per-shot loop (extrapolated): {loop_s:8.2f} s")
    print(f"vectorised, serial:           {serial_s:8.2f} s   speed-up {loop_s / serial_s:7.1f}x")
    print(f"vectorised, Dask local:       {dask_s:8.2f} s   (cluster start-up included)")
    print(f"serial == Dask: {serial == parallel}")


if __name__ == "__main__":
    main()
