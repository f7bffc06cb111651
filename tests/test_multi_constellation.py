"""Several constellations in one Doppler fix: one receiver clock per constellation (DESIGN 4.3)."""

import numpy as np
import pytest

from leosop.constants import C_MPS
from leosop.frames import C_e_n, geodetic_to_ecef
from leosop.positioning.doppler_ls import FixStatus, solve_snapshots, solve_static, solve_static_passes

#: Noise-free recovery: the solver stops on steps below 0.1 mm; 1 mm leaves room for the last step.
ONE_MM = 1e-3
#: Velocity: 1 um/s steps, 1e-4 m/s bound.
VEL_TOL_MPS = 1e-4
#: Clock offsets: 10 uHz steps, 1e-4 Hz bound.
CLOCK_TOL_HZ = 1e-4
#: Start 1,000 km off the truth (the brief's convergence requirement).
START_OFFSET_M = 1.0e6

SITE_LLA = (np.radians(65.0), np.radians(25.0), 100.0)
#: (carrier [Hz], orbit height [m], receiver clock offset [Hz]) of the synthetic families.
FAMILIES = {0: (11.325e9, 550e3, 1234.5), 1: (11.7e9, 1200e3, -3210.0), 2: (1626.2708e6, 780e3, 42.0)}


def _sky(rng, n_sv, height_m, pos_rx):
    """Satellites above 20 deg elevation at ``height_m`` with circular-orbit speed in random directions."""
    lat, lon, _ = SITE_LLA
    C = C_e_n(lat, lon)
    az = rng.uniform(0, 2 * np.pi, n_sv)
    el = rng.uniform(np.radians(20), np.radians(88), n_sv)
    u_n = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)
    u_e = u_n @ C.T
    # Distance along the line of sight to the sphere of radius R + h.
    radius = np.linalg.norm(pos_rx) + height_m
    b = u_e @ pos_rx
    rho = -b + np.sqrt(b**2 - (pos_rx @ pos_rx - radius**2))
    r_s = pos_rx + rho[:, None] * u_e
    speed = np.sqrt(3.986004418e14 / radius)
    d = rng.normal(size=(n_sv, 3))
    d -= np.sum(d * r_s, -1, keepdims=True) * r_s / radius**2
    v_s = speed * d / np.linalg.norm(d, axis=-1, keepdims=True)
    return r_s, v_s


def _doppler(r_s, v_s, pos_rx, vel_rx, f0, clock_hz):
    dr = r_s - pos_rx
    rate = np.sum((v_s - vel_rx) * dr, -1) / np.linalg.norm(dr, axis=-1)
    return -rate * f0 / C_MPS + clock_hz


def _snapshot_set(seed, counts, vel_rx=(30.0, -20.0, 5.0)):
    """One epoch's rows: ``counts[g]`` satellites of family g."""
    rng = np.random.default_rng(seed)
    pos_rx = geodetic_to_ecef(*SITE_LLA)
    vel_rx = np.asarray(vel_rx, float)
    r, v, f0, clk, grp = [], [], [], [], []
    for g, n in counts.items():
        carrier, height, offset = FAMILIES[g]
        rs, vs = _sky(rng, n, height, pos_rx)
        r.append(rs), v.append(vs), f0.append(np.full(n, carrier)), clk.append(np.full(n, offset))
        grp.append(np.full(n, g))
    r, v, f0, clk, grp = (np.concatenate(a) for a in (r, v, f0, clk, grp))
    y = _doppler(r, v, pos_rx, vel_rx, f0, clk)
    return y, r, v, f0, grp, pos_rx, vel_rx


def _start(pos_rx):
    """A ground point 1,000 km east of the truth."""
    lat, lon, _ = SITE_LLA
    east = C_e_n(lat, lon)[:, 0]
    return pos_rx + START_OFFSET_M * east


