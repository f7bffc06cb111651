"""The Doppler rate of a moving receiver (the simulator's chirp), and for an inertial time offset of the orbit,
against differences of SGP4 states."""

import numpy as np

from leosop.constants import C_MPS
from leosop.constellations import REGISTRY
from leosop.frames import geodetic_to_ecef, range_rate, rotate_to_later_ecef
from leosop.geometry.doppler import doppler_rate, sv_motion
from leosop.orbits import load_constellation
from leosop.orbits.propagate import state_ecef

F_KU_HZ = REGISTRY["starlink"].carrier_hz


def test_moving_receiver_doppler_rate_matches_differences_of_propagated_states():
    const = load_constellation().subset([0])
    rx = geodetic_to_ecef(np.radians(34.0), np.radians(108.9), 10e3)
    vel_rx = np.array([150.0, -200.0, 30.0])  # an aircraft in straight flight [m/s]
    t = np.datetime64("2025-01-01T00:00:00") + np.arange(0, 6000, 60).astype("timedelta64[s]")
    h_s = 0.05
    dt = np.timedelta64(int(h_s * 1e3), "ms")
    (pos,), (vel,), _ = state_ecef(const, t)
    (pos_p,), (vel_p,), _ = state_ecef(const, t + dt)
    (pos_m,), (vel_m,), _ = state_ecef(const, t - dt)
    doppler_p = -F_KU_HZ / C_MPS * range_rate(pos_p, vel_p, rx + h_s * vel_rx, vel_rx)
    doppler_m = -F_KU_HZ / C_MPS * range_rate(pos_m, vel_m, rx - h_s * vel_rx, vel_rx)
    fd = (doppler_p - doppler_m) / (2 * h_s)
    # Per pair, as the simulator calls it: one receiver state per satellite row.
    n = len(t)
    rate, grad = doppler_rate(pos[:, None], vel[:, None], np.broadcast_to(rx, (n, 3)), F_KU_HZ,
                              np.broadcast_to(vel_rx, (n, 1, 3)))
    # The model leaves out J2 (up to ~1.5e-2 m/s^2 in low orbit, x f0/c = 38 Hz per m/s at Ku band:
    # ~0.6 Hz/s; achieved 0.52); the central difference errs by ~(0.05 s)^2/6 x the third derivative
    # (<1e-2 Hz/s). Bound 1 Hz/s on the rates of this orbit, up to ~230 Hz/s.
    np.testing.assert_allclose(rate[:, 0], fd, atol=1.0)
    assert np.abs(fd).max() > 100.0  # the comparison covers large rates, not only a far-away satellite
    # Gradient w.r.t. the receiver position against central differences in 1 m steps.
    e = np.eye(3)
    fd_grad = np.stack([(doppler_rate(pos, vel, rx + e[j], F_KU_HZ, vel_rx)[0]
                         - doppler_rate(pos, vel, rx - e[j], F_KU_HZ, vel_rx)[0]) / 2.0 for j in range(3)], -1)
    np.testing.assert_allclose(grad[:, 0], fd_grad, rtol=1e-6, atol=1e-12)


def test_at_rest_is_the_moving_model_with_zero_velocity():
    rng = np.random.default_rng(3)
    rx = geodetic_to_ecef(np.radians(-33.9), np.radians(18.4), 0.0)
    pos = rx + rng.normal(size=(6, 3)) * 8e5 + 5e5 * rx / np.linalg.norm(rx)
    vel = rng.normal(size=(6, 3)) * 4e3
    rest = doppler_rate(pos, vel, rx, F_KU_HZ)
    moving = doppler_rate(pos, vel, rx, F_KU_HZ, np.zeros(3))
    np.testing.assert_array_equal(rest[0], moving[0])
    np.testing.assert_array_equal(rest[1], moving[1])


def test_inertial_time_offset_rate_matches_differences_of_rotated_states():
    # An element set's along-track error: the satellite is where its orbit puts it at t + dt, the Earth
    # having turned until t only, i.e. SGP4's ECEF states at t + dt expressed in the frame of t.
    const = load_constellation().subset([0])
    rx = geodetic_to_ecef(np.radians(48.1), np.radians(11.6), 520.0)
    t = np.datetime64("2025-01-01T00:00:00") + np.arange(0, 6000, 60).astype("timedelta64[s]")
    h_s = 0.05
    dt = np.timedelta64(int(h_s * 1e3), "ms")
    (pos,), (vel,), _ = state_ecef(const, t)
    doppler = {}
    for sign in (1, -1):
        (p,), (v,), _ = state_ecef(const, t + sign * dt)
        doppler[sign] = -F_KU_HZ / C_MPS * range_rate(rotate_to_later_ecef(p, -sign * h_s),
                                                      rotate_to_later_ecef(v, -sign * h_s), rx, np.zeros(3))
    fd = (doppler[1] - doppler[-1]) / (2 * h_s)
    rate, grad = doppler_rate(pos, vel, rx, F_KU_HZ, inertial=True)
    ecef, _ = doppler_rate(pos, vel, rx, F_KU_HZ)
    # As above: J2 left out (~0.6 Hz/s), the central difference good to 1e-2 Hz/s. The ECEF rate differs by
    # the Earth's turn, omega |r| / |v| ~ 7 % of the along-track motion: tens of Hz/s on this orbit.
    np.testing.assert_allclose(rate, fd, atol=1.0)
    assert np.abs(ecef - fd).max() > 20.0
    e = np.eye(3)
    fd_grad = np.stack([(doppler_rate(pos, vel, rx + e[j], F_KU_HZ, inertial=True)[0]
                         - doppler_rate(pos, vel, rx - e[j], F_KU_HZ, inertial=True)[0]) / 2.0 for j in range(3)], -1)
    np.testing.assert_allclose(grad, fd_grad, rtol=1e-6, atol=1e-12)


def test_satellite_terms_computed_once_give_the_same_rates_to_the_last_bit():
    """A multi-pass fix computes :func:`sv_motion` once for all its iterates: the rates and gradients are
    those :func:`doppler_rate` makes on its own, bit for bit, in both offset models."""
    rng = np.random.default_rng(7)
    pos = rng.normal(size=(9, 3)) * 7.0e6
    vel = rng.normal(size=(9, 3)) * 7.5e3
    rx = rng.normal(size=(4, 3)) * 6.4e6  # four iterates of the receiver
    for inertial in (False, True):
        motion = sv_motion(pos, vel, inertial=inertial)
        alone = doppler_rate(pos, vel, rx, F_KU_HZ, inertial=inertial)
        shared = doppler_rate(pos, vel, rx, F_KU_HZ, inertial=inertial, motion=motion)
        assert alone[0].shape == (4, 9) and all(np.array_equal(a, b) for a, b in zip(alone, shared))
