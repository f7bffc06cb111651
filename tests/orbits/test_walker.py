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


def test_bundled_families_are_the_published_walker_stars():
    # Published plane spacing (Iridium: 31.6 deg, 22 deg across the seam; OneWeb: 15.225 deg,
    # 12.525 deg across the seam): the node of plane p is p times the spacing, so the
    # northbound half of the last plane and the southbound half of the first are the seam apart.
    from leosop.apps.simulate.sky import FAMILIES_TLE

    const = load_constellation(FAMILIES_TLE)
    for family, n_planes, spacing_deg, seam_deg in (("iridium", 6, 31.6, 22.0), ("oneweb", 12, 15.225, 12.525)):
        sats = [s for s, f in zip(const.satrecs, const.families) if f == family]
        nodes = np.unique(np.round(np.degrees([s.nodeo for s in sats]), 3))
        assert nodes.size == n_planes
        np.testing.assert_allclose(np.diff(nodes), spacing_deg, atol=1e-3)  # TLE prints 4 decimals
        np.testing.assert_allclose(180.0 - (nodes[-1] - nodes[0]), seam_deg, atol=1e-3)
        # Adjacent planes half a slot apart in argument of latitude (phasing F = P / 2).
        slot = 360.0 / (len(sats) // n_planes)
        u = np.degrees([s.mo + s.argpo for s in sats]).reshape(n_planes, -1)
        np.testing.assert_allclose(np.mod(u[1, 0] - u[0, 0], slot), slot / 2, atol=1e-3)
