"""Channel: Doppler laws in the samples, and the site geometry against direct SGP4."""

import importlib.util

import numpy as np
import pytest

from scipy.optimize import brentq

from leosop.constants import C_MPS, OMEGA_E_RAD_PER_S
from leosop.errors import InputError
from leosop.frames import geodetic_to_ecef, range_rate
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef, state_ecef_pairs
from leosop.positioning.measurements import sv_states_from_tle
from leosop.signal.channel import (CN0_REF_RANGE_M, OrbitError, SiteChannel, cn0_geometry_dbhz, doppler_blocks,
                                   light_time_positions, site_geometry)
from leosop.signal.pilot import PilotComb

FS = 1e6
START = np.datetime64("2025-01-01T19:40:00", "ns")
XIAN = geodetic_to_ecef(np.radians(34.342), np.radians(108.940), 400.0)
NEEDS_NUMBA = pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed (leosop[fast])")


def _inst_freq_poly(x, fs, deg):
    """Polynomial fit of the unwrapped phase (cycles) of a single tone, about the block centre."""
    t = (np.arange(x.size) - (x.size - 1) / 2) / fs
    return np.polyfit(t, np.unwrap(np.angle(x)) / (2 * np.pi), deg)


def test_blocks_follow_doppler_law():
    one = PilotComb(n_tones=1)
    x = doppler_blocks(FS, 50_000, [1_234.5, -20_000.0], [3_000.0, -4_000.0], doppler_accel_hz_per_s2=[50.0, 0.0],
                       comb=one, dtype=np.complex128)
    for row, (d, r, a) in zip(x, [(1_234.5, 3_000.0, 50.0), (-20_000.0, -4_000.0, 0.0)]):
        p = _inst_freq_poly(row, FS, 3)  # cycles = a t^3/6 + r t^2/2 + d t + c
        # Noise-free phase: the fit is exact to float rounding (1e-9 relative).
        np.testing.assert_allclose(p[:3], [a / 6, r / 2, d], rtol=1e-7, atol=1e-6)


