"""Write leosop/data/leo_families_walker.tle: OneWeb, Iridium NEXT and Orbcomm as ideal Walker shells.

With the bundled Starlink-like constellation (leosop/data/starlink_walker.tle)
it is the offline sky of the multi-constellation simulations (scenario
``leo.constellations``), at the same epoch. Shell parameters, from the
operators' public descriptions, rounded:

- OneWeb first generation: 1200 km, 87.9 deg, 12 planes of 49 (588), a Walker
  star: nodes 15.225 deg apart (12.525 deg across the seam where northbound
  meets southbound planes), i.e. spread over 182.7 deg;
- Iridium NEXT: 780 km, 86.4 deg, 6 planes of 11 (66), a Walker star: nodes
  31.6 deg apart (22 deg across the seam), spread over 189.6 deg;
- Orbcomm OG2: about 750 km, 47 deg, 6 planes of 3 (18; the real 17 are in
  fewer, unevenly filled planes), a Walker delta.

The near-polar stars matter: spread over 360 deg, a plane's descending half
overlays the ascending half of the plane opposite, which halves the number
of distinct ground tracks and leaves coverage gaps (with 6 Iridium planes
over 360 deg, Xi'an went 76 min without a satellite above 15 deg).
The phasing F = P/2 offsets adjacent planes by half a slot, as the real
shells are phased; the published descriptions do not give F.

Run from the repository root:

    python tools/make_family_walker_tle.py
"""

import numpy as np

from leosop.fileio import atomic_path
from leosop.orbits.walker import Shell, format_tle, walker_delta
from leosop.apps.simulate.sky import FAMILIES_TLE

EPOCH_UTC = np.datetime64("2025-01-01T00:00:00")
FAMILIES = (
    ("ONEWEB-W", 80001, (Shell(1200e3, 87.9, 12, 49, phasing=6, node_spread_deg=12 * 15.225),)),
    ("IRIDIUM-W", 81001, (Shell(780e3, 86.4, 6, 11, phasing=3, node_spread_deg=6 * 31.6),)),
    ("ORBCOMM-W", 82001, (Shell(750e3, 47.0, 6, 3),)),
)

if __name__ == "__main__":
    text = "".join(format_tle(walker_delta(shells, EPOCH_UTC, first_id=first, name_prefix=prefix))
                   for prefix, first, shells in FAMILIES)
    with atomic_path(FAMILIES_TLE) as tmp:
        tmp.write_text(text)
    print(f"{FAMILIES_TLE}: {text.count(chr(10)) // 3} satellites, epoch {EPOCH_UTC}Z")
