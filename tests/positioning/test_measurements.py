"""Measurement CSV reader/writer and satellite states with light time."""

import numpy as np
import pytest

from leosop.constants import C_MPS, OMEGA_E_RAD_PER_S
from leosop.errors import InputError
from leosop.frames import geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef
from leosop.positioning.measurements import (DEFAULT_CARRIER_HZ, Measurements, read_measurements,
                                             sv_states_from_tle, write_measurements)


def _write(tmp_path, text):
    path = tmp_path / "meas.csv"
    path.write_text(text)
    return path


def test_round_trip_keeps_every_value(tmp_path):
    rng = np.random.default_rng(1)
    n = 6
    t = np.datetime64("2025-01-01T00:00:00", "ns") + (np.arange(n) * 123_456_789).astype("timedelta64[ns]")
    meas = Measurements(t_s=np.zeros(n), time_utc=t, sat_id=np.array([str(70001 + k) for k in range(n)]),
                        doppler_hz=rng.normal(0, 1e5, n), sigma_hz=rng.uniform(0.1, 2, n),
                        carrier_hz=np.full(n, 11.575e9), pos_sv_ecef_m=rng.normal(0, 7e6, (n, 3)),
                        vel_sv_ecef_mps=rng.normal(0, 7e3, (n, 3)), line=np.arange(n))
    write_measurements(tmp_path / "m.csv", meas)
    back = read_measurements(tmp_path / "m.csv")
    # repr() of floats round-trips exactly; times are written to the microsecond.
    np.testing.assert_array_equal(back.doppler_hz, meas.doppler_hz)
    np.testing.assert_array_equal(back.pos_sv_ecef_m, meas.pos_sv_ecef_m)
    np.testing.assert_array_equal(back.sigma_hz, meas.sigma_hz)
    assert (np.abs((back.time_utc - t).astype(np.int64)) < 1000).all()
    np.testing.assert_allclose(back.t_s, np.arange(n) * 0.123456789, atol=1e-6)
    assert back.rejected == ()


def test_bad_rows_are_set_aside_with_reasons(tmp_path):
    path = _write(tmp_path, "time_utc,sat_id,doppler_hz,sigma_hz\n"
                            "2025-01-01T00:00:00Z,1,10.5,1\n"
                            "2025-01-01T00:00:00Z,2,nan,1\n"
                            "2025-01-01T00:00:00Z,1,11.0,1\n"
                            "2025-01-01T00:00:01Z,3,abc,1\n"
                            "2025-01-01T00:00:01Z,4,12,-1\n"
                            "2025-01-01T00:00:01Z,5,12,\n"
                            "yesterday,6,12,\n"
                            "2025-01-01T00:00:02Z,7\n")
    meas = read_measurements(path, carrier_hz=1.5e9)
    assert list(meas.sat_id) == ["1", "5"]
    assert np.isnan(meas.sigma_hz[1]) and meas.carrier_hz[0] == 1.5e9
    reasons = dict(meas.rejected)
    assert set(reasons) == {3, 4, 5, 6, 8, 9}
    assert "doppler_hz" in reasons[3] and "duplicate of line 2" in reasons[4]
    assert "sigma_hz" in reasons[6] and "ISO 8601" in reasons[8] and "fields" in reasons[9]


@pytest.mark.parametrize("text, message", [
    ("time_utc,sat_id\n2025-01-01T00:00:00Z,1\n", "missing column doppler_hz"),
    ("sat_id,doppler_hz\n1,2\n", "missing column time_utc or t_s"),
    ("t_s,sat_id,doppler_hz,x_sv_m,y_sv_m\n0,1,2,3,4\n", "missing column z_sv_m"),
    ("t_s,sat_id,doppler_hz\n", "no measurement rows"),
    ("", "empty file"),
    ("t_s,sat_id,doppler_hz\n0,1,nan\n", "no usable measurement rows"),
])
def test_whole_file_errors_name_the_problem(tmp_path, text, message):
    with pytest.raises(InputError, match=message):
        read_measurements(_write(tmp_path, text))


def test_default_carrier_is_the_starlink_pilot(tmp_path):
    meas = read_measurements(_write(tmp_path, "t_s,sat_id,doppler_hz\n0,1,2\n"))
    assert meas.carrier_hz[0] == DEFAULT_CARRIER_HZ == 11.325e9


