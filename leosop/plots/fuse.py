"""Figures of ``leosop fuse``: the track with the outages marked, outage errors with 3 sigma, bias estimates."""

import numpy as np

from ..frames import ecef_to_enu, geodetic_to_ecef
from .core import pyplot, save_png

__all__ = ["biases", "outage_errors", "track"]


def _enu(lat_deg, lon_deg, alt_m, lat0_deg, lon0_deg, alt0_m):
    d = geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), alt_m) \
        - geodetic_to_ecef(np.radians(lat0_deg), np.radians(lon0_deg), alt0_m)
    return ecef_to_enu(d, np.radians(lat0_deg), np.radians(lon0_deg))


def track(path, run, sol, title):
    """Fused antenna track (East/North from the first GNSS epoch), GNSS fixes, the fused track in outages in red."""
    plt = pyplot()
    ref = (sol.lat_deg[0], sol.lon_deg[0], sol.alt_m[0])
    fused = _enu(run.lat_deg, run.lon_deg, run.alt_m, *ref)
    gnss = _enu(sol.lat_deg, sol.lon_deg, sol.alt_m, *ref)
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.plot(gnss[~run.withheld, 0], gnss[~run.withheld, 1], ".", color="0.6", ms=2, label="GNSS used")
    ax.plot(gnss[run.withheld, 0], gnss[run.withheld, 1], "k.", ms=3, label="GNSS withheld (reference)")
    ax.plot(fused[:, 0], fused[:, 1], "C0-", lw=0.8, label="fused")
    dr = np.where(run.q == 7, fused[:, 1], np.nan)
    ax.plot(fused[:, 0], dr, "C3-", lw=1.5, label="fused in outage (dead reckoning)")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title)
    ax.legend(fontsize=8)
    save_png(fig, path)


def outage_errors(path, outages, title):
    """Horizontal error against the withheld fixes in each outage, with the filter's 3 sigma."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, o in enumerate(outages):
        if not o["n_ref"]:
            continue
        t = np.asarray(o["t_s"]) - o["start_s"]
        c = f"C{i % 10}"
        ax.plot(t, o["horiz_err_m"], "-", color=c, lw=1.2, label=f"{o['start_s']:g} s" if i < 12 else None)
        ax.plot(t, 3 * np.asarray(o["horiz_sigma_m"]), "--", color=c, lw=0.8)
    ax.set_xlabel("time since the outage began [s]")
    ax.set_ylabel("horizontal error [m]")
    ax.set_title(f"{title}: error (solid) and filter 3 sigma (dashed)")
    ax.grid(alpha=0.3)
    ax.legend(title="outage start", fontsize=7, ncol=2)
    save_png(fig, path)


def biases(path, res):
    """Estimated gyro [deg/s] and accelerometer [m/s^2] biases with 1 sigma, and the IMU time offset.

    Bias axes are the body's Right, Forward, Up.
    """
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True, height_ratios=(3, 3, 2))
    for ax, est, sig, scale, unit in ((axes[0], res.gyro_bias_rad_per_s, res.sigma[:, 9:12], np.degrees(1.0), "deg/s"),
                                      (axes[1], res.accel_bias_mps2, res.sigma[:, 12:15], 1.0, "m/s^2")):
        for k, name in enumerate("RFU"):
            ax.plot(res.t_s, est[:, k] * scale, f"C{k}-", lw=1, label=name)
            ax.fill_between(res.t_s, (est[:, k] - sig[:, k]) * scale, (est[:, k] + sig[:, k]) * scale,
                            color=f"C{k}", alpha=0.15, lw=0)
        ax.set_ylabel(f"bias [{unit}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[2].plot(res.t_s, -1e3 * res.time_offset_s, "k-", lw=1)
    axes[2].set_ylabel("IMU time offset\nestimate change [ms]")
    axes[2].grid(alpha=0.3)
    axes[2].set_xlabel("time since the first GNSS epoch [s]")
    axes[0].set_title("estimated IMU biases (shaded: 1 sigma)")
    save_png(fig, path)
