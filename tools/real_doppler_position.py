"""Doppler positioning on the real data sets in ../shared/data, with the errors against their truth.

    python tools/real_doppler_position.py [--data DIR] [--export DIR] [--windows 2,3,5] [--no-single]
        [--time-offset-model inertial|earth_fixed|both] [--no-all] [--doptrack-only]

DopTrack (Delfi-C3, 98 passes): one static fix per pass with the station
height known, no start given (the solver's own starts); error per pass and
the median. Then fixes from several passes (a transmitter frequency
polynomial per pass, position shared): all 98 passes, each day's passes, and
sliding windows of N consecutive passes; errors against the station, the
posterior sigma and their ratio; without the per-pass time offsets of the
satellite states (along-track errors of the element sets), then with them
(the default, prior TIME_OFFSET_SIGMA_S), shifting each pass's satellite
along its inertial orbit or with the Earth (``--time-offset-model``; ``both``
runs the two in turn). ``--windows ''``, ``--no-single``, ``--no-all`` (no
98-pass fix, itself > 10 min on a shared machine) and ``--doptrack-only``
shorten the run. FOX-1D: the trimmed pass with each candidate catalogue number.
GSDC: snapshot velocity, clock drift and position, and a static fix.
``--export DIR`` also writes each data set as a DESIGN 4.3 table (plus the
element sets) so that ``leosop position`` can be run on them.
"""

import argparse
import csv
from pathlib import Path

import numpy as np

from leosop.frames import C_e_n, ecef_to_enu, geodetic_to_ecef
from leosop.orbits import read_tle
from leosop.positioning.datasets import doptrack_table, read_doptrack, read_fll, read_gsdc
from leosop.positioning.measurements import write_measurements
from leosop.positioning.solve import position_snapshots, position_static, position_static_passes, satellite_states
from leosop.progress import progress

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FOX_SITE = (37.229976, -80.439627, 610.0)


def doptrack(data, export, windows=(2, 3, 5), single=True, models=("inertial",), all_passes=True):
    passes = read_doptrack(data / "leo-doppler" / "doptrack_delfi-c3_2020-04")
    if single:
        doptrack_single(passes, export)
    doptrack_passes(passes, windows, all_passes, time_bias=False)
    # A time offset per pass (along-track error of its element set, or a time-tag error), the default.
    for model in models:
        doptrack_passes(passes, windows, all_passes, time_offset_model=model)


def doptrack_single(passes, export):
    print("DopTrack Delfi-C3, static fix per pass, height known (95 m), no start given; cubic transmitter\n"
          "frequency, side of the ground track chosen with a linear one. mirror: the other side's solution,\n"
          "dchi2 = its chi-square minus the fix's on the rows the fix used (< 0: the mirror fits better)")
    print(f"{'pass':30s} {'maxel':>5s} {'rows':>5s} {'used':>5s} {'sigma':>6s} {'status':>13s} {'amb':>4s} "
          f"{'east_m':>10s} {'north_m':>10s} {'err_m':>10s} {'mirror_m':>10s} {'dchi2':>8s}")
    errors, mirrors, tca_lag = [], [], []
    for p in passes:
        tca_lag.append(_tca_lag_s(p))
        res = position_static(p.meas, constellation=p.constellation, alt_m=p.station_alt_m)
        f = res.fixes
        lat, lon = np.radians(p.station_lat_deg), np.radians(p.station_lon_deg)
        d = ecef_to_enu(f.pos_ecef_m - p.station_pos_ecef_m, lat, lon)
        errors.append(np.linalg.norm(d))
        mirrors.append(np.linalg.norm(f.mirror_pos_ecef_m - p.station_pos_ecef_m))
        print(f"{p.name:30s} {p.max_elevation_deg:5.0f} {len(p.meas):5d} {f.n_used:5d} {res.sigma_hz_default:6.2f} "
              f"{f.status.name:>13s} {str(f.ambiguous)[0]:>4s} {d[0]:10.0f} {d[1]:10.0f} {errors[-1]:10.0f} "
              f"{mirrors[-1]:10.0f} {f.mirror_chi2 - f.chi2:8.1f}")
        if export:
            write_measurements(export / "doptrack" / f"{p.name}.csv", p.meas)
            (export / "doptrack" / f"{p.name}.tle").write_text("\n".join(p.tle_lines) + "\n")
    e, em = np.array(errors), np.array(mirrors)
    ok = np.isfinite(e)
    either = np.fmin(e, em)
    print(f"median error {np.median(e[ok]):.0f} m over {ok.sum()} solved passes of {len(e)}; "
          f"{(e[ok] < 10e3).sum()} within 10 km, {(e[ok] < 100e3).sum()} within 100 km "
          f"(median of those {np.median(e[ok & (e < 100e3)]):.0f} m)")
    print(f"fix or its mirror: {(either < 10e3).sum()} within 10 km, {(either < 100e3).sum()} within 100 km")
    lag = np.array(tca_lag)
    q1, q2, q3 = np.nanpercentile(lag, [25, 50, 75])
    print(f"time tags: range rate at the station crosses zero {q2:+.2f} s after the files' tca "
          f"(median; quartiles {q1:+.2f}, {q3:+.2f} s; element sets and station as given)")


