"""Coarse alignment ([Qu 2024]) against closed forms, the paper's numbers and real data."""

import warnings

import numpy as np
import pytest

from leosop.constants import G0_MPS2, OMEGA_E_RAD_PER_S
from leosop.earth import normal_gravity_mps2
from leosop.errors import InputError
from leosop.ins import alignment as al
from leosop.apps.repro.alignment import attitude_errors, sweep
from leosop.rotations import euler_to_dcm, heading_from_yaw

from tests.helpers import data_path


LAT = np.radians(30.0)
G = float(normal_gravity_mps2(LAT, 0.0))
W_N = OMEGA_E_RAD_PER_S * np.array([0.0, np.cos(LAT), np.sin(LAT)])


def _static_outputs(C_n_b):
    """Error-free mean specific force and angular rate in body RFU for attitudes C_n_b."""
    return (np.einsum("...ji,j->...i", C_n_b, [0.0, 0.0, G]), np.einsum("...ji,j->...i", C_n_b, W_N))


def _random_attitudes(n, rng, max_pitch_deg=85.0):
    pitch = np.radians(rng.uniform(-max_pitch_deg, max_pitch_deg, n))
    roll = rng.uniform(-np.pi, np.pi, n)
    yaw = rng.uniform(-np.pi, np.pi, n)
    return pitch, roll, yaw


@pytest.mark.parametrize("method", al.METHODS)
def test_error_free_outputs_give_the_true_attitude(method):
    rng = np.random.default_rng(0)
    pitch, roll, yaw = _random_attitudes(200, rng)
    f_b, w_b = _static_outputs(euler_to_dcm(pitch, roll, yaw))
    p, r, y = al.align(f_b, w_b, LAT, method=method, g_mps2=G)
    # Exact formulas: only rounding (1e-16 relative, amplified ~1/cos(85 deg)).
    for est, true in ((p, pitch), (r, roll), (y, yaw)):
        np.testing.assert_allclose(np.angle(np.exp(1j * (est - true))), 0.0, atol=1e-9)


@pytest.mark.parametrize("algorithm", ["1", "2"])
def test_closed_forms_are_the_angles_of_the_matrix(algorithm):
    # Eq. 10-15 against eq. 5-6 with noisy (non-orthogonal) inputs, paper frames.
    rng = np.random.default_rng(1)
    pitch, roll, yaw = _random_attitudes(100, rng)
    f_b, w_b = _static_outputs(euler_to_dcm(pitch, roll, yaw))
    f_fur = (f_b + rng.normal(0, 0.01, f_b.shape)) @ al.P_RFU_FUR
    w_fur = (w_b + rng.normal(0, 1e-6, w_b.shape)) @ al.P_RFU_FUR
    C = al.dual_vector_dcm_paper(f_fur, w_fur, LAT, algorithm=algorithm, g_mps2=G)
    theta, phi, gamma = al.paper_angles(f_fur, w_fur, LAT, algorithm=algorithm, g_mps2=G)
    # Same quantities through two routes: agreement to rounding.
    np.testing.assert_allclose(theta, np.arcsin(C[:, 2, 0]), atol=1e-12)
    np.testing.assert_allclose(phi, np.arctan2(-C[:, 2, 2], C[:, 2, 1]), atol=1e-12)
    np.testing.assert_allclose(gamma, np.arctan2(C[:, 0, 0], C[:, 1, 0]), atol=1e-12)


