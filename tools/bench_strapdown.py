"""Benchmark: the 782 s Xi'an-Baoji flight at 100 Hz through the strapdown.

Times leosop.ins.strapdown.integrate (plain-float loop) next to a baseline in
the same run: the same two-sample algorithm written the naive way, one update
per step on numpy 3-vectors with the vectorised leosop.earth and
leosop.rotations functions. Prints both times, the speed ratio, their
agreement and the error against the truth.

    python tools/bench_strapdown.py
"""

import time

import numpy as np

from leosop import earth, frames
from leosop.ins import strapdown, trajectory
from leosop.rotations import quat_multiply, quat_normalize, quat_to_dcm, rotvec_to_quat


def naive_integrate(state0, dtheta, dvel, dt):
    """Two-sample strapdown, one numpy-on-3-vectors update per step (the baseline)."""
    lat, lon, h = state0.lat_rad, state0.lon_rad, state0.alt_m
    v, q = state0.vel_enu_mps.copy(), state0.q_n_b.copy()
    T = 2 * dt
    out = [np.concatenate([[lat, lon, h], v, q])]
    for k in range(0, dtheta.shape[0] - 1, 2):
        th1, th2, dv1, dv2 = dtheta[k], dtheta[k + 1], dvel[k], dvel[k + 1]
        th, dv = th1 + th2, dv1 + dv2
        phi = th + 2 / 3 * np.cross(th1, th2)
        rot = np.cross(th, dv)
        dvb = dv + 0.5 * rot + np.cross(th, rot) / 6 + 2 / 3 * (np.cross(th1, dv2) + np.cross(dv1, th2))
        s = quat_to_dcm(q) @ dvb
        R_M, R_N = earth.radii_m(lat)
        w_c = 2 * earth.earth_rate_enu(lat) + earth.transport_rate_enu(lat, h, v)
        g = earth.gravity_enu_mps2(lat, h)
        v_mid = v + 0.5 * s + 0.5 * T * (g - np.cross(w_c, v))
        lat_mid, h_mid = lat + 0.5 * T * v[1] / (R_M + h), h + 0.5 * T * v[2]
        R_M, R_N = earth.radii_m(lat_mid)
        w_ie = earth.earth_rate_enu(lat_mid)
        w_en = earth.transport_rate_enu(lat_mid, h_mid, v_mid)
        w_in = w_ie + w_en
        g = earth.gravity_enu_mps2(lat_mid, h_mid)
        v1 = v + s - 0.5 * T * np.cross(w_in, s) + T * (g - np.cross(2 * w_ie + w_en, v_mid))
        lat = lat + 0.5 * T * (v[1] + v1[1]) / (R_M + h_mid)
        lon = lon + 0.5 * T * (v[0] + v1[0]) / ((R_N + h_mid) * np.cos(lat_mid))
        h = h + 0.5 * T * (v[2] + v1[2])
        q = quat_normalize(quat_multiply(rotvec_to_quat(-w_in * T), quat_multiply(q, rotvec_to_quat(phi))))
        v = v1
        out.append(np.concatenate([[lat, lon, h], v, q]))
    return np.array(out)


def main():
    tr = trajectory.xian_baoji()
    s0 = strapdown.NavState.from_dcm(tr.lat_rad[0], tr.lon_rad[0], tr.alt_m[0], tr.vel_enu_mps[0], tr.C_n_b[0])
    t0 = time.perf_counter()
    hist = strapdown.integrate(s0, tr.dtheta_b_rad, tr.dvel_b_mps, tr.dt_s)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    base = naive_integrate(s0, tr.dtheta_b_rad, tr.dvel_b_mps, tr.dt_s)
    t_base = time.perf_counter() - t0
    ours = np.column_stack([hist.lat_rad, hist.lon_rad, hist.alt_m, hist.vel_enu_mps, hist.q_n_b])
    d_pos = np.linalg.norm(frames.geodetic_to_ecef(*ours[:, :3].T) - frames.geodetic_to_ecef(*base[:, :3].T), axis=1)
    ref = tr.at(hist.t_s)
    err_pos = np.linalg.norm(frames.geodetic_to_ecef(hist.lat_rad, hist.lon_rad, hist.alt_m) - ref.pos_ecef_m, axis=1)
    err_vel = np.linalg.norm(hist.vel_enu_mps - ref.vel_enu_mps, axis=1)
    n = hist.t_s.size - 1
    print(f"Xi'an-Baoji, {tr.t_s[-1]:.0f} s at 100 Hz, {n} two-sample updates (50 Hz)")
    print(f"  leosop.ins.strapdown.integrate (float loop): {t_ours:8.3f} s  ({1e6 * t_ours / n:5.1f} us/update)")
    print(f"  baseline, same algorithm on numpy 3-vectors: {t_base:8.3f} s  ({1e6 * t_base / n:5.1f} us/update)")
    print(f"  speed-up: {t_base / t_ours:.1f}x")
    print(f"  max |ours - baseline| position: {d_pos.max():.2e} m")
    print(f"  error vs truth at 782 s: position {err_pos[-1]:.2e} m, velocity {err_vel[-1]:.2e} m/s")


if __name__ == "__main__":
    main()