def fix_passes(passes, **kw):
    """Multi-pass static fix, height known, no start given; light time recomputed at the first fix.

    The second solve starts from the first fix and its mirror solution (so
    that an ambiguous fix stays flagged, with the mirror in its covariance);
    if it fails, the first fix stands. ``kw`` goes to position_static_passes
    (the time-bias options).
    """
    meas = doptrack_table(passes)
    first = position_static_passes(meas, meas.pass_id, alt_m=passes[0].station_alt_m, **kw).fixes
    if not np.isfinite(first.pos_ecef_m).all():
        return first
    starts = np.vstack([first.pos_ecef_m] + [first.mirror_pos_ecef_m] * bool(np.isfinite(first.mirror_chi2)))
    meas = doptrack_table(passes, first.pos_ecef_m)
    again = position_static_passes(meas, meas.pass_id, alt_m=passes[0].station_alt_m, init_pos_ecef_m=starts,
                                   **kw).fixes
    return again if np.isfinite(again.pos_ecef_m).all() else first


def _horizontal(fix, p):
    """Horizontal error against the station and its posterior sigma [m]."""
    lat, lon = np.radians(p.station_lat_deg), np.radians(p.station_lon_deg)
    d = ecef_to_enu(fix.pos_ecef_m - p.station_pos_ecef_m, lat, lon)
    C = C_e_n(lat, lon)
    cov_enu = C.T @ fix.cov[:3, :3] @ C
    return float(np.hypot(d[0], d[1])), float(np.sqrt(cov_enu[0, 0] + cov_enu[1, 1]))


def _nees_h(fix, p):
    """Horizontal normalised error squared against the station (chi-square with 2 dof when consistent)."""
    lat, lon = np.radians(p.station_lat_deg), np.radians(p.station_lon_deg)
    d = ecef_to_enu(fix.pos_ecef_m - p.station_pos_ecef_m, lat, lon)[:2]
    C = C_e_n(lat, lon)
    cov_en = (C.T @ fix.cov[:3, :3] @ C)[:2, :2]
    return float(d @ np.linalg.solve(cov_en, d)) if np.isfinite(cov_en).all() and np.isfinite(d).all() else np.nan