def test_paper_frames_convert_to_the_toolkit_convention():
    # C_b^n of the FUR body with noise-free inputs must be the toolkit C_n_b
    # with the body axes permuted, and gamma the heading.
    pitch, roll, heading = np.radians([40.0, -70.0, 120.0])
    C_n_b = euler_to_dcm(pitch, roll, -heading)
    f_b, w_b = _static_outputs(C_n_b)
    C_paper = al.dual_vector_dcm_paper(f_b @ al.P_RFU_FUR, w_b @ al.P_RFU_FUR, LAT, algorithm="2", g_mps2=G)
    np.testing.assert_allclose(C_paper, C_n_b @ al.P_RFU_FUR, atol=1e-12)
    theta, phi, gamma = al.paper_angles(f_b @ al.P_RFU_FUR, w_b @ al.P_RFU_FUR, LAT, algorithm="1", g_mps2=G)
    np.testing.assert_allclose([theta, phi, gamma], [pitch, roll, heading], atol=1e-12)


@pytest.mark.parametrize("algorithm", ["1", "2"])
def test_error_equations_match_finite_perturbations(algorithm):
    rng = np.random.default_rng(2)
    pitch, roll, yaw = _random_attitudes(50, rng, max_pitch_deg=80.0)
    f_b, w_b = _static_outputs(euler_to_dcm(pitch, roll, yaw))
    f, w = f_b @ al.P_RFU_FUR, w_b @ al.P_RFU_FUR
    df = rng.normal(0, 1e-5, f.shape)  # 1 ug and 1e-3 deg/h: deep in the linear regime
    dw = rng.normal(0, 5e-12, w.shape)
    lin = al.paper_angle_errors(f, w, df, dw, LAT, algorithm=algorithm, g_mps2=G)
    a0 = al.paper_angles(f, w, LAT, algorithm=algorithm, g_mps2=G)
    a1 = al.paper_angles(f + df, w + dw, LAT, algorithm=algorithm, g_mps2=G)
    for d_lin, x0, x1 in zip(lin, a0, a1):
        exact = np.angle(np.exp(1j * (x1 - x0)))
        # Second-order remainder ~ (relative perturbation) x first order: 1e-6 x 1/cos(80) -> 1e-4.
        np.testing.assert_allclose(d_lin, exact, rtol=1e-3, atol=1e-12)


def test_monte_carlo_at_80_deg_matches_the_paper():
    # [Qu 2024]: 1 mg, 0.1 deg/h, latitude 30, 100 shots per attitude; at 80 deg
    # pitch the maximum yaw error is about 11 deg (alg. 1) and 2.2 deg (alg. 2).
    # A 30 deg yaw/roll grid samples the maxima a little less densely than the
    # paper's sweep: bounds are the paper's values -30 % / +40 %.
    res = sweep([80.0], np.arange(-180, 180, 30.0), np.arange(0, 360, 30.0), seed=3, scheduler="serial")
    yaw = {k: v[0] for k, v in res["max_yaw_err_deg"].items()}
    assert 7.7 < yaw["alg1"] < 15.4
    assert 1.5 < yaw["alg2"] < 3.1
    # [Qu 2024]: pitch and roll errors below 1.6 deg up to 80.5 deg pitch.
    assert res["max_pitch_err_deg"]["alg2"][0] < 1.6 and res["max_roll_err_deg"]["alg2"][0] < 1.6


def test_wahba_beats_algorithm_2_at_large_pitch():
    # Same random errors for all methods (common random numbers).
    res = sweep([80.0, 85.0], np.arange(-180, 180, 45.0), np.arange(0, 360, 45.0), seed=4, scheduler="serial")
    for i, pitch in enumerate((80.0, 85.0)):
        pe = res["max_pitch_err_deg"]
        # alg. 2's pitch error grows as 1/cos(pitch) (arcsin of f_x / g), the
        # optimal one does not: at least 3x (theory 5.8x at 80, 11x at 85).
        assert pe["wahba"][i] * 3 < pe["alg2"][i], pitch
        # Yaw: both at the gyrocompassing limit; not worse by more than 5 %.
        assert res["max_yaw_err_deg"]["wahba"][i] < 1.05 * res["max_yaw_err_deg"]["alg2"][i]


