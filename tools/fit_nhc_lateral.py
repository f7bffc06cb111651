"""Fit the drive's lateral body velocity to the NHC's two terms: sensor offset and tyre slip.

The GNSS velocity of the Q = 1 fixes (speed over 2 m/s) is put in the
filter's body frame (Right-Forward-Up) of a run without outages, the epochs
of both bench schedules (15 s and 30 s, 1 s either side) excluded, and its
Right component is fitted by least squares as ``v_R = c_w w_up + c_a w_up v_F``
with ``w_up`` the filter's bias-corrected yaw rate: ``-c_w`` [m] is the
sensor's distance ahead of the vehicle's non-slipping point (a point ``d``
ahead of it moves sideways at ``-d w_up``), ``c_a`` [s] the outward slip per
lateral acceleration ``w_up v_F``. These are ``FuseOptions.nhc_offset_m`` and
``nhc_slip_s`` (docs/fusion-real.md).

Usage: ``python tools/fit_nhc_lateral.py [--data DIR] [--nhc-off]``.
"""

import argparse
from pathlib import Path

import numpy as np

import bench_fuse
from leosop.fusion import real
from leosop.gnss.rtklib_pos import read_pos
from leosop.ins import imu_io
from leosop.rotations import quat_to_dcm


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=bench_fuse.ROOT / "shared" / "data" / "gnss-ins")
    ap.add_argument("--nhc-off", action="store_true", help="the filter's attitude from a run without the NHC")
    args = ap.parse_args(argv)
    folder, _, stem, imu, mount, (f, r, d), offset, aids, start, end = bench_fuse.LOGS["drive"]
    sol = read_pos(args.data / folder / f"gnss_{stem}.pos")
    log = imu_io.read_rtklib_csv(args.data / folder / imu, C_b_s=imu_io.mount_C_b_s(*mount))
    opts = real.FuseOptions(spec=real.GRADES["consumer"], lever_arm_b_m=(r, f, -d),
                            **{**aids, "nhc": not args.nhc_off})
    res = real.fuse(log, sol, opts, imu_time_offset_s=offset).result
    t_g = sol.t_gpst_s - sol.t_gpst_s[0]
    excluded = np.zeros(t_g.size, dtype=bool)
    for length in bench_fuse.OUTAGE_LENGTHS_S:
        for s, dur in bench_fuse.schedule(t_g[-1], start, end, length):
            excluded |= (t_g >= s - 1.0) & (t_g < s + dur + 1.0)
    k = np.flatnonzero((sol.q == 1) & ~excluded & (t_g > res.t_s[0] + 5.0) & (t_g < res.t_s[-1]))
    i = np.searchsorted(res.t_s, t_g[k])
    C_n_b = np.stack([quat_to_dcm(q) for q in res.q_n_b[i]])
    vel_b = np.einsum("nji,nj->ni", C_n_b, sol.vel_enu_mps[k])
    w_up = res.omega_ib_b_rad_per_s[i, 2]
    fast = vel_b[:, 1] > 2.0
    A = np.stack([w_up[fast], w_up[fast] * vel_b[fast, 1]], axis=1)
    (c_w, c_a), *_ = np.linalg.lstsq(A, vel_b[fast, 0], rcond=None)
    resid = vel_b[fast, 0] - A @ (c_w, c_a)
    turning = np.abs(w_up[fast]) > np.radians(15.0)
    rms = np.sqrt(np.mean(np.square([vel_b[fast, 0][turning], resid[turning]]), axis=1))
    print(f"{fast.sum()} epochs: v_R = {c_w:+.3f} m x w_up {c_a:+.4f} s x w_up v_F; residual {resid.std():.3f} m/s "
          f"(lateral speed {vel_b[fast, 0].std():.3f} m/s RMS); over 15 deg/s ({turning.sum()}): lateral "
          f"{rms[0]:.3f}, residual {rms[1]:.3f} m/s")


if __name__ == "__main__":
    main()