def doptrack_passes(passes, windows=(2, 3, 5), all_passes=True, **kw):
    """Multi-pass fixes of all passes, each day's and sliding windows; ``kw`` to position_static_passes."""
    print("\nDopTrack, several passes in one fix: a cubic transmitter frequency per pass, position shared, height\n"
          "known, starts on a grid around the sub-satellite centroid (no truth); sigma per pass from the\n"
          "residuals of a first joint fit. err_h: horizontal error, sig_h: posterior horizontal sigma. "
          f"Options: {kw or 'none'}")
    p0 = passes[0]
    if all_passes:
        fix = fix_passes(passes, **kw)
        err, sig = _horizontal(fix, p0)
        err_3d = np.linalg.norm(fix.pos_ecef_m - p0.station_pos_ecef_m)
        print(f"all {len(passes)} passes: err_h {err:.0f} m, 3-D {err_3d:.0f} m, sig_h {sig:.1f} m, "
              f"err/sig {err / sig:.1f}, NEES_h {_nees_h(fix, p0):.2f}, chi2/dof {fix.chi2 / fix.dof:.3f}, "
              f"{fix.status.name}, {fix.n_used}/{len(fix.used)} rows, ambiguous {fix.ambiguous}")
        if fix.time_bias_s is not None:
            q1, q2, q3 = np.percentile(fix.time_bias_s, [25, 50, 75])
            print(f"  time offsets per pass: median {q2:+.2f} s, quartiles {q1:+.2f}, {q3:+.2f} s")
    days = np.array([str(p.meas.time_utc[0])[:10] for p in passes])
    by_day = [[p for p, d in zip(passes, days) if d == day] for day in np.unique(days)]
    sets = [("each day", by_day)] + [(f"{n} in a row", [passes[k:k + n] for k in range(len(passes) - n + 1)])
                                     for n in windows]
    print(f"{'set':>12s} {'fixes':>5s} {'failed':>6s} {'passes':>6s} {'median_err_h':>12s} {'<10km':>6s} {'<5km':>5s} "
          f"{'median_sig_h':>12s} {'median_err/sig':>14s} {'err/sig<3':>9s} {'ambiguous':>9s} {'mean_NEES_h':>11s} "
          f"{'median_chi2/dof':>15s} {'median_|dt|_s':>13s}")
    for name, subsets in sets:
        fixes = [fix_passes(s, **kw) for s in progress(subsets, desc=name)]
        stats = np.array([(*_horizontal(f, p0), f.ambiguous, _nees_h(f, p0), f.chi2 / max(f.dof, 1),
                           np.median(np.abs(f.time_bias_s)) if f.time_bias_s is not None else np.nan)
                          for f in fixes])
        e, sg, amb, nees, chi2_dof, dt_abs = stats.T
        r = e / sg
        n_pass = np.array([len(x) for x in subsets])
        print(f"{name:>12s} {len(subsets):5d} {np.isnan(e).sum():6d} {n_pass.mean():6.1f} {np.nanmedian(e):12.0f} "
              f"{(e < 10e3).sum():6d} {(e < 5e3).sum():5d} {np.nanmedian(sg):12.1f} {np.nanmedian(r):14.1f} "
              f"{(r < 3).sum():9d} {int(amb.sum()):9d} {np.nanmean(nees):11.2f} {np.nanmedian(chi2_dof):15.3f} "
              f"{np.nanmedian(dt_abs):13.2f}")
        if name == "each day":
            for k in np.unique(n_pass):
                day = n_pass == k
                print(f"{'':>12s} days with {k} passes: {day.sum()}, median err_h {np.nanmedian(e[day]):.0f} m, "
                      f"median err/sig {np.nanmedian(r[day]):.1f}")


def _tca_lag_s(p):
    """Zero crossing of the element sets' range rate at the station minus the file's tca [s]."""
    pos, vel, reason, _ = satellite_states(p.meas, p.constellation, p.station_pos_ecef_m)
    ok = reason == ""
    los = pos[ok] - p.station_pos_ecef_m
    rate = np.einsum("ni,ni->n", los, vel[ok]) / np.linalg.norm(los, axis=-1)
    t = p.meas.t_s[ok]
    k = np.flatnonzero((rate[:-1] < 0) & (rate[1:] >= 0))
    if k.size == 0:
        return np.nan
    t_zero = t[k[0]] - rate[k[0]] * (t[k[0] + 1] - t[k[0]]) / (rate[k[0] + 1] - rate[k[0]])
    return t_zero - (p.tca_utc - p.meas.time_utc[0]).astype(np.int64) * 1e-9 - p.meas.t_s[0]