def test_turntable_errors_are_fixed_in_the_body():
    # One IMU on a turntable: the same attitude visited twice in a trial sees
    # the same sensor errors, hence identical alignment errors; independent
    # draws per attitude (the paper's simulation) do not.
    kw = dict(accel_sigma_mps2=1e-4 * G0_MPS2, gyro_sigma_rad_per_s=np.radians(1.0) / 3600, lat_rad=LAT)
    errs = attitude_errors([80.0, 80.0], [45.0, 45.0], [90.0, 90.0], 20, rng=np.random.default_rng(5),
                           same_errors_for_all_attitudes=True, **kw)
    np.testing.assert_array_equal(errs["2"][2][0], errs["2"][2][1])
    errs = attitude_errors([80.0, 80.0], [45.0, 45.0], [90.0, 90.0], 20, rng=np.random.default_rng(5), **kw)
    assert np.all(errs["2"][2][0] != errs["2"][2][1])


def test_bad_latitude_and_method_raise_input_error():
    f_b, w_b = _static_outputs(np.eye(3))
    with pytest.raises(InputError, match="latitude"):
        al.align(f_b, w_b, np.radians(95.0))
    with pytest.raises(InputError, match="pole"):
        al.align(f_b, w_b, np.radians(89.5))
    with pytest.raises(InputError, match="method"):
        al.align(f_b, w_b, LAT, method="3")


def test_moving_vehicle_is_detected():
    rng = np.random.default_rng(6)
    dt, n = 0.01, 3000
    f_b, w_b = _static_outputs(np.eye(3))
    dtheta = np.tile(w_b * dt, (n, 1))
    dvel = np.tile(f_b * dt, (n, 1)) + rng.normal(0, 1e-3 * G0_MPS2 * dt, (n, 3))  # 1 mg noise: static
    with warnings.catch_warnings():
        warnings.simplefilter("error", al.MotionWarning)
        al.align_increments(dtheta, dvel, dt, LAT)
    # Driving: 0.5 m/s^2 accelerations changing every few seconds.
    t = np.arange(n) * dt
    dvel_moving = dvel + np.stack([0.5 * np.sin(2 * np.pi * t / 7), 0.5 * np.cos(2 * np.pi * t / 5), 0 * t], -1) * dt
    with pytest.warns(al.MotionWarning, match="static"):
        al.align_increments(dtheta, dvel_moving, dt, LAT)


def test_psins_laser_gyro_first_300_s():
    from leosop.ins.imu_io import read_psins

    log = read_psins(data_path("gnss-ins", "psins_lasergyro", "lasergyro.imu"))
    n = 30000  # 300 s at 100 Hz
    lat = np.radians(log.metadata["lat_deg"])
    res = {m: al.align_increments(log.dtheta_b_rad[:n], log.dvel_b_mps[:n], 0.01, lat, method=m) for m in al.METHODS}
    header_heading = float(np.degrees(heading_from_yaw(np.radians(log.metadata["yaw_deg"]))))
    for m, (p, r, y) in res.items():
        heading = np.degrees(heading_from_yaw(y))
        # The header heading (90.6 deg) is "maybe inaccurate" and the vehicle
        # was disturbed: the 300 s gyrocompass lands at 83 deg; 10 deg bound.
        assert abs(heading - header_heading) < 10.0, m
        # Levelling of a navigation-grade IMU on a parked vehicle: within 2 deg of level.
        assert abs(np.degrees(p)) < 2 and abs(np.degrees(r)) < 2
    # Near level the three methods are the same estimator: they agree to 0.01 deg.
    h = [np.degrees(res[m][2]) for m in al.METHODS]
    assert np.ptp(h) < 0.01


