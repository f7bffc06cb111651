"""Static Doppler fix of the Starlink replay case with and without per-satellite orbit-error states.

    python tools/bench_static_time_offset.py [--seeds 20] [--tle FILE]

Seven real Starlink satellites (SGP4 from the 2026-04-08 snapshot) above
25 deg over a site for 150 s, one pilot Doppler per satellite per second,
sigma the comb's CRLB for a 20 ms block at 2.5 MS/s and 45 dB-Hz
(:func:`leosop.signal.error_model.doppler_sigma_hz`). Truth per seed: each
satellite's orbit is its element set shifted in time by ``dt_s ~ N(0,
(300 m / v)^2)`` (an along-track error of ~300 m), each satellite has its own
frequency offset ``~ U(-5, 5) Hz`` ([Shen 2024] Table 1), the receiver a
frequency offset and drift. All estimators use the common-clock model
(receiver offset + drift, per-satellite offsets with the 5 Hz prior) from a
start 2 km off, no height constraint:

(a) the element sets' states, no orbit-error states;
(b) the same with a time offset per satellite (the default, 0.5 s prior);
(c) the truth orbits (ideal: it knows the orbit errors), no orbit-error states;
(d) (b) with a free cubic per satellite instead of the common clock (the
    ``per_pass`` model).

Prints the median and RMS 3-D and horizontal errors, the mean NEES of the
position (3 for a consistent covariance) and the run time per fix. Light
time is left out of truth and model alike (it does not change the
comparison).
"""

import argparse
import time
from pathlib import Path

import numpy as np

from leosop.constants import C_MPS
from leosop.constellations import REGISTRY
from leosop.frames import C_e_n, azimuth_elevation_range, geodetic_to_ecef
from leosop.orbits import read_tle
from leosop.orbits.propagate import state_ecef
from leosop.positioning.static_passes import solve_static_passes
from leosop.signal.error_model import doppler_sigma_hz

TLE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "tle" / "starlink_3le_2026-04-08_Bochika.txt"
LAT_DEG, LON_DEG, ALT_M = 42.7, 23.3, 550.0
T0 = np.datetime64("2026-04-08T06:00:00")
N_EPOCHS, N_SATS, MIN_EL_DEG = 150, 7, 25.0
ALONG_TRACK_SIGMA_M = 300.0
SAT_OFFSET_HZ = 5.0
CN0_DBHZ, BLOCK_S = 45.0, 0.02


def scene(tle_path):
    """The 7 satellites above MIN_EL_DEG for the whole window: constellation subset and the site."""
    const = read_tle(tle_path, skip_bad=True)
    site = geodetic_to_ecef(np.radians(LAT_DEG), np.radians(LON_DEG), ALT_M)
    t = T0 + np.arange(N_EPOCHS).astype("timedelta64[s]")
    pos, _, status = state_ecef(const, t[[0, -1]])
    _, el, _ = azimuth_elevation_range(pos, site)
    up = np.flatnonzero((el.min(-1) > np.radians(MIN_EL_DEG)) & (status == 0).all(-1))
    pick = np.random.default_rng(0).choice(up, N_SATS, replace=False)
    return const.subset(np.sort(pick)), site, t


def doppler(pos, vel, site):
    """Geometric pilot Doppler (n_sats, n_ep) of a receiver at rest at ``site``."""
    los = pos - site
    return -np.sum(los * vel, -1) / np.linalg.norm(los, axis=-1) * REGISTRY["starlink"].carrier_hz / C_MPS


