"""Readers for ``leosop fuse``: RTKLIB .pos, the generic IMU CSV, the GNSS_IMU mounting convention.

References: the data's PROVENANCE.md counts, scipy's Euler rotations, the
mounting matrices derived independently in :mod:`leosop.ins.imu_io`, the
rtklibexplorer converted-CSV reader, write/read round trips.
"""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from leosop.errors import InputError
from leosop.gnss.rtklib_pos import PosSolution, read_pos, write_pos
from leosop.ins import imu_io

from tests.helpers import data_path

RFU_FROM_FRD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def test_mounting_matches_the_repositorys_stated_mountings_and_scipy():
    np.testing.assert_allclose(imu_io.mount_C_b_s(180, 0, 180), imu_io.DRIVE_0708_C_B_S, atol=1e-15)
    np.testing.assert_allclose(imu_io.mount_C_b_s(180, 0, -90), imu_io.WALK_0827_C_B_S, atol=1e-15)
    # Groves' Euler_to_CTM is the passive (transposed) yaw-pitch-roll rotation.
    r, p, y = 12.0, -6.79, 185.35
    C = Rotation.from_euler("ZYX", [y, p, r], degrees=True).as_matrix().T
    np.testing.assert_allclose(imu_io.mount_C_b_s(r, p, y), RFU_FROM_FRD @ C, atol=1e-15)


@pytest.mark.parametrize("folder, n, n_fix, n_float, first", [
    ("rtklibexplorer_drive_0708", 2197, 2189, 8, "2025-07-08T19:34:18.499"),
    ("rtklibexplorer_walk_0827", 536, 349, 187, "2025-08-28T17:30:39.749"),
])
def test_read_pos_real_files_match_provenance(folder, n, n_fix, n_float, first):
    path = next(data_path("gnss-ins", folder).glob("gnss_*_sf.pos"))
    sol = read_pos(path)
    assert sol.t_gpst_s.size == n and (sol.q == 1).sum() == n_fix and (sol.q == 2).sum() == n_float
    t0 = (np.datetime64(first, "ns") - np.datetime64("1970-01-01", "ns")) / np.timedelta64(1, "s")
    assert abs(sol.t_gpst_s[0] - t0) < 1e-6
    assert np.all(np.diff(sol.t_gpst_s) > 0) and sol.vel_enu_mps.shape == (n, 3)
    # RTK fixes: about 1 cm per axis (PROVENANCE); East and North on the diagonal's first two places.
    assert np.median(np.sqrt(sol.cov_enu_m2[sol.q == 1, 0, 0])) < 0.02


def _solution(n=5):
    rng = np.random.default_rng(3)
    A = rng.normal(0, 0.1, (n, 3, 3))
    cov = A @ np.swapaxes(A, 1, 2) + np.eye(3) * 1e-3
    return PosSolution(1.7e9 + np.arange(n) * 0.25, 40 + rng.normal(0, 1e-4, n), -105 + rng.normal(0, 1e-4, n),
                       1600 + rng.normal(0, 1, n), np.array([1, 2, 5, 7, 1])[:n], np.arange(n), cov,
                       rng.normal(0, 3, (n, 3)), cov * 0.01, "test")


def test_pos_round_trip(tmp_path):
    sol = _solution()
    write_pos(tmp_path / "a.pos", sol, comments=("made by a test",))
    back = read_pos(tmp_path / "a.pos")
    np.testing.assert_allclose(back.t_gpst_s, sol.t_gpst_s, atol=5e-4)  # written to the millisecond
    np.testing.assert_allclose(back.lat_deg, sol.lat_deg, atol=1e-9)  # 9 decimals = 0.1 mm
    np.testing.assert_allclose(back.alt_m, sol.alt_m, atol=1e-4)
    np.testing.assert_array_equal(back.q, sol.q)
    np.testing.assert_allclose(back.vel_enu_mps, sol.vel_enu_mps, atol=1e-5)
    # Sigmas written to 0.1 mm; covariances through RTKLIB's signed square roots.
    np.testing.assert_allclose(back.cov_enu_m2, sol.cov_enu_m2, atol=2e-4 * np.sqrt(np.abs(sol.cov_enu_m2)).max())


