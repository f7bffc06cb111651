"""Benchmark: a 10-minute snapshot recording (20 ms every 1 s, 2.5 MS/s, 7 satellites).

Times ``leosop generate``'s channel path (geometry, then samples snapshot by
snapshot) beside the baseline of synthesising the whole continuous stream and
keeping only the snapshots, both in this run, on the first 60 s of the
baseline (scaled to 600 s) so that the run stays short; prints the ratio.

    python tools/bench_generate.py
"""

import time

import numpy as np

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.signal.channel import SiteChannel, cn0_geometry_dbhz, site_geometry

FS = 2.5e6
SNAP, PERIOD, DURATION = 0.02, 1.0, 600.0
IDS = ["70002", "70524", "70546", "71563", "71585", "71607", "72129"]


def channel(duration_s):
    const = load_constellation().select_ids(IDS)
    xian = geodetic_to_ecef(np.radians(34.342), np.radians(108.940), 400.0)
    start = np.datetime64("2025-01-01T19:40:00", "ns")
    t_nodes, range_m, elev = site_geometry(const, xian, start, duration_s)
    return SiteChannel(t_nodes, range_m, FS, cn0_geometry_dbhz(45.0, range_m, elev), 5.0)


def snapshots(duration_s, rng):
    ch = channel(duration_s)
    n_snap = int(SNAP * FS)
    for k in range(int(duration_s / PERIOD)):
        ch.samples(int(k * PERIOD * FS), n_snap, rng).astype(np.complex64)


def continuous_then_cut(duration_s, rng, chunk=1 << 18):
    ch = channel(duration_s)
    for start in range(0, int(duration_s * FS), chunk):
        ch.samples(start, chunk, rng).astype(np.complex64)


def main():
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    snapshots(DURATION, rng)
    t_snap = time.perf_counter() - t0
    base_s = 60.0
    t0 = time.perf_counter()
    continuous_then_cut(base_s, rng)
    t_cont = (time.perf_counter() - t0) * DURATION / base_s
    print(f"10-min snapshot recording ({SNAP * 1e3:g} ms every {PERIOD:g} s, {FS:g} S/s, {len(IDS)} sats): "
          f"{t_snap:.2f} s")
    print(f"baseline, continuous stream then cut (60 s measured, x10): {t_cont:.1f} s")
    print(f"ratio baseline / snapshot: {t_cont / t_snap:.0f}x")


if __name__ == "__main__":
    main()
