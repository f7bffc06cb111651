"""Write the bundled default constellation, leosop/data/starlink_walker.tle (tle/ links to it).

A Starlink-like Walker-delta constellation from the published first-generation
shell parameters (leosop.orbits.walker.STARLINK_GEN1_SHELLS) at a fixed epoch,
so that every command runs offline. Run from the repository root:

    python tools/make_walker_tle.py
"""


import numpy as np

from leosop.fileio import atomic_path
from leosop.orbits import DEFAULT_TLE
from leosop.orbits.walker import STARLINK_GEN1_SHELLS, format_tle, walker_delta

EPOCH_UTC = np.datetime64("2025-01-01T00:00:00")
OUT = DEFAULT_TLE

if __name__ == "__main__":
    const = walker_delta(STARLINK_GEN1_SHELLS, EPOCH_UTC)
    with atomic_path(OUT) as tmp:
        tmp.write_text(format_tle(const))
    print(f"{OUT}: {len(const)} satellites, epoch {EPOCH_UTC}Z")
