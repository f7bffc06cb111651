"""Visible satellites per constellation and the Doppler GDOP of the mix at a high-latitude site.

Usage::

    python tools/multi_constellation_visibility.py [--tle FILE] [--site LAT,LON,ALT] [--start ISO]
        [--duration-s S] [--step-s S] [--mask-deg D]

Default: the 2021-08-06 CelesTrak "active" snapshot in ../shared/data/tle, 65 N 25 E, one hour
from 2021-08-06T12:00Z every 10 s, 25 deg mask. Prints, per family and for the mix (one receiver
clock per family, GDOP of position, velocity and clocks as eq. 10 of [Shen 2024] with the clocks
added), the visible counts and the GDOP over the epochs where the states are determined.
"""

import argparse
from pathlib import Path

import numpy as np

from leosop.constellations import REGISTRY, carriers_hz
from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.visibility import compute_visibility

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "tle"
FAMILIES = ("starlink", "oneweb", "iridium")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tle", default=str(DATA / "active_3le_2021-08-06_atqlong.txt"))
    ap.add_argument("--site", default="65,25,0")
    ap.add_argument("--start", default="2021-08-06T12:00:00")
    ap.add_argument("--duration-s", type=float, default=3600.0)
    ap.add_argument("--step-s", type=float, default=10.0)
    ap.add_argument("--mask-deg", type=float, default=25.0)
    args = ap.parse_args()
    lat, lon, alt = (float(v) for v in args.site.split(","))
    const = load_constellation(args.tle)
    const = const.subset(np.isin(const.families, FAMILIES))
    times = np.datetime64(args.start, "ns") + (np.arange(0, args.duration_s + 1e-9, args.step_s) * 1e9).astype(
        "timedelta64[ns]")
    site = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    vis = compute_visibility(const, times, site, args.mask_deg, show_progress=False)
    group = np.array([FAMILIES.index(f) for f in const.families])
    carrier = carriers_hz(const.families)
    counts = vis.n_visible_by_group(group)
    print(f"{Path(args.tle).name}: site {args.site}, {len(times)} epochs from {args.start}Z every {args.step_s:g} s, "
          f"mask {args.mask_deg:g} deg; satellites in file: "
          + ", ".join(f"{f} {int((const.families == f).sum())}" for f in FAMILIES))

    def report(name, n_vis, gdop):
        ok = np.isfinite(gdop)
        g = f"GDOP median {np.median(gdop[ok]):.1f}, 90th pct {np.percentile(gdop[ok], 90):.1f}" if ok.any() else \
            "GDOP -"
        print(f"{name:28s} visible min/median/max {n_vis.min():3d} {np.median(n_vis):5.1f} {n_vis.max():3d}   "
              f"fix possible {ok.mean():6.1%}   {g}")

    for j, fam in enumerate(FAMILIES):
        sub = compute_visibility(const.subset(group == j), times, site, args.mask_deg, show_progress=False)
        report(f"{fam} alone (7 states)", counts[:, j], sub.doppler_gdop(REGISTRY[fam].carrier_hz))
    report("mix (6 + one clock each)", vis.n_visible, vis.doppler_gdop(carrier, group))


if __name__ == "__main__":
    main()