def test_snapshot_two_constellations_recovers_state_and_each_clock():
    y, r, v, f0, grp, pos_rx, vel_rx = _snapshot_set(1, {0: 6, 1: 5})
    x0 = np.zeros(7)
    x0[:3] = _start(pos_rx)
    fx = solve_snapshots(y[None], 1.0, r[None], v[None], f0[None], x0=x0, clock_group=grp[None], alpha=None)
    assert fx.status[0] == FixStatus.OK
    assert np.linalg.norm(fx.pos_ecef_m[0] - pos_rx) < ONE_MM
    assert np.linalg.norm(fx.vel_ecef_mps[0] - vel_rx) < VEL_TOL_MPS
    np.testing.assert_allclose(fx.clock_offsets_hz[0], [FAMILIES[0][2], FAMILIES[1][2]], atol=CLOCK_TOL_HZ)
    assert fx.clock_labels == (0, 1)
    assert fx.cov.shape == (1, 8, 8) and np.isfinite(fx.gdop[0])


def test_snapshot_three_constellations_and_a_missing_one_per_epoch():
    """Epoch 0 sees all three families, epoch 1 only two: 9 and 8 states, the absent clock is NaN."""
    y0, r0, v0, f0_0, g0, pos_rx, vel_rx = _snapshot_set(2, {0: 5, 1: 3, 2: 3})
    y1, r1, v1, f0_1, g1, _, _ = _snapshot_set(3, {0: 5, 2: 4})
    pad = lambda a, k: np.concatenate([a, np.full((k,) + a.shape[1:], np.nan)])  # noqa: E731
    k = len(y0) - len(y1)
    Y, R, V, F = np.stack([y0, pad(y1, k)]), np.stack([r0, pad(r1, k)]), np.stack([v0, pad(v1, k)]), \
        np.stack([f0_0, pad(f0_1, k)])
    G = np.stack([g0, np.concatenate([g1, np.zeros(k, int)])])
    x0 = np.zeros(7)
    x0[:3] = _start(pos_rx)
    fx = solve_snapshots(Y, 1.0, R, V, F, x0=x0, clock_group=G, alpha=None)
    assert (fx.status == FixStatus.OK).all()
    assert np.linalg.norm(fx.pos_ecef_m - pos_rx, axis=-1).max() < ONE_MM
    np.testing.assert_allclose(fx.clock_offsets_hz[0], [FAMILIES[g][2] for g in (0, 1, 2)], atol=CLOCK_TOL_HZ)
    np.testing.assert_allclose(fx.clock_offsets_hz[1, [0, 2]], [FAMILIES[0][2], FAMILIES[2][2]], atol=CLOCK_TOL_HZ)
    assert np.isnan(fx.clock_offsets_hz[1, 1]) and np.isnan(fx.cov[1, 7]).all()
    assert fx.n_used.tolist() == [11, 9]


def test_snapshot_rank_rule_six_plus_clocks():
    """Two clocks need 8 measurements: 7 are refused (TOO_FEW), 8 solve."""
    y, r, v, f0, grp, pos_rx, _ = _snapshot_set(4, {0: 4, 1: 4})
    mask = np.ones((2, 8), bool)
    mask[0, 7] = False
    fx = solve_snapshots(np.stack([y, y]), 1.0, np.stack([r, r]), np.stack([v, v]), np.stack([f0, f0]), mask,
                         clock_group=np.stack([grp, grp]), alpha=None)
    assert fx.status[0] == FixStatus.TOO_FEW and np.isnan(fx.pos_ecef_m[0]).all()
    assert fx.status[1] == FixStatus.OK