def _rocking_increments(C0, lat, duration_s, dt=0.01, sub=8):
    """Exact-enough increments of a parked vehicle that rocks and slowly settles.

    Body rotation relative to the ground about the body Right axis:
    0.05 deg rocking with a 3 s period plus a 0.1 deg settling ramp, i.e. a
    mean rate of 3 deg/h, a fifth of the Earth rate. Increments integrate the
    rates at ``sub`` midpoints per sample (error ~1e-12 rad).
    """
    amp, period, ramp = np.radians(0.05), 3.0, np.radians(0.1) / duration_s
    w_n = OMEGA_E_RAD_PER_S * np.array([0.0, np.cos(lat), np.sin(lat)])
    n = int(round(duration_s / dt))
    t = (np.arange(n * sub) + 0.5) * dt / sub

    def Rx(a):
        c, s = np.cos(a), np.sin(a)
        z, o = np.zeros_like(a), np.ones_like(a)
        return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)

    ang = amp * np.sin(2 * np.pi * t / period) + ramp * t
    rate = amp * 2 * np.pi / period * np.cos(2 * np.pi * t / period) + ramp
    C_n_b = C0 @ Rx(ang)
    w_b = np.einsum("kji,j->ki", C_n_b, w_n) + rate[:, None] * [1.0, 0.0, 0.0]
    f_b = np.einsum("kji,j->ki", C_n_b, [0.0, 0.0, G])
    dtheta = w_b.reshape(n, sub, 3).sum(axis=1) * dt / sub
    dvel = f_b.reshape(n, sub, 3).sum(axis=1) * dt / sub
    T = n * dt
    return dtheta, dvel, C0 @ Rx(np.array(amp * np.sin(2 * np.pi * T / period) + ramp * T))


def test_inertial_alignment_is_immune_to_rocking():
    pitch, roll, heading = np.radians([2.0, -1.0, 250.0])
    C0 = euler_to_dcm(pitch, roll, -heading)
    dtheta, dvel, C_end = _rocking_increments(C0, LAT, 120.0)
    p_true, r_true, y_true = (float(a) for a in (np.arcsin(C_end[2, 1]), np.arctan2(-C_end[2, 0], C_end[2, 2]),
                                                 np.arctan2(-C_end[0, 1], C_end[1, 1])))
    p, r, y = al.align_increments(dtheta, dvel, 0.01, LAT, method="inertial", g_mps2=G)
    # Error-free sensors: only the per-sample rotation-vector integration
    # (1e-9 rad) and the fit remain; 0.01 deg bounds.
    assert np.degrees(abs(p - p_true)) < 0.01 and np.degrees(abs(r - r_true)) < 0.01
    assert np.degrees(abs(np.angle(np.exp(1j * (y - y_true))))) < 0.01
    # The mean-rate methods take the 3 deg/h settling for Earth rate: degrees of heading error.
    _, _, y2 = al.align_increments(dtheta, dvel, 0.01, LAT, method="2", g_mps2=G)
    assert np.degrees(abs(np.angle(np.exp(1j * (y2 - y_true))))) > 3.0


def test_psins_laser_gyro_windows_inertial_is_stable():
    from leosop.ins.imu_io import read_psins

    log = read_psins(data_path("gnss-ins", "psins_lasergyro", "lasergyro.imu"))
    lat = np.radians(log.metadata["lat_deg"])
    headings = {}
    for m in ("2", "inertial"):
        headings[m] = np.array([np.degrees(heading_from_yaw(al.align_increments(
            log.dtheta_b_rad[k:k + 6000], log.dvel_b_mps[k:k + 6000], 0.01, lat, method=m)[2]))
            for k in range(0, 30000, 6000)])  # five 60 s windows of the first 300 s
    # The vehicle settles by ~0.1 deg per minute (3 deg/h, a quarter of the
    # horizontal Earth rate): the mean-rate gyrocompass swings by tens of
    # degrees between windows (measured 38..108), the inertial-frame one stays
    # within a degree of the header's 90.6 deg (measured 89.8..90.9).
    assert np.ptp(headings["2"]) > 30.0
    assert np.ptp(headings["inertial"]) < 2.0
    assert np.all(np.abs(headings["inertial"] - 90.6) < 1.5)