def trial(const, site, t, rng, sigma_hz):
    """One seed: returns the estimators' position errors (4, 3) and covariances (4, 3, 3) and times (4,)."""
    t_s = (t - t[0]) / np.timedelta64(1, "s")
    pos_tle, vel_tle, _ = state_ecef(const, t)
    speed = np.linalg.norm(vel_tle, axis=-1).mean()
    dt_true = rng.normal(0.0, ALONG_TRACK_SIGMA_M / speed, N_SATS)
    shifted = [state_ecef(const.subset([k]), t + np.round(dt_true[k] * 1e9).astype("timedelta64[ns]"))
               for k in range(N_SATS)]
    pos_true = np.concatenate([s[0] for s in shifted])
    vel_true = np.concatenate([s[1] for s in shifted])
    sat_hz = rng.uniform(-SAT_OFFSET_HZ, SAT_OFFSET_HZ, N_SATS)
    rx_hz = rng.normal(0.0, 2e3) + rng.normal(0.0, 1.0) * (t_s - t_s.mean())
    y = doppler(pos_true, vel_true, site) + sat_hz[:, None] + rx_hz + rng.normal(0.0, sigma_hz, (N_SATS, N_EPOCHS))
    sat = np.repeat(np.arange(N_SATS), N_EPOCHS)
    start = site + C_e_n(np.radians(LAT_DEG), np.radians(LON_DEG)) @ np.array([1.5e3, -1.3e3, 0.0])
    args = (y.ravel(), sigma_hz)
    common = dict(t_s=np.tile(t_s, N_SATS), pass_id=sat, pos0_ecef_m=start, carrier_hz=REGISTRY["starlink"].carrier_hz)
    runs = [(pos_tle, vel_tle, dict(clock="common", time_bias=False)),
            (pos_tle, vel_tle, dict(clock="common")),
            (pos_true, vel_true, dict(clock="common", time_bias=False)),
            (pos_tle, vel_tle, dict(clock="per_pass"))]
    err, cov, secs = np.full((4, 3), np.nan), np.full((4, 3, 3), np.nan), np.zeros(4)
    for k, (p, v, kw) in enumerate(runs):
        tic = time.perf_counter()
        fix = solve_static_passes(*args, p.reshape(-1, 3), v.reshape(-1, 3), **common, **kw)
        secs[k] = time.perf_counter() - tic
        err[k], cov[k] = fix.pos_ecef_m - site, fix.cov[:3, :3]
    return err, cov, secs


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--tle", type=Path, default=TLE)
    args = parser.parse_args()
    const, site, t = scene(args.tle)
    sigma_hz = float(doppler_sigma_hz(CN0_DBHZ, BLOCK_S))
    print(f"{N_SATS} Starlink satellites above {MIN_EL_DEG:.0f} deg at ({LAT_DEG}, {LON_DEG}) from {T0}, "
          f"{N_EPOCHS} x 1 s; sigma {sigma_hz:.3f} Hz ({CN0_DBHZ:.0f} dB-Hz, {BLOCK_S * 1e3:.0f} ms); "
          f"along-track errors {ALONG_TRACK_SIGMA_M:.0f} m rms, satellite offsets U(+-{SAT_OFFSET_HZ:.0f}) Hz; "
          f"{args.seeds} seeds")
    out = [trial(const, site, t, np.random.default_rng(seed), sigma_hz) for seed in range(args.seeds)]
    err = np.array([o[0] for o in out])
    cov = np.array([o[1] for o in out])
    secs = np.array([o[2] for o in out])
    C = C_e_n(np.radians(LAT_DEG), np.radians(LON_DEG))
    enu = err @ C
    names = ["(a) no orbit-error states", "(b) time offset per sat", "(c) truth orbits (ideal)",
             "(d) (b), cubic per sat"]
    print(f"{'estimator':28s} {'med_3d_m':>9s} {'rms_3d_m':>9s} {'med_h_m':>8s} {'rms_h_m':>8s} {'sig_3d_m':>9s} "
          f"{'NEES':>7s} {'ms/fix':>7s}")
    for k, name in enumerate(names):
        e3, eh = np.linalg.norm(err[:, k], axis=-1), np.linalg.norm(enu[:, k, :2], axis=-1)
        nees = np.einsum("si,sij,sj->s", err[:, k], np.linalg.inv(cov[:, k]), err[:, k])
        sig3 = np.sqrt(np.trace(cov[:, k], axis1=-2, axis2=-1))
        print(f"{name:28s} {np.median(e3):9.2f} {np.sqrt(np.mean(e3**2)):9.2f} {np.median(eh):8.2f} "
              f"{np.sqrt(np.mean(eh**2)):8.2f} {np.median(sig3):9.2f} {np.mean(nees):7.2f} "
              f"{1e3 * np.median(secs[:, k]):7.0f}")
    print("NEES: mean of e^T P^-1 e over the seeds (3 when the covariance is consistent).")


if __name__ == "__main__":
    main()
