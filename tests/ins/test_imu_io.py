"""Real IMU log readers: real data against physics and GNSS, bad input, round trip."""

import numpy as np
import pytest

from leosop import earth
from leosop.errors import InputError
from leosop.ins import imu_io

from tests.helpers import data_path


def test_psins_laser_gyro_at_rest_senses_earth_rate_and_gravity():
    log = imu_io.read_psins(data_path("gnss-ins", "psins_lasergyro", "lasergyro.imu"))
    md = log.metadata
    assert (md["lat_deg"], md["lon_deg"], md["alt_m"], md["yaw_deg"]) == (34.246048, 108.909664, 380.0, -90.6)
    assert log.t_s.size == 184_718 and log.t_s[-1] == pytest.approx(1847.18) and log.rate_hz == pytest.approx(100.0)
    # First 300 s, mostly at rest: the mean specific force is gravity and the
    # up component of the mean rate is Omega sin L (8.47 deg/h). Tolerances: the
    # "disturbances" of the log and the laser gyro's bias (~0.2 deg/h here);
    # accelerometer bias and the tilt of a ground vehicle (< 0.02 m/s^2).
    lat = np.radians(md["lat_deg"])
    f = log.accel_mps2[:30_000].mean(axis=0)
    w = log.gyro_rad_per_s[:30_000].mean(axis=0)
    assert np.linalg.norm(f) == pytest.approx(earth.normal_gravity_mps2(lat, 380.0), abs=0.02)
    up = f / np.linalg.norm(f)
    assert np.degrees(w @ up) * 3600 == pytest.approx(np.degrees(earth.earth_rate_enu(lat)[2]) * 3600, abs=0.3)


def _pos_rows(path):
    rows = [line.split() for line in path.read_text().splitlines() if line and not line.startswith("%")]
    t = np.array([np.datetime64(r[0].replace("/", "-") + "T" + r[1], "us") for r in rows])
    return t, np.array([[float(r[15]), float(r[16])] for r in rows])


def test_rtklib_drive_axes_agree_with_the_rtk_velocity():
    folder = data_path("gnss-ins", "rtklibexplorer_drive_0708")
    log = imu_io.read_rtklib_csv(folder / "imu_1934.csv", C_b_s=imu_io.DRIVE_0708_C_B_S)
    assert log.epoch == "2025-07-08T19:34:21.854000Z GPST" and log.rate_hz == pytest.approx(100.0, rel=1e-3)
    t_gnss, vel_ne = _pos_rows(folder / "gnss_1934_sf.pos")
    t = (t_gnss - np.datetime64(log.epoch.split("Z")[0], "us")) / np.timedelta64(1, "s")
    speed = np.hypot(*vel_ne.T)
    course = np.unwrap(np.arctan2(vel_ne[:, 1], vel_ne[:, 0]))  # clockwise from North
    dt = np.diff(t)
    tt = np.concatenate([[0.0], log.t_s])
    ok = (speed[1:] > 3) & (speed[:-1] > 3) & (t[:-1] > 0.1) & (t[1:] < log.t_s[-1])

    def mean_over_gnss_intervals(incr):
        c = np.concatenate([np.zeros((1, 3)), np.cumsum(incr, axis=0)])
        at = np.stack([np.interp(t, tt, c[:, i]) for i in range(3)], axis=-1)
        return np.diff(at, axis=0) / dt[:, None]

    f = mean_over_gnss_intervals(log.dvel_b_mps)[ok]
    w = mean_over_gnss_intervals(log.dtheta_b_rad)[ok]
    along = (np.diff(speed) / dt)[ok]
    turn = (np.diff(course) / dt)[ok]
    # Right-Forward-Up: forward specific force follows d(speed)/dt, the up gyro
    # follows minus the course rate (counter-clockwise yaw), the right specific
    # force follows the centripetal v * course rate. Measured correlations 0.88,
    # 0.98, 0.95 and slopes 1.06, 0.96, 1.01 over 1800 moving epochs; a wrong
    # axis or sign would give ~0 or negative correlation. Thresholds leave room
    # for road slope, lever arm and MEMS noise.
    assert np.corrcoef(f[:, 1], along)[0, 1] > 0.8
    assert np.corrcoef(w[:, 2], -turn)[0, 1] > 0.95
    assert np.corrcoef(f[:, 0], speed[1:][ok] * turn)[0, 1] > 0.9
    assert np.polyfit(-turn, w[:, 2], 1)[0] == pytest.approx(1.0, abs=0.1)


