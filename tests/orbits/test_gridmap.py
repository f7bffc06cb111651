"""Grid visibility and Doppler GDOP maps: footprints against brute force, grid rules."""

import math
from fractions import Fraction

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.geometry.dop import gdop
from leosop.geometry.doppler import doppler_jacobian
from leosop.kernels import compiled
from leosop.orbits import load_constellation
from leosop.orbits.gridcells import (
    _EXACT_BAND_M,
    _IU,
    _JU,
    _Q_OF,
    KERNEL_MODULE,
    _footprint_segments,
    _normal_gdop,
    _segment_pairs,
    _visible,
    _visible_segments,
    segment_batches,
)
from leosop.orbits.gridmap import (
    FOOTPRINT_MARGIN_DEG,
    READABLE_GRID_DEG,
    ConstellationSource,
    brute_force_epoch,
    check_grid_deg,
    epoch_maps,
    footprint_pairs,
    gdop_map,
    make_grid,
    satellite_carriers_hz,
    _task_blocks,
)
from leosop.orbits.propagate import state_ecef

from tests.helpers import data_path

# Cholesky of the normal matrix against the eigen-decomposition of dop.cofactor:
# both exact to rounding, conditioned geometries amplify it to ~1e-7.
GDOP_RTOL = 1e-5
START = np.datetime64("2025-01-01T00:00:00", "ns")


@pytest.fixture(scope="module")
def walker_states():
    const = load_constellation()
    times = START + np.array([0, 7, 23]) * np.timedelta64(60, "s")
    pos, vel, _ = state_ecef(const, times)
    return const, times, pos, vel, satellite_carriers_hz(const)


@pytest.mark.parametrize("grid_deg, mask_deg", [(10.0, 40.0), (6.0, 10.0)])
def test_footprints_match_brute_force(walker_states, grid_deg, mask_deg):
    _, times, pos, vel, carrier = walker_states
    grid = make_grid(grid_deg)
    for j in range(len(times)):
        n_f, g_f = epoch_maps(pos[:, j], vel[:, j], carrier, grid, mask_deg)
        n_b, g_b = brute_force_epoch(pos[:, j], vel[:, j], carrier, grid, mask_deg)
        np.testing.assert_array_equal(n_f.ravel(), n_b)
        np.testing.assert_array_equal(np.isfinite(g_f.ravel()), np.isfinite(g_b))
        np.testing.assert_allclose(g_f.ravel(), g_b, rtol=GDOP_RTOL)
        assert n_b.max() >= 7 and np.isfinite(g_b).any()
        if mask_deg >= 40:  # the sparse Walker set leaves cells without a fix
            assert np.isnan(g_b).any()


def test_footprints_match_brute_force_on_the_real_snapshot():
    """The 10,138-satellite Starlink snapshot (all its shells, polar ones included), 10 deg grid, one epoch.

    Counts identical cell by cell; GDOP to :data:`GDOP_RTOL` where both have a fix.
    """
    const = load_constellation(data_path("tle", "starlink_3le_2026-04-08_Bochika.txt"))
    pos, vel, _ = state_ecef(const, np.datetime64("2026-04-08T12:00:00", "ns"))
    carrier, grid = satellite_carriers_hz(const), make_grid(10.0)
    n_f, g_f = epoch_maps(pos[:, 0], vel[:, 0], carrier, grid, 40.0)
    n_b, g_b = brute_force_epoch(pos[:, 0], vel[:, 0], carrier, grid, 40.0)
    np.testing.assert_array_equal(n_f.ravel(), n_b)
    np.testing.assert_array_equal(np.isfinite(g_f.ravel()), np.isfinite(g_b))
    np.testing.assert_allclose(g_f.ravel(), g_b, rtol=GDOP_RTOL)
    assert n_b.max() > 20 and np.isfinite(g_b).mean() > 0.5  # a dense constellation, most cells with a fix