def _tau_bisection(const, k, t_rx_s):
    """Light time of satellite k at reception START + t_rx_s by bracketing c tau = range (independent solver)."""
    def residual_m(tau):
        t_tx = t_rx_s - tau
        t_ns = np.round(t_tx * 1e9)
        p, v, _ = state_ecef_pairs(const, [k], START + np.array([t_ns], dtype="timedelta64[ns]"))
        p = p[0] + v[0] * (t_tx - t_ns * 1e-9)
        a = OMEGA_E_RAD_PER_S * tau  # the Earth turns by a during tau: rotate into the frame of reception
        rot = np.array([[np.cos(a), np.sin(a), 0.0], [-np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        return np.linalg.norm(rot @ p - XIAN) - C_MPS * tau

    return brentq(residual_m, 1e-4, 2e-2, xtol=1e-16, rtol=4 * np.finfo(float).eps)


def test_light_time_against_bisection():
    const = load_constellation().select_ids(["71585", "70524"])
    t = np.array([0.0, 0.37, 1.0])
    _, tau = light_time_positions(const, XIAN, START + np.round(t * 1e9).astype("timedelta64[ns]"))
    ref = np.array([[_tau_bisection(const, k, ti) for ti in t] for k in range(2)])
    # Fixed point after 3 passes: residual (rr/c)^3 * tau ~ 1e-16 s; brentq to float
    # precision on ~3e-3 s: 1e-15 s. Range (c tau) agrees to 1e-6 m.
    np.testing.assert_allclose(tau * C_MPS, ref * C_MPS, atol=1e-6)


def test_doppler_is_derivative_of_light_time_range():
    const = load_constellation().select_ids(["71585", "70524"])
    t_nodes, range_m, elev = site_geometry(const, XIAN, START, 1.0)
    ch = SiteChannel(t_nodes, range_m, FS, 45.0, [3.0, 7.0])
    t = np.array([0.0137, 0.5003, 0.9871])  # between nodes
    h = 1e-3
    tt = START + np.round(np.concatenate([t - h, t + h]) * 1e9).astype("timedelta64[ns]")
    _, tau = light_time_positions(const, XIAN, tt)
    rho_dot = C_MPS * (tau[:, 3:] - tau[:, :3]) / (2 * h)
    direct = -rho_dot * ch.comb.carrier_hz / C_MPS + np.array([[3.0], [7.0]])
    # Central difference: h^2/6 |d3 rho/dt3| < 1e-6 m/s (< 10 m/s^3 in LEO); spline of the
    # range at 0.1 s nodes: ~h^3/24 |d4 rho/dt4| ~ 1e-6 m/s. 1e-3 Hz = 2.6e-5 m/s: 20x margin.
    np.testing.assert_allclose(ch.doppler_hz(t), direct, atol=1e-3)
    # The positioning side (sv_states_from_tle) puts the satellite at the same emission
    # position: its range matches c tau to its ns rounding of tau (7.5 km/s x 0.5 ns < 4 um).
    ids = np.repeat(np.array(const.sat_ids), 3)
    when = np.tile(START + np.round(t * 1e9).astype("timedelta64[ns]"), 2)
    p, v, _ = sv_states_from_tle(const, ids, when, XIAN)
    _, tau_t = light_time_positions(const, XIAN, START + np.round(t * 1e9).astype("timedelta64[ns]"))
    np.testing.assert_allclose(np.linalg.norm(p - XIAN, axis=-1), (tau_t * C_MPS).ravel(), atol=1e-5)
    # Without light time (range rate at reception) the Doppler is off by ~rate x tau:
    # several Hz, the effect this model exists for.
    pr, vr, _ = state_ecef(const, START + np.round(t * 1e9).astype("timedelta64[ns]"))
    no_lt = -range_rate(pr, vr, XIAN) * ch.comb.carrier_hz / C_MPS + np.array([[3.0], [7.0]])
    assert np.all(np.abs(ch.doppler_hz(t) - no_lt) > 2.0)
    assert np.all((np.degrees(elev) > 40) & (np.degrees(elev) < 90))


def test_orbit_error_along_track_closed_form():
    const = load_constellation().select_ids(["71585", "70524"])
    dt = 0.01  # 76 m along track
    t_nodes, r0, _ = site_geometry(const, XIAN, START, 2.0)
    _, r1, _ = site_geometry(const, XIAN, START, 2.0, orbit_error=OrbitError([dt, dt], 0.0, 0.0))
    ch0, ch1 = SiteChannel(t_nodes, r0, FS, 45.0, 0.0), SiteChannel(t_nodes, r1, FS, 45.0, 0.0)
    t = np.array([0.5, 1.5])
    # First order in dt: the ECEF time shift gives dt * Doppler rate; the Earth's turn
    # omega dt during the offset is the same as moving the receiver by -dt * omega x r_rx
    # (westward), whose Doppler is -(f/c) dt d/dt(u . omega x r_rx), u the unit line of sight.
    h = 1e-3
    tt = START + np.round(np.concatenate([t - h, t + h]) * 1e9).astype("timedelta64[ns]")
    pos, _ = light_time_positions(const, XIAN, tt)
    los = pos - XIAN
    u = los / np.linalg.norm(los, axis=-1, keepdims=True)
    proj = u @ np.cross([0.0, 0.0, OMEGA_E_RAD_PER_S], XIAN)
    rot_hz = -ch0.comb.carrier_hz / C_MPS * dt * (proj[:, 2:] - proj[:, :2]) / (2 * h)
    expect = dt * ch0.doppler_rate_hz_per_s(t) + rot_hz
    # Second order: dt^2/2 * |Doppler acceleration| (< 60 Hz/s^2) = 3e-3 Hz.
    np.testing.assert_allclose(ch1.doppler_hz(t) - ch0.doppler_hz(t), expect, atol=5e-3)
    assert np.all(np.abs(expect) > 20)  # the offset matters: tens of Hz


def test_orbit_error_radial_cross_shift():
    const = load_constellation().select_ids(["71585", "70524"])
    radial, cross = np.array([100.0, -40.0]), np.array([50.0, 80.0])
    t_nodes, r0, _ = site_geometry(const, XIAN, START, 0.2)
    _, r1, _ = site_geometry(const, XIAN, START, 0.2, orbit_error=OrbitError(0.0, radial, cross))
    times = START + np.round(t_nodes * 1e9).astype("timedelta64[ns]")
    pos, _ = light_time_positions(const, XIAN, times)
    # RTN axes from the SGP4 state at reception (3 ms from emission: the axes turn by
    # ~3e-6 rad, 3e-4 m on a 100 m shift).
    p, v, _ = state_ecef(const, times)
    v_i = v + np.cross([0.0, 0.0, OMEGA_E_RAD_PER_S], p)
    r_hat = p / np.linalg.norm(p, axis=-1, keepdims=True)
    c_hat = np.cross(p, v_i)
    c_hat /= np.linalg.norm(c_hat, axis=-1, keepdims=True)
    u = (pos - XIAN) / r0[..., None]
    shift = radial[:, None, None] * r_hat + cross[:, None, None] * c_hat
    # First order: the range grows by u . shift; second order |shift|^2 / (2 range) < 1e-2 m.
    np.testing.assert_allclose(r1 - r0, np.sum(u * shift, axis=-1), atol=0.02)


def test_cn0_geometry():
    # Zenith at the reference range: the reference value; twice the range at 30 deg:
    # -6.02 dB of free-space loss and 10 log10(0.5) = -3.01 dB of pattern.
    got = cn0_geometry_dbhz(45.0, np.array([1.0, 2.0, 2.0]) * CN0_REF_RANGE_M, np.radians([90.0, 30.0, -1.0]))
    np.testing.assert_allclose(got[:2], [45.0, 45.0 - 20 * np.log10(2) + 10 * np.log10(0.5)], atol=1e-12)
    assert got[2] == -np.inf  # below the horizon: blocked


#: |x| of a unit tone: the numpy path's exponentials are unit to ~1e-15; the compiled recurrence's
#: rotations drift by at most u (K^3/6 + K^2/2 + K) ~ 2.5e-9 between anchors (leosop.signal.combkernels).
_MODULUS_RTOL = {"numpy": 1e-12, "numba": 3e-9}


@pytest.mark.parametrize("kernel", ["numpy", pytest.param("numba", marks=NEEDS_NUMBA)])
def test_time_varying_cn0_and_silence(kernel):
    const = load_constellation().select_ids(["71585", "70524"])
    t_nodes, range_m, _ = site_geometry(const, XIAN, START, 0.3)
    cn0 = np.stack([np.linspace(40.0, 43.0, t_nodes.size), np.full(t_nodes.size, -np.inf)])
    ch = SiteChannel(t_nodes, range_m, FS, cn0, 0.0, comb=PilotComb(n_tones=1), kernel=kernel)
    # Linear in amplitude between nodes: at a node the node's value exactly.
    np.testing.assert_allclose(ch.cn0_at(t_nodes[3:4])[:, 0], [cn0[0, 3], -np.inf])
    x = ch.samples(1000, 2000)
    # A single tone of a silent second satellite: |x| is the first one's amplitude alone.
    np.testing.assert_allclose(np.abs(x), ch.amplitude((1000 + np.arange(2000)) / FS)[0],
                               rtol=_MODULUS_RTOL[kernel])


@NEEDS_NUMBA
def test_compiled_comb_matches_numpy_path():
    # Second implementation: the compiled kernel (cubic phases by recurrence, leosop.signal.combkernels)
    # against comb_baseband summed satellite by satellite, on five satellites with clock offsets, drifts,
    # phases, a shared range reference and C/N0 varying over nodes (one silent), over chunks that start
    # inside a node interval and cross several nodes (4e5 samples at 1 MS/s: 0.1 s nodes, 512-sample anchors).
    const = load_constellation().select_ids(["71585", "70524", "70546", "71563", "72129"])
    t_nodes, range_m, elev = site_geometry(const, XIAN, START, 1.0)
    rng = np.random.default_rng(3)
    cn0 = cn0_geometry_dbhz(45.0, range_m, elev)
    cn0[4] = -np.inf
    kw = dict(clock_offset_hz=620e3 + rng.uniform(0.0, 5.0, 5), phase_rad=rng.uniform(0.0, 6.0, 5),
              rx_drift_hz_per_s=25.0, sat_drift_hz_per_s=rng.normal(0.0, 0.1, 5), range_ref_m=range_m[:, 5])
    x = {k: SiteChannel(t_nodes, range_m, FS, cn0, kernel=k, **kw).samples(123_457, 400_000)
         for k in ("numpy", "numba")}
    # Both paths round the ~1000 km range to 1.2e-10 m in float64, 4.4e-9 cycles of phase (2.8e-8 rad)
    # at 11.3 GHz, differently: 1e-6 of a unit tone bounds 4 satellites x 9 tones x that (measured 4.1e-7).
    assert np.max(np.abs(x["numba"] - x["numpy"])) < 1e-6
    assert np.max(np.abs(x["numpy"])) > 1.0  # the comparison saw signal


def test_unknown_kernel():
    const = load_constellation().select_ids(["71585"])
    t_nodes, range_m, _ = site_geometry(const, XIAN, START, 0.1)
    with pytest.raises(InputError, match="kernel"):
        SiteChannel(t_nodes, range_m, FS, 45.0, 0.0, kernel="fortran")



def test_samples_phase_is_integral_of_doppler():
    const = load_constellation().select_ids(["71585"])
    t_nodes, range_m, _ = site_geometry(const, XIAN, START, 0.3)
    ch = SiteChannel(t_nodes, range_m, FS, 45.0, 5.0, comb=PilotComb(n_tones=1))
    start, n = 100_000, 100_000
    x = np.concatenate([ch.samples(start, n // 2), ch.samples(start + n // 2, n // 2)])  # chunked
    p = _inst_freq_poly(x, FS, 3)
    t_c = (start + (n - 1) / 2) / FS
    # Noise-free: the phase fit's frequency equals the truth to 1e-6 Hz.
    assert p[2] == pytest.approx(ch.doppler_hz([t_c])[0, 0], abs=1e-6)
    assert 2 * p[1] == pytest.approx(ch.doppler_rate_hz_per_s([t_c])[0, 0], abs=1e-3)


def test_several_satellites_amplitudes():
    const = load_constellation().select_ids(["71585", "70524"])
    t_nodes, rr, _ = site_geometry(const, XIAN, START, 0.1)
    one = PilotComb(n_tones=1)
    both = SiteChannel(t_nodes, rr, FS, [45.0, 39.0], 0.0, comb=one).samples(0, 1000)
    a = SiteChannel(t_nodes, rr[:1], FS, 45.0, 0.0, comb=one).samples(0, 1000)
    b = SiteChannel(t_nodes, rr[1:], FS, 45.0, 0.0, comb=one).samples(0, 1000)
    # Sum with the weaker satellite 6 dB down (amplitude 10^(-6/20)).
    np.testing.assert_allclose(both, a + 10 ** (-6 / 20) * b, atol=1e-9)


def test_moving_receiver_doppler_is_the_relative_velocity_along_the_line_of_sight():
    # A receiver at 25 m/s through Xi'an, heading for the first satellite: the channel's
    # Doppler, from the light-time range at 0.1 s nodes, against the closed form
    # -(f/c) u . (v_sv - v_rx) with the satellite's apparent state at the receiver's
    # position (sv_states_from_tle, the positioning side's independent path).
    const = load_constellation().select_ids(["71585", "70524"])
    p0, _, _ = state_ecef(const, np.array([START]))
    vel_rx = 25.0 * (p0[0, 0] - XIAN) / np.linalg.norm(p0[0, 0] - XIAN)
    t_nodes, range_m, _ = site_geometry(const, XIAN, START, 2.0, vel_rx_ecef_mps=vel_rx)
    ch = SiteChannel(t_nodes, range_m, FS, 45.0, [0.0, 0.0])
    t = np.array([0.0137, 1.0003, 1.9871])
    rx = XIAN + t[:, None] * vel_rx
    # Range at the nodes: each node's receiver position given alone (static) gives the same c tau.
    _, tau = light_time_positions(const, XIAN + t_nodes[3] * vel_rx, START + np.round(t_nodes[3] * 1e9)
                                  .astype("timedelta64[ns]"))
    np.testing.assert_allclose(range_m[:, 3], tau[:, 0] * C_MPS, atol=1e-6)
    ids = np.repeat(np.array(const.sat_ids), 3)
    when = np.tile(START + np.round(t * 1e9).astype("timedelta64[ns]"), 2)
    p, v, _ = sv_states_from_tle(const, ids, when, np.tile(rx, (2, 1)))
    u = (p - np.tile(rx, (2, 1)))
    u /= np.linalg.norm(u, axis=1)[:, None]
    direct = -np.sum(u * (v - vel_rx), axis=1) * ch.comb.carrier_hz / C_MPS
    # The receiver's motion is worth up to 25 m/s x 38 Hz/(m/s) ~ 950 Hz here; the node spline
    # and the ns rounding of the apparent state agree to ~1e-3 Hz (the static test above).
    assert np.max(np.abs(np.sum(u * vel_rx, axis=1))) * ch.comb.carrier_hz / C_MPS > 100.0
    np.testing.assert_allclose(ch.doppler_hz(t).ravel(), direct, atol=5e-3)