def test_rtklib_walk_raw_and_converted_share_the_time_base():
    folder = data_path("gnss-ins", "rtklibexplorer_walk_0827")
    raw = imu_io.read_rtklib_csv(folder / "imu_1730.csv", C_b_s=imu_io.WALK_0827_C_B_S)
    conv = imu_io.read_rtklib_sf_csv(folder / "imu_1730_sf.csv", C_b_s=imu_io.WALK_0827_C_B_S)
    # The converted file's times are the repository's stretch of the same
    # ticks (printed to 0.1 us): both readers agree to 1 us.
    assert raw.epoch == conv.epoch
    assert raw.t_s.size == conv.t_s.size == 20_454
    np.testing.assert_allclose(raw.t_s, conv.t_s, atol=1e-6)
    # Up axis carries gravity at rest (raw 1e-3 g resolution, MEMS bias < 0.03 g).
    assert raw.accel_mps2[:100, 2].mean() == pytest.approx(9.9, abs=0.3)


def _write_psins(path, counts, dt_ms=10.0, quanta=(0.1, 0.1, 0.1, 125.0, 125.0, 125.0)):
    lines = ["% test", "", "1 2 -90 0 0 0", f"34 108 380 0 {dt_ms} 9.78", " ".join(map(str, quanta))]
    lines += [" ".join(str(int(c)) for c in row) for row in counts]
    path.write_text("\n".join(lines) + "\n")


def test_psins_round_trip(tmp_path):
    counts = np.random.default_rng(1).integers(-1000, 1000, (50, 6))
    _write_psins(tmp_path / "x.imu", counts)
    log = imu_io.read_psins(tmp_path / "x.imu")
    np.testing.assert_allclose(log.dtheta_b_rad, counts[:, :3] * np.radians(0.1 / 3600), rtol=1e-15)
    np.testing.assert_allclose(log.dvel_b_mps, counts[:, 3:] * 125e-6 * 9.78, rtol=1e-15)
    np.testing.assert_allclose(log.t_s, 0.01 * np.arange(1, 51), rtol=1e-15)
    assert log.metadata["roll_deg"] == 2.0


def test_bad_psins_input(tmp_path):
    p = tmp_path / "bad.imu"
    counts = [[0, 0, 0, 0, 0, 80]] * 5
    _write_psins(p, counts)
    p.write_text(p.read_text() + "1 2 3 4 5\n")
    with pytest.raises(InputError, match=r"bad\.imu:11: expected 6 values, got 5"):
        imu_io.read_psins(p)
    _write_psins(p, counts, dt_ms=0.0)
    with pytest.raises(InputError, match=r"bad\.imu:4: sampling interval"):
        imu_io.read_psins(p)


def test_bad_csv_input(tmp_path):
    p = tmp_path / "imu_sf.csv"
    rows = [[100.0 + 0.01 * k, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0] for k in range(20)]
    rows[7][0] = rows[6][0]  # duplicate time
    p.write_text("\n".join(",".join(map(str, r)) for r in rows))
    with pytest.raises(InputError, match=r"imu_sf\.csv:8: time"):
        imu_io.read_rtklib_sf_csv(p)
    rows[7][0] = 100.07
    rows[15:] = [[r[0] + 1.0] + r[1:] for r in rows[15:]]  # a 1 s gap
    p.write_text("\n".join(",".join(map(str, r)) for r in rows))
    with pytest.warns(UserWarning, match="gap"):
        log = imu_io.read_rtklib_sf_csv(p)
    assert log.metadata["gaps"] == [{"line": 16, "t_s": pytest.approx(1.15), "gap_s": pytest.approx(1.01)}]
    p.write_text("\n".join(",".join(map(str, [1e-6 * k] + r[1:])) for k, r in enumerate(rows)))
    with pytest.raises(InputError, match="sample rate"):
        imu_io.read_rtklib_sf_csv(p)
    raw = tmp_path / "imu.csv"
    raw.write_text("partial\n0,0,1,0,0,0,10\n0,0,1,0,0,10\n0,0,1,0,0,0,30\npart")
    with pytest.raises(InputError, match=r"imu\.csv:3: expected 7 values, got 6"):
        imu_io.read_rtklib_csv(raw)
    raw.write_text("partial\n0,0,1,0,0,0,10\n0,0,1,0,0,0,20\n0,0,1,0,0,0,30\npart")
    with pytest.raises(InputError, match="time-tag"):
        imu_io.read_rtklib_csv(raw)