@pytest.mark.parametrize("text, message", [
    ("% x-ecef(m) y-ecef(m)\n2025/01/01 00:00:00.000 1 2 3 1 5 0 0 0 0 0 0 0 0\n", "ECEF or ENU"),
    ("%  UTC  latitude(deg)\n2025/01/01 00:00:00.000 40 -105 1600 1 5 0 0 0 0 0 0 0 0\n", "GPST"),
    ("2025/01/01 00:00:00.000 40 -105 1600 1 5 0 0\n", ":1: 9 fields"),
    ("2025/01/01 00:00:01.000 40 -105 1600 1 5 0 0 0 0 0 0 0 0\n"
     "2025/01/01 00:00:00.000 40 -105 1600 1 5 0 0 0 0 0 0 0 0\n", ":2: time is not after"),
    ("2025/01/01 00:00:00.000 40 -105 1600 9 5 0 0 0 0 0 0 0 0\n", "Q=9"),
    ("2025/01/01 00:00:00.000 40 -105 x 1 5 0 0 0 0 0 0 0 0\n", "non-numeric"),
])
def test_read_pos_bad_input_names_file_and_line(tmp_path, text, message):
    p = tmp_path / "bad.pos"
    p.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        read_pos(p)
    assert str(p) in str(err.value) and "\n" not in str(err.value)


def test_generic_csv_matches_converted_reader_on_real_walk():
    path = data_path("gnss-ins", "rtklibexplorer_walk_0827", "imu_1730_sf.csv")
    a = imu_io.read_rtklib_sf_csv(path, C_b_s=imu_io.WALK_0827_C_B_S)
    cols = dict(t_gpst_s=0, ax_g=1, ay_g=2, az_g=3, gx_rad_per_s=4, gy_rad_per_s=5, gz_rad_per_s=6)
    b = imu_io.read_csv_columns(path, cols, C_b_s=imu_io.WALK_0827_C_B_S)
    assert a.epoch == b.epoch and a.epoch_gpst_s == b.epoch_gpst_s
    np.testing.assert_array_equal(a.dtheta_b_rad, b.dtheta_b_rad)
    np.testing.assert_array_equal(a.dvel_b_mps, b.dvel_b_mps)


def test_generic_csv_units_and_columns(tmp_path):
    p = tmp_path / "imu.csv"
    rows = [f"{1.7e9 + 0.01 * k:.2f};0;1;0;0;90;0;extra" for k in range(4)]
    p.write_text("time;a;b;c;d;e;f;g\n" + "\n".join(rows) + "\n")
    cols = dict(t_gpst_s=0, ay_g=1, ax_g=2, az_g=3, gx_deg_per_s=4, gz_deg_per_s=5, gy_deg_per_s=6)
    log = imu_io.read_csv_columns(p, cols, delimiter=";", skip_rows=1)
    np.testing.assert_allclose(log.accel_mps2[0], [9.80665, 0, 0])  # ax_g is column 2
    np.testing.assert_allclose(log.gyro_rad_per_s[0], [0, 0, math.pi / 2])  # gz_deg_per_s is column 5
    assert log.epoch.endswith("Z GPST")
    with pytest.raises(InputError, match="exactly one g._\\* column|exactly one gy"):
        imu_io.read_csv_columns(p, {**cols, "gy_rad_per_s": 7}, delimiter=";", skip_rows=1)
    with pytest.raises(InputError, match="unknown IMU column"):
        imu_io.read_csv_columns(p, {**cols, "speed": 7}, delimiter=";", skip_rows=1)
    with pytest.raises(InputError, match=r"imu.csv:1: non-numeric"):
        imu_io.read_csv_columns(p, cols, delimiter=";")
