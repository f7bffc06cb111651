"""Screened visibility against brute-force SatrecArray propagation, in one run.

Default: the real 10,138-satellite Starlink snapshot of 2026-04-08 (from
../shared/data/tle), one site (Delft), 24 h at 1 s, 40 deg mask. Prints both
times, their ratio, and whether the visible (satellite, epoch) sets are
identical. Goal (DESIGN 6): screened >= 20x faster, identical sets.

    python tools/bench_visibility.py [--hours 24] [--mask-deg 40] [--tle FILE]
"""

import argparse
import time
from pathlib import Path

import numpy as np

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.visibility import compute_visibility

SNAPSHOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "tle" / "starlink_3le_2026-04-08_Bochika.txt"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tle", default=str(SNAPSHOT))
    parser.add_argument("--start", default="2026-04-08T00:00:00")
    parser.add_argument("--hours", type=float, default=24.0)
    parser.add_argument("--step-s", type=float, default=1.0)
    parser.add_argument("--mask-deg", type=float, default=40.0)
    parser.add_argument("--site", default="51.9989,4.3733585,95")
    args = parser.parse_args()

    const = load_constellation(args.tle)
    lat, lon, alt = (float(x) for x in args.site.split(","))
    site = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    n = int(args.hours * 3600 / args.step_s)
    times = np.datetime64(args.start, "ns") + (np.arange(n) * args.step_s * 1e9).astype("timedelta64[ns]")
    print(f"{len(const)} satellites x {n} epochs = {len(const) * n / 1e6:.0f} M satellite-epochs, "
          f"mask {args.mask_deg:g} deg, site {args.site}")

    t0 = time.perf_counter()
    fast = compute_visibility(const, times, site, args.mask_deg, screen=True)
    t_fast = time.perf_counter() - t0
    print(f"screened:    {t_fast:8.2f} s  ({len(fast.epoch_index)} visible pairs)", flush=True)
    t0 = time.perf_counter()
    slow = compute_visibility(const, times, site, args.mask_deg, screen=False)
    t_slow = time.perf_counter() - t0
    print(f"brute force: {t_slow:8.2f} s  ({len(slow.epoch_index)} visible pairs)")
    same = np.array_equal(fast.epoch_index, slow.epoch_index) and np.array_equal(fast.sat_index, slow.sat_index)
    print(f"speed-up: {t_slow / t_fast:.1f}x   identical visible sets: {same}")
    print(f"visible per epoch: min {fast.n_visible.min()}, median {np.median(fast.n_visible):g}, "
          f"max {fast.n_visible.max()}")


if __name__ == "__main__":
    main()