def test_candidates_are_a_tight_superset(walker_states):
    _, _, pos, vel, carrier = walker_states
    grid = make_grid(5.0)
    sat, cell = footprint_pairs(pos[:, 0], grid, 40.0)
    n_b, _ = brute_force_epoch(pos[:, 0], vel[:, 0], carrier, grid, 40.0)
    assert len(np.unique(sat * grid.n_cells + cell)) == len(sat)  # each pair once
    # Widening the ~5 deg cap by the margin grows it by about (1 + margin/cap)^2.
    assert n_b.sum() <= len(sat) < 2.0 * n_b.sum()


def _edge_satellites(grid, mask_deg):
    """Satellites 1000 km from cells (lat 0, 48, 84) at exactly the mask elevation, towards north and east.

    Their margins are rounding-sized, inside the band where the reference test decides.
    Returns the cells (3,) and the satellite positions (6, 3).
    """
    sin_mask, cos_mask = math.sin(math.radians(mask_deg)), math.cos(math.radians(mask_deg))
    n_lon = grid.shape[1]
    cells = [(np.searchsorted(grid.lat_deg, lat) * n_lon + n_lon // 2) for lat in (0.0, 48.0, 84.0)]
    up = grid.up_ecef[cells]
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east, axis=1, keepdims=True)
    north = np.cross(up, east)
    return cells, np.concatenate([grid.pos_ecef_m[cells] + 1e6 * (cos_mask * h + sin_mask * up) for h in (north, east)])


def test_table_elevation_test_is_the_reference_test(walker_states):
    """The map's elevation test decides every candidate pair as :func:`_visible` does, at the mask too."""
    _, _, pos, _, _ = walker_states
    grid, mask_deg = make_grid(6.0), 10.0
    sin_mask = math.sin(math.radians(mask_deg))
    n_lon = grid.shape[1]
    cells, edge = _edge_satellites(grid, mask_deg)
    pos_sv = np.concatenate([pos[:, 0], edge])
    sat, row, j0, n_cols = _footprint_segments(pos_sv, grid, mask_deg)
    seg, lon = _segment_pairs(j0, n_cols)
    vis, rng = _visible_segments(pos_sv, grid, sat, row, seg, lon, sin_mask)
    cell = row[seg] * n_lon + lon % n_lon
    ref, los, ref_rng = _visible(pos_sv[sat[seg]], grid.pos_ecef_m[cell], grid.up_ecef[cell], sin_mask)
    np.testing.assert_array_equal(vis, ref)
    np.testing.assert_allclose(rng, ref_rng, rtol=1e-12)  # same range to rounding
    margin = np.einsum("mi,mi->m", los, grid.up_ecef[cell]) - sin_mask * ref_rng
    on_edge = np.isin(sat[seg], len(pos) + np.arange(len(edge))) & np.isin(cell, cells)
    assert on_edge.sum() == len(edge) and np.all(np.abs(margin[on_edge]) < _EXACT_BAND_M)


@pytest.mark.skipif(compiled(KERNEL_MODULE) is None, reason="numba is not installed")
def test_numba_kernels_are_bit_identical_to_numpy(walker_states, monkeypatch):
    """The compiled per-pair work repeats numpy's operations in numpy's order: identical counts and GDOP bits.

    The real snapshot on a 4 deg grid in small batches (running sums over many batches, as on a fine grid), and
    the Walker set with satellites on the mask edge (pairs decided by the reference test).
    """
    monkeypatch.setattr("leosop.orbits.gridcells._BATCH_PAIRS", 3_000)
    const = load_constellation(data_path("tle", "starlink_3le_2026-04-08_Bochika.txt"))
    pos, vel, _ = state_ecef(const, np.datetime64("2026-04-08T12:00:00", "ns"))
    grid = make_grid(4.0)
    assert len(segment_batches(_footprint_segments(pos[:, 0], grid, 40.0)[3])) > 10
    cases = [(pos[:, 0], vel[:, 0], satellite_carriers_hz(const), grid, 40.0)]
    _, _, pos, vel, carrier = walker_states
    grid = make_grid(6.0)
    _, edge = _edge_satellites(grid, 10.0)
    cases.append((np.concatenate([pos[:, 0], edge]), np.concatenate([vel[:, 0], np.full(edge.shape, 7e3)]),
                  np.r_[carrier, np.full(len(edge), carrier[0])], grid, 10.0))
    for case in cases:
        n_numpy, g_numpy = epoch_maps(*case, kernel="numpy")
        n_numba, g_numba = epoch_maps(*case, kernel="numba")
        np.testing.assert_array_equal(n_numba, n_numpy)
        np.testing.assert_array_equal(g_numba, g_numpy)  # NaN where NaN, every other value to the bit
        assert np.isfinite(g_numpy).sum() > 100
    with pytest.raises(ValueError, match="kernel 'fortran'"):
        epoch_maps(*case, kernel="fortran")


def test_footprint_over_the_pole_and_dateline():
    grid = make_grid(5.0)
    # A satellite 550 km above the north pole and one above lon 180 on the equator.
    pos = np.array([[0.0, 0.0, 6_356_752.0 + 550e3], [-6_928_137.0, 0.0, 0.0]])
    vel = np.array([[7_600.0, 0.0, 0.0], [0.0, 0.0, 7_600.0]])
    carrier = np.full(2, 11.325e9)
    n_f, _ = epoch_maps(pos, vel, carrier, grid, 10.0)
    n_b, _ = brute_force_epoch(pos, vel, carrier, grid, 10.0)
    np.testing.assert_array_equal(n_f.ravel(), n_b)
    assert n_f[-1].all() and n_f[grid.shape[0] // 2, 0] == 1 and n_f[grid.shape[0] // 2, -1] == 1


def test_normal_gdop_matches_dop_and_flags_singular():
    rng = np.random.default_rng(3)
    pos = rng.normal(size=(50, 9, 3)) * 1e6 + np.array([0, 0, 7e6])
    vel = rng.normal(size=(50, 9, 3)) * 7e3
    H = doppler_jacobian(pos, vel, np.zeros((50, 3)), np.zeros((50, 3)), 11.325e9)
    normal = np.einsum("mki,mkj->mij", H, H)[:, _IU, _JU].T  # upper triangles, (28, 50)
    np.testing.assert_allclose(_normal_gdop(normal), gdop(H), rtol=1e-9)
    normal[_JU == 6, 0] = 0.0  # no clock information: singular
    assert np.isnan(_normal_gdop(normal)[0]) and np.isfinite(_normal_gdop(normal)[1:]).all()
    if compiled(KERNEL_MODULE):  # the compiled GDOP: the same bits, the same singular cell
        out = np.full(50, -1.0)
        compiled(KERNEL_MODULE).normal_gdop(normal, np.arange(50), _Q_OF, out)
        np.testing.assert_array_equal(out, _normal_gdop(normal))


@pytest.mark.parametrize("grid_deg", [1.0, 0.5, 2.5, 4.0, 7.5, 90.0])
def test_valid_grid_steps(grid_deg):
    grid = make_grid(grid_deg)
    assert grid.lat_deg[0] == -90 and grid.lat_deg[-1] == 90 and grid.lon_deg[0] == -180
    assert grid.lon_deg[-1] < 180 and math.isclose(grid.lon_deg[-1] + grid_deg, 180)


@pytest.mark.parametrize("grid_deg, message", [
    (7.0, "nearest valid: 6 or 7.2"),
    (0.7, "nearest valid: 0.6 or 0.72"),
    (89.0, "nearest valid: 60 or 90"),
    (0.11, "nearest valid: 0.1 or 0.12"),
    (0.0, "must be in (0, 90]"),
    (120.0, "must be in (0, 90]"),
])
def test_bad_grid_steps(grid_deg, message):
    with pytest.raises(InputError, match=r"^grid_deg ") as err:
        check_grid_deg(grid_deg)
    assert message in str(err.value)


def test_offered_grid_steps_are_readable_and_valid():
    """Each offered step has at most two decimals and makes the contract's grid; none is missing in between."""
    exact = {Fraction(k, 100) for k in range(10, 9_001) if Fraction(180) / Fraction(k, 100) % 1 == 0}
    assert {Fraction(str(g)) for g in READABLE_GRID_DEG} == exact
    for g in READABLE_GRID_DEG:
        assert check_grid_deg(g) == g
    for g in READABLE_GRID_DEG[READABLE_GRID_DEG >= 1.0]:  # finer grids: ~100 MB each, the rule is the same
        grid = make_grid(g)
        assert len(grid.lat_deg) == Fraction(180) / Fraction(str(g)) + 1 and math.isclose(grid.lat_deg[-1], 90.0)


def test_empty_family_selection():
    with pytest.raises(InputError, match="no oneweb satellites"):
        ConstellationSource(None, ("oneweb",)).load()


def test_dataset_layout_serial(walker_states):
    const, times, _, _, _ = walker_states
    ds = gdop_map(const, times[:2], 10.0, 40.0, scheduler="serial", epochs_per_task=1)
    assert ds["n_visible"].dims == ("time", "lat", "lon") and ds["gdop"].shape == (2, 19, 36)
    assert ds["lat"].attrs["units"] == "degrees_north" and ds["lon"].attrs["standard_name"] == "longitude"
    np.testing.assert_array_equal(ds["time"].values, times[:2])
    assert FOOTPRINT_MARGIN_DEG > 0.38  # two 0.19 deg ellipsoid effects, see the module docstring


def test_dask_matches_serial(walker_states):
    distributed = pytest.importorskip("distributed")
    const, times, _, _, _ = walker_states
    serial = gdop_map(const, times, 10.0, 40.0, scheduler="serial")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=":0") as cluster, distributed.Client(cluster) as client:
        one = gdop_map(ConstellationSource(), times, 10.0, 40.0, scheduler=client, epochs_per_task=1)
        guided = gdop_map(ConstellationSource(), times, 10.0, 40.0, scheduler=client, n_workers=2)
    for par in (one, guided):
        np.testing.assert_array_equal(par["n_visible"].values, serial["n_visible"].values)
        np.testing.assert_array_equal(par["gdop"].values, serial["gdop"].values)


def test_local_cluster_writes_the_maps_in_place(walker_states, monkeypatch):
    """``scheduler=None``: worker processes of a local cluster write their epochs into shared arrays; the maps are
    bit-identical to the serial ones and no file is left in /dev/shm."""
    import contextlib
    import os

    from leosop.orbits import gridmap

    pytest.importorskip("distributed")
    if not os.path.isdir("/dev/shm"):
        pytest.skip("no /dev/shm on this system")
    const, times, _, _, _ = walker_states
    used, shared_outputs = [], gridmap.shared_outputs

    @contextlib.contextmanager
    def spy(*args):
        with shared_outputs(*args) as shared:
            used.append(shared is not None)
            yield shared

    monkeypatch.setattr(gridmap, "shared_outputs", spy)
    monkeypatch.setattr("leosop.parallel._SHARED_HEADROOM", 0)  # a container's /dev/shm may hold 64 MB only
    before = set(os.listdir("/dev/shm"))
    serial = gdop_map(const, times, 10.0, 40.0, scheduler="serial")
    local = gdop_map(ConstellationSource(), times, 10.0, 40.0, scheduler=None, n_workers=2)
    assert used == [False, True]
    np.testing.assert_array_equal(local["n_visible"].values, serial["n_visible"].values)
    np.testing.assert_array_equal(local["gdop"].values, serial["gdop"].values)
    assert {f for f in os.listdir("/dev/shm") if f.startswith("leosop-")} <= before


def test_task_blocks_shrink_to_the_end():
    """Every epoch once, in order; full tasks first, then at most the remaining epochs over twice the workers."""
    todo = np.arange(5, 1446)
    blocks = _task_blocks(todo, 60, 2)
    np.testing.assert_array_equal(np.concatenate(blocks), todo)
    sizes = np.array([len(b) for b in blocks])
    left = len(todo) - np.concatenate([[0], np.cumsum(sizes)[:-1]])
    assert sizes.max() == 60 and np.all(np.diff(sizes) <= 0)
    np.testing.assert_array_equal(sizes, np.minimum(np.minimum(60, np.maximum(-(-left // 4), 2)), left))
    assert [len(b) for b in _task_blocks(np.arange(130), 60, 1)] == [60, 60, 10]