def fox1d(data, export):
    folder = data / "leo-doppler" / "fox1d_vtgs_2018-01-13"
    const = read_tle(folder / "pslv40_st.tle")
    site = geodetic_to_ecef(np.radians(FOX_SITE[0]), np.radians(FOX_SITE[1]), FOX_SITE[2])
    print("\nFOX-1D over VTGS, trimmed pass, static fix, height known (610 m)")
    for sat_id in ("43135", "43136", "43137"):
        meas = read_fll(folder / "DOPPLER_FOX-1D_20180113_161201.862011_UTC_10sps.csv", sat_id)
        res = position_static(meas, constellation=const, alt_m=FOX_SITE[2])
        d = ecef_to_enu(res.fixes.pos_ecef_m - site, np.radians(FOX_SITE[0]), np.radians(FOX_SITE[1]))
        print(f"  as {sat_id}: rms {res.fixes.residual_rms_hz:6.2f} Hz  status {res.fixes.status.name}  "
              f"ambiguous {res.fixes.ambiguous}  error E {d[0]:.0f} N {d[1]:.0f} m, {np.linalg.norm(d):.0f} m")
        if export:
            write_measurements(export / "fox1d" / f"fox1d_as_{sat_id}.csv", meas)
    if export:
        (export / "fox1d" / "pslv40_st.tle").write_bytes((folder / "pslv40_st.tle").read_bytes())


def gsdc(data, export):
    for sub in ("gsdc2022_2021-04-29_mtv", "gsdc2023_2023-09-07_pixel7pro"):
        folder = data / "gnss-raw" / sub
        g = read_gsdc(folder / "device_gnss.csv")
        with open(folder / "ground_truth.csv", newline="") as fh:
            gt = next(csv.DictReader(fh))
        lat, lon = np.radians(float(gt["LatitudeDegrees"])), np.radians(float(gt["LongitudeDegrees"]))
        truth = geodetic_to_ecef(lat, lon, float(gt["AltitudeMeters"]))
        res = position_snapshots(g.meas)
        f = res.fixes
        pos_err = np.linalg.norm(f.pos_ecef_m - truth, axis=-1)
        speed = np.linalg.norm(f.vel_ecef_mps, axis=-1)
        clock_err = f.clock_offset_hz - g.clock_drift_hz[res.rows[:, 0]]
        st = position_static(g.meas).fixes
        print(f"\nGSDC {sub}: {len(res.t_s)} epochs, {res.n_sats.min()}-{res.n_sats.max()} L1/E1 satellites, "
              f"GDOP {np.median(f.gdop):.0f}")
        print(f"  snapshot |velocity| (truth 0): median {np.median(speed):.3f} m/s, max {speed.max():.3f} m/s")
        print(f"  snapshot clock drift - phone's DriftNanosPerSecond: median |{np.median(np.abs(clock_err)):.2f}| Hz "
              f"= {np.median(np.abs(clock_err)) * 299792458 / 1575.42e6:.3f} m/s")
        print(f"  snapshot position error: median {np.median(pos_err):.0f} m, max {pos_err.max():.0f} m")
        print(f"  static fix over all epochs: error {np.linalg.norm(st.pos_ecef_m - truth):.0f} m, {st.status.name}")
        if export:
            write_measurements(export / "gsdc" / f"{sub}.csv", g.meas)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--export", type=Path, help="write DESIGN 4.3 tables here (outside the repository)")
    parser.add_argument("--windows", default="2,3,5", help="sliding windows of N passes (comma list, '' none)")
    parser.add_argument("--no-single", action="store_true", help="skip the single-pass DopTrack fixes")
    parser.add_argument("--no-all", action="store_true", help="skip the 98-pass DopTrack fixes")
    parser.add_argument("--time-offset-model", choices=("inertial", "earth_fixed", "both"), default="inertial",
                        help="what each pass's time offset shifts: the satellite along its inertial orbit (default), "
                             "with the Earth (a time tag), or both in turn")
    parser.add_argument("--doptrack-only", action="store_true", help="skip FOX-1D and GSDC")
    args = parser.parse_args()
    windows = tuple(int(w) for w in args.windows.split(",") if w.strip())
    models = ("inertial", "earth_fixed") if args.time_offset_model == "both" else (args.time_offset_model,)
    doptrack(args.data, args.export, windows, not args.no_single, models, not args.no_all)
    if not args.doptrack_only:
        fox1d(args.data, args.export)
        gsdc(args.data, args.export)


if __name__ == "__main__":
    main()
