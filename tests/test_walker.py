"""The bundled Walker constellation: the published shells, and the file matches its generator."""

import numpy as np

from leosop.constants import WGS84_A_M
from leosop.orbits import DEFAULT_TLE, load_constellation
from leosop.orbits.propagate import state_teme
from leosop.orbits.walker import STARLINK_GEN1_SHELLS, format_tle, walker_delta


def test_bundled_file_is_what_the_generator_writes():
    const = walker_delta(STARLINK_GEN1_SHELLS, np.datetime64("2025-01-01T00:00:00"))
    assert DEFAULT_TLE.read_text() == format_tle(const)


def test_bundled_constellation_has_the_published_shells():
    const = load_constellation()
    sizes = [s.n_planes * s.sats_per_plane for s in STARLINK_GEN1_SHELLS]
    assert len(const) == sum(sizes) == 4408
    assert (const.families == "starlink").all()
    incl = np.degrees([s.inclo for s in const.satrecs])
    edges = np.cumsum([0, *sizes])
    r, _, _ = state_teme(const, const.epochs_utc[:1] + np.arange(0, 6000, 60).astype("timedelta64[s]"))
    radius = np.linalg.norm(r, axis=-1)
    for shell, a, b in zip(STARLINK_GEN1_SHELLS, edges[:-1], edges[1:]):
        np.testing.assert_allclose(incl[a:b], shell.incl_deg, atol=1e-4)  # TLE prints 4 decimals
        # SGP4 mean elements vs geometric radius: J2 short-period terms move
        # the radius by ~10 km around the nominal shell; e = 1e-4 adds < 1 km.
        alt_mean = radius[a:b].mean() - WGS84_A_M
        assert abs(alt_mean - shell.alt_m) < 15e3, (shell, alt_mean)
        raan = np.degrees([s.nodeo for s in const.satrecs[a:b]])
        assert len(np.unique(np.round(raan, 3))) == shell.n_planes
