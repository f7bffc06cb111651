"""Search the start time of the bundled xian-baoji scenario (issue 6).

[Shen 2024]'s Fig. 9 shows 7 or more visible Starlink satellites for nearly the
whole 782 s flight and a short thin stretch around 402-431 s. This script
scans start times every 60 s over the day of the bundled TLE epoch, counts
the satellites above the 40 deg mask at 1 Hz along the flight, and prints
the best-matching starts: 7 or more satellites everywhere outside a mid-flight
window, and 10-40 s below 7 inside it.

Usage: python tools/search_start_time.py [--tle FILE] [--day ISO_DATE]
"""

import argparse

import numpy as np

from leosop.frames import azimuth_elevation_range, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef
from leosop.apps.scenarios import XIAN_BAOJI


def flight_ecef_m(scenario, n_epochs):
    """Receiver ECEF positions at 1 Hz, straight in lat/lon between the two waypoints (n_epochs, 3)."""
    (lat0, lon0, alt0), (lat1, lon1, alt1) = scenario.waypoints[:2]
    f = np.arange(n_epochs) / (n_epochs - 1)
    return geodetic_to_ecef(np.radians(lat0 + f * (lat1 - lat0)), np.radians(lon0 + f * (lon1 - lon0)),
                            alt0 + f * (alt1 - alt0))


def counts_for_hour(constellation, hour_start, rx_ecef_m, mask_deg):
    """Visible counts (60, n_epochs) for starts every 60 s in one hour."""
    n_epochs = len(rx_ecef_m)
    mid = rx_ecef_m[n_epochs // 2]
    coarse = hour_start + np.arange(0, 3600 + n_epochs + 30, 30).astype("timedelta64[s]")
    pos, _, _ = state_ecef(constellation, coarse)
    _, el, _ = azimuth_elevation_range(pos, mid)
    # A pass above 40 deg lasts minutes; 30 s sampling at a 15 deg threshold misses none.
    near = np.flatnonzero(np.nanmax(np.degrees(el), axis=1) > mask_deg - 25)
    fine = hour_start + np.arange(0, 3600 + n_epochs).astype("timedelta64[s]")
    pos, _, _ = state_ecef(constellation.subset(near), fine)
    counts = np.empty((60, n_epochs), dtype=int)
    for m in range(60):
        sv = pos[:, 60 * m: 60 * m + n_epochs]
        _, el, _ = azimuth_elevation_range(sv, rx_ecef_m)
        counts[m] = (np.degrees(el) > mask_deg).sum(axis=0)
    return counts


def score(n, window=(380, 460)):
    """(ok, outside fraction >= 7, seconds below 7 in the window)."""
    k = np.arange(len(n))
    inside = (k >= window[0]) & (k < window[1])
    low_inside = int((n[inside] < 7).sum())
    frac_out = float((n[~inside] >= 7).mean())
    return frac_out, low_inside


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tle")
    parser.add_argument("--day", default="2025-01-01")
    args = parser.parse_args()
    constellation = load_constellation(args.tle)
    scenario = XIAN_BAOJI
    rx = flight_ecef_m(scenario, int(scenario.duration_s))
    day = np.datetime64(args.day, "ns")
    rows = []
    for hour in range(24):
        start = day + np.timedelta64(hour, "h")
        counts = counts_for_hour(constellation, start, rx, scenario.mask_deg)
        for m in range(60):
            frac_out, low_inside = score(counts[m])
            rows.append((frac_out, low_inside, start + np.timedelta64(60 * m, "s"), counts[m]))
    good = [r for r in rows if 10 <= r[1] <= 40]
    good.sort(key=lambda r: (-r[0], abs(r[1] - 30)))
    print("start_utc                       frac>=7 outside  s<7 inside  min  mean")
    for frac_out, low_inside, start, n in good[:15]:
        print(f"{np.datetime_as_string(start, unit='s')}Z  {frac_out:14.3f}  {low_inside:10d}  "
              f"{n.min():3d}  {n.mean():5.2f}")


if __name__ == "__main__":
    main()
