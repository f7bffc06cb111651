"""Write leosop/data/leo_families_walker.tle: OneWeb, Iridium NEXT and Orbcomm as ideal Walker shells.

With the bundled Starlink-like constellation (leosop/data/starlink_walker.tle)
it is the offline sky of the multi-constellation simulations (scenario
``leo.constellations``), at the same epoch. Shell parameters, from the
operators' public filings, rounded:

- OneWeb first generation: 1200 km, 87.9 deg, 12 planes of 49 (588);
- Iridium NEXT: 780 km, 86.4 deg, 6 planes of 11 (66); the real constellation
  spreads its planes over 180 deg of node (a Walker star), here over 360 deg;
- Orbcomm OG2: about 750 km, 47 deg, 6 planes of 3 (18; the real 17 are in
  fewer, unevenly filled planes).

Run from the repository root:

    python tools/make_family_walker_tle.py
"""

import numpy as np

from leosop.fileio import atomic_path
from leosop.orbits.walker import Shell, format_tle, walker_delta
from leosop.simulate import FAMILIES_TLE

EPOCH_UTC = np.datetime64("2025-01-01T00:00:00")
FAMILIES = (
    ("ONEWEB-W", 80001, (Shell(1200e3, 87.9, 12, 49),)),
    ("IRIDIUM-W", 81001, (Shell(780e3, 86.4, 6, 11),)),
    ("ORBCOMM-W", 82001, (Shell(750e3, 47.0, 6, 3),)),
)

if __name__ == "__main__":
    text = "".join(format_tle(walker_delta(shells, EPOCH_UTC, first_id=first, name_prefix=prefix))
                   for prefix, first, shells in FAMILIES)
    with atomic_path(FAMILIES_TLE) as tmp:
        tmp.write_text(text)
    print(f"{FAMILIES_TLE}: {text.count(chr(10)) // 3} satellites, epoch {EPOCH_UTC}Z")
