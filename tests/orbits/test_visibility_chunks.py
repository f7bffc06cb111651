"""Chunked visibility (leosop.orbits.chunks) against the whole-span computation, pair for pair."""

import numpy as np
import pytest

from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.chunks import PassStitcher, visibility_chunks
from leosop.orbits.visibility import compute_visibility
from leosop.timebase import utc_from_seconds

START = np.datetime64("2025-01-01T00:20:00", "ns")  # the bundled Walker set's epoch + 20 min
STEP_S = 10.0
N_EPOCHS = 721  # two hours, both ends
SITE = geodetic_to_ecef(np.radians(34.342), np.radians(108.940), 400.0)


@pytest.fixture(scope="module")
def whole():
    const = load_constellation().subset(slice(0, None, 8))
    times = utc_from_seconds(np.arange(N_EPOCHS) * STEP_S, START)
    return const, compute_visibility(const, times, SITE, 15.0, show_progress=False)


# Chunks of 5 epochs (the longer passes rise in one chunk and set several later), 37 (not a whole number of
# 60 s screening steps) and 360 (two chunks and a one-epoch tail): each must give the whole span's result.
@pytest.mark.parametrize("chunk_epochs", [5, 37, 360])
def test_chunks_give_the_whole_span_result(whole, chunk_epochs):
    const, vis = whole
    stitcher = PassStitcher(const.sat_ids, N_EPOCHS)
    sat, ep, elev, gdop, passes = [], [], [], [], []
    for a, chunk in visibility_chunks(const, START, STEP_S, N_EPOCHS, SITE, 15.0, chunk_epochs=chunk_epochs,
                                      show_progress=False):
        np.testing.assert_array_equal(chunk.times_utc, vis.times_utc[a:a + len(chunk.times_utc)])
        sat.append(chunk.sat_index)
        ep.append(chunk.epoch_index + a)
        elev.append(chunk.elev_rad)
        gdop.append(chunk.doppler_gdop(11.325e9))
        passes += stitcher.add(a, chunk)
    passes += stitcher.finish()
    np.testing.assert_array_equal(np.concatenate(ep), vis.epoch_index)
    np.testing.assert_array_equal(np.concatenate(sat), vis.sat_index)
    np.testing.assert_array_equal(np.concatenate(elev), vis.elev_rad)
    # Each epoch's GDOP is computed from its own satellites only, but the padded width (the chunk's most
    # visible) changes the order of the sums in the products: equal to a few ulp, not bit for bit.
    np.testing.assert_allclose(np.concatenate(gdop), vis.doppler_gdop(11.325e9), rtol=1e-12)
    expected = vis.passes()
    assert len(expected) > 50 and any(p.truncated for p in expected)
    longest = max(p.set_utc - p.rise_utc for p in expected) / np.timedelta64(1, "s")
    assert longest > 3 * 5 * STEP_S  # spans several 5-epoch chunks
    assert passes == expected and stitcher.n_passes == len(expected)