def test_light_time_against_direct_solution():
    """tau solves |r_s(t - tau) in the frame of t - r_r| = c tau; check it from scratch with bisection."""
    const = load_constellation().subset(slice(0, 5))
    t_rx = np.full(5, np.datetime64("2025-01-01T01:00:00", "ns"))
    rx = geodetic_to_ecef(np.radians(10.0), np.radians(20.0), 0.0)
    pos, vel, reason = sv_states_from_tle(const, const.sat_ids, t_rx, rx, max_age_days=1.0)
    assert (reason == "").all()
    for k in range(5):
        def gap(tau):
            p, _, _ = state_ecef(const.subset([k]), [t_rx[k] - np.timedelta64(int(round(tau * 1e9)), "ns")])
            a = OMEGA_E_RAD_PER_S * tau
            c, s = np.cos(a), np.sin(a)
            x = p[0, 0]
            q = np.array([c * x[0] + s * x[1], -s * x[0] + c * x[1], x[2]])
            return np.linalg.norm(q - rx) - C_MPS * tau, q
        lo, hi = 0.0, 0.1
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if gap(mid)[0] > 0 else (lo, mid)
        # 1 ns of time rounding moves a LEO satellite by 8 um; 1 mm leaves room for it.
        np.testing.assert_allclose(pos[k], gap(lo)[1], atol=1e-3)
    # Without light time the state differs by roughly v * tau (tens of metres).
    p0, _, _ = sv_states_from_tle(const, const.sat_ids, t_rx)
    assert (np.linalg.norm(p0 - pos, axis=-1) > 10.0).all()


def test_refusals_unknown_id_and_stale_elements():
    const = load_constellation().subset(slice(0, 2))
    t = np.array(["2025-01-01T01:00:00", "2025-03-01T00:00:00", "2025-01-01T01:00:00"], dtype="datetime64[ns]")
    pos, vel, reason = sv_states_from_tle(const, [const.sat_ids[0], const.sat_ids[1], "99999"], t)
    assert reason[0] == "" and np.isfinite(pos[0]).all()
    assert "+59.0 days" in reason[1] and "limit 30 days" in reason[1]
    assert "no element set for satellite id 99999" in reason[2]
    assert np.isnan(pos[1:]).all() and np.isnan(vel[1:]).all()


def test_tle_states_give_the_doppler_of_the_light_time_range():
    """The generator's Doppler (derivative of the exact light-time range) is what the solver's model predicts.

    Independent paths: the generator solves the light time on a node grid and
    differentiates a spline of the range; the positioning side differentiates
    the apparent satellite position and projects it on the line of sight.
    """
    from leosop.constants import C_MPS
    from leosop.constellations import REGISTRY
    from leosop.frames import geodetic_to_ecef
    from leosop.orbits import load_constellation
    from leosop.positioning.measurements import sv_states_from_tle
    from leosop.signal.channel import SiteChannel, site_geometry

    const = load_constellation()
    const = const.subset(np.arange(0, 4408, 400))
    rx = geodetic_to_ecef(np.radians(34.342), np.radians(108.94), 400.0)
    start = np.datetime64("2025-01-01T19:40:00", "ns")
    t_nodes, range_m, _ = site_geometry(const, rx, start, 20.0)
    channel = SiteChannel(t_nodes, range_m, 2.5e6, 45.0, 0.0)
    t = np.arange(0.0, 20.0, 2.0)
    truth = channel.doppler_hz(t)  # (n_sats, n_t)
    ids = np.repeat(const.sat_ids, t.size)
    times = start + np.tile((t * 1e9).astype("timedelta64[ns]"), len(const))
    p, v, reason = sv_states_from_tle(const, ids, times, rx)
    u = (p - rx) / np.linalg.norm(p - rx, axis=-1, keepdims=True)
    model = -np.sum(u * v, axis=-1) * REGISTRY["starlink"].carrier_hz / C_MPS
    # Spline of a 0.1 s node grid: ~1e-4 Hz; the old model (SGP4 velocity, no light-time
    # rate) was up to ~6 Hz off.
    assert (reason == "").all()
    assert np.max(np.abs(model - truth.ravel())) < 5e-3