def test_snapshot_one_group_is_bit_identical_to_no_groups():
    rng = np.random.default_rng(5)
    y, r, v, f0, _, pos_rx, _ = _snapshot_set(5, {0: 9})
    y = y + rng.normal(0, 0.5, y.shape)
    a = solve_snapshots(y[None], 0.5, r[None], v[None], f0[None])
    b = solve_snapshots(y[None], 0.5, r[None], v[None], f0[None], clock_group=np.full((1, 9), 3))
    for name in ("pos_ecef_m", "vel_ecef_mps", "clock_offset_hz", "cov", "gdop", "residuals_hz", "chi2"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert b.clock_labels == (3,)


def _static_set(seed, counts, n_ep=40, step_s=15.0):
    """A receiver at rest; satellites on straight lines (a synthetic motion, consistent with the given states)."""
    y, r, v, f0, grp, pos_rx, _ = _snapshot_set(seed, counts, vel_rx=(0.0, 0.0, 0.0))
    t = np.arange(n_ep) * step_s
    R = r[None] + t[:, None, None] * v[None]
    drift = {0: 0.5, 1: -0.8, 2: 0.05}
    clk = np.array([FAMILIES[g][2] for g in grp])[None] + np.array([drift[g] for g in grp])[None] * \
        (t - t.mean())[:, None]
    Y = _doppler(R, np.broadcast_to(v, R.shape), pos_rx, np.zeros(3), f0, clk)
    n_sv = len(grp)
    return (Y.ravel(), R.reshape(-1, 3), np.broadcast_to(v, R.shape).reshape(-1, 3), np.tile(f0, n_ep),
            np.repeat(t, n_sv), np.tile(grp, n_ep), np.tile(np.arange(n_sv), n_ep), pos_rx, drift)


def test_static_two_clocks_recover_offset_and_drift_each():
    Y, R, V, F, T, G, _, pos_rx, drift = _static_set(6, {0: 3, 2: 3})
    fix = solve_static(Y, 1.0, R, V, F, T, pos0_ecef_m=_start(pos_rx), clock_group=G, alpha=None)
    assert fix.status == FixStatus.OK
    assert np.linalg.norm(fix.pos_ecef_m - pos_rx) < ONE_MM
    np.testing.assert_allclose(fix.clock_polys_hz, [[FAMILIES[0][2], drift[0]], [FAMILIES[2][2], drift[2]]],
                               atol=CLOCK_TOL_HZ)
    assert fix.cov.shape == (7, 7)


def test_static_passes_common_two_clocks():
    Y, R, V, F, T, G, P, pos_rx, drift = _static_set(7, {0: 4, 1: 3})
    fix = solve_static_passes(Y, 1.0, R, V, F, T, P, pos0_ecef_m=_start(pos_rx), clock="common", clock_group=G,
                              time_bias=False, alpha=None)
    assert fix.status == FixStatus.OK
    assert np.linalg.norm(fix.pos_ecef_m - pos_rx) < ONE_MM
    np.testing.assert_allclose(fix.rx_clock_polys_hz, [[FAMILIES[0][2], drift[0]], [FAMILIES[1][2], drift[1]]],
                               atol=CLOCK_TOL_HZ)
    np.testing.assert_allclose(fix.sat_offset_hz, 0.0, atol=CLOCK_TOL_HZ)
    assert fix.pass_clock.tolist() == [0] * 4 + [1] * 3


def test_static_passes_one_group_is_identical_to_no_groups():
    Y, R, V, F, T, G, P, pos_rx, _ = _static_set(8, {0: 5})
    Y = Y + np.random.default_rng(8).normal(0, 0.3, Y.shape)
    kw = dict(pos0_ecef_m=_start(pos_rx), clock="common", time_bias=False)
    a = solve_static_passes(Y, 0.3, R, V, F, T, P, **kw)
    b = solve_static_passes(Y, 0.3, R, V, F, T, P, clock_group=G, **kw)
    np.testing.assert_array_equal(a.pos_ecef_m, b.pos_ecef_m)
    np.testing.assert_array_equal(a.cov, b.cov)


@pytest.mark.parametrize("counts", [{0: 3, 1: 3}])
def test_static_one_group_vs_two_differ_when_clocks_differ(counts):
    """A single clock cannot explain two constellations' offsets: the fit is then inconsistent (can fail)."""
    Y, R, V, F, T, G, _, pos_rx, _ = _static_set(9, counts)
    one = solve_static(Y, 1.0, R, V, F, T, pos0_ecef_m=pos_rx, alpha=None)
    two = solve_static(Y, 1.0, R, V, F, T, pos0_ecef_m=pos_rx, clock_group=G, alpha=None)
    assert two.chi2 < 1e-6 < one.chi2
