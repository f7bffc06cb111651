"""Identification and fix against the receiver's LO offset and drift (issue 26).

For each LO offset and drift and each recording kind (snapshot: 20 ms every
second; continuous), one recording is generated at one site per seed (``--seeds``;
the satellites, noise and orbit errors the same across offsets), with
``--front-end`` the generator's preset (``consumer``: 8 bits, phase noise,
IQ imbalance, DC, a CW line; its own offset and drift replaced by the
sweep's), and replayed with ``--init`` 100 km off and without it (global
search), with ``--lo-offset-max-hz`` 100 kHz (PLL LNBs) up to 50 kHz and
3 MHz (the wide mode) beyond. The clean recording (no offset, drift or
front end) is always replayed first. Reported per run:

- tracks, how many are true (a satellite's truth Doppler from the SigMF
  annotations within 20 Hz of the track, median over its blocks), how many
  identified, and how many identified wrongly (the named satellite's truth
  is not within 20 Hz); satellites with a true track (``sats``) and those
  identified (``s_id``: a fragment of a satellite's track is ``duplicate``
  when a longer track of it is identified);
- the static fix's horizontal and 3-D error, its 3-D sigma (``sig3d_m``,
  from the fix's covariance: the error to judge it by, as the recordings
  share their satellites' orbit errors and a few metres of ratio to the
  clean one say little) and its ratio to the same kind's clean recording
  with the same search (``x_zero``); ``dsig3d_m``: the 3-D sigma of the
  data-only fix (as ``crb_hz`` below), the one the error should be measured
  against on these recordings, which lack the element sets' radial and
  cross-track error;
- ``img``: tracks that are no satellite's but mirror one about 0 Hz (an IQ
  imbalance's image of its comb at minus its Doppler, within 20 Hz);
- ``lw_hz``: the LO's Wiener linewidth the replay found in the fix's
  residuals (:func:`leosop.replay.lo.lo_noise`; the preset's is 0.01 Hz);
- the estimated offset and drift minus the truth. The truth offset is the
  receiver's plus the mean of the identified satellites' own offsets (drawn
  in [0, 5] Hz): nothing separates that mean from the receiver's offset
  (:mod:`leosop.replay.lo`). ``sig_hz`` is the replay's sigma of that sum.
  It includes the element sets' radial and cross-track error at their age
  (:mod:`leosop.orbits.accuracy`, ~20-25 Hz at 0.8 days), which the
  recordings lack unless ``--impair`` adds it (``--orbit-error-radial-m``,
  ``--orbit-error-cross-m``); ``crb_hz`` is the sigma of the same sum from
  the data alone (the fix solved again without that error and without the
  passes' disagreement priced in: the Cramer-Rao bound of this geometry),
  the one the error should be measured against on recordings without it.
  ``d_w_hz`` and ``crb_w_hz``: the same from the data-only fix, but with the
  satellites' offsets weighted for the least variance of the sum instead of
  averaged (:func:`_min_variance_weights`; truth weighted alike): what a
  well-determined satellite's offset, known through its long track, is worth
  against a short track's, known only through the offset prior.

``--impair "OPTIONS"`` (repeatable) adds a run per string of generator
options at zero offset and drift (an interferer or IQ-imbalance sweep:
``--impair "--cw 150e3 70" --impair "--iq-gain-db 2 --iq-phase-deg 10"``).

``--duration-s`` sets a snapshot recording's length (default 60 s; the
offset's bound falls with it, docs/replay.md "What 1 Hz takes").

``--seeds S [S ...]`` (default 7) generates every recording once per
generator seed (the satellites' noise, orbit errors and own offsets drawn
anew; each seed's clean twin with the same seed, ``x_zero`` against it)
and, with more than one, ends with a summary per case over the seeds:
seeds with every tracked satellite identified (``all_id``) and wrong
identities (``wrong``); the fix error's ratio to its own seed's clean twin
(``x_med``, median) and the ratio of the RMS errors over the seeds
(``x_rms``, the less noisy measure), with ``xsig_rms`` the same ratio of
the data-only 3-D sigmas ``dsig3d_m`` (what the impaired fix's model gives
up) and ``nees`` the mean of (error / ``dsig3d_m``)^2 (1 when the sigma
covers the error: ``dsig3d_m^2`` is the trace of the position covariance,
the error's expected square); the fractions of
seeds with the offset within 1 Hz (``off<1Hz``) and the drift within
0.05 Hz/s (``dr<.05``); ``z2_off``, the mean of (offset error / ``crb_hz``)^2
(1 if the bound holds), and ``rms_off_hz``. ``--rows FILE`` appends every
run's numbers to FILE as JSON lines; ``--summarise FILE [FILE ...]`` prints
the summary of such files and runs nothing (runs split over processes by
seed, then summarised together).

Usage: python tools/bench_lo_offset.py [--kinds snapshot continuous] [--offsets 0 5e3 ...]
       [--drifts 0 25 50] [--front-end consumer] [--impair "OPTIONS" ...] [--no-global] [--workdir DIR]
       [--duration-s 120] [--seeds 7 8 9 10] [--rows FILE] [--summarise FILE ...]
"""

import argparse
import json
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from leosop.cli.position import solutions_doc
from leosop.frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef
from leosop.orbits import load_constellation
from leosop.positioning.solve import satellite_states
from leosop.positioning.static_passes import solve_static_passes
from leosop.replay.lo import common_offset_sigma_hz
from leosop.replay.pipeline import replay
from leosop.signal.frontend import PRESETS, wiener_doppler_sigma_hz
from leosop.signal.iq import open_sigmf

SITE = (48.137, 11.575, 520.0)
START = "2025-01-01T19:40:00Z"
#: 4 MS/s: a comb at 1 MHz offset with 300 kHz of Doppler (+-176 kHz of tones) stays in the band.
SAMPLE_RATE_HZ = 4e6
#: Generator options per kind besides the length (``--duration-s``, ``--continuous-s``).
KINDS = {
    "snapshot": ["--snapshot-s", "0.02", "--period-s", "1"],
    "continuous": [],
}
#: A snapshot recording's default length [s].
SNAPSHOT_S = 60.0
#: A track is a satellite's when its truth Doppler is this close (median over the blocks) [Hz].
MATCH_HZ = 20.0


def generate(path, kind, offset_hz, drift_hz_per_s, front_end, impair="", mask_deg=25.0, continuous_s=12.0,
             snapshot_s=SNAPSHOT_S, seed=7):
    span = ["--duration-s", f"{continuous_s if kind == 'continuous' else snapshot_s:g}", *KINDS[kind]]
    cmd = [sys.executable, "-m", "leosop", "generate", "-o", str(path), "--site", ",".join(map(str, SITE)),
           "--start", START, "--sample-rate-hz", str(SAMPLE_RATE_HZ), "--mask-deg", f"{mask_deg:g}",
           "--seed", str(seed), "--orbit-error-along-m", "300", "--rx-offset-hz", str(offset_hz), "--rx-drift-hz-per-s",
           str(drift_hz_per_s), "--front-end", front_end, *span, *shlex.split(impair)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def truth(meta_path):
    """Per satellite: annotation times and Doppler, and its own offset (clock offset minus the receiver's)."""
    meta = json.loads(Path(meta_path).read_text())
    sats = meta["global"]["leosop:satellites"]
    sats = json.loads(sats.replace("'", '"')) if isinstance(sats, str) else sats
    curves = {}
    for a in meta["annotations"]:
        curves.setdefault(a["leosop:sat_id"], []).append((a["leosop:t_s"], a["leosop:doppler_hz"]))
    curves = {k: np.array(sorted(v)) for k, v in curves.items()}
    clock = {s["sat_id"]: s["clock_offset_hz"] for s in sats}
    return curves, clock


def score(res, curves):
    """(true tracks, identified true tracks, wrong identities, satellites tracked, satellites identified, images).

    A satellite is tracked when one of its tracks is true, identified when one of its tracks is
    identified rightly (a fragment of a satellite's track is ``duplicate`` when the longer one has it).
    An image is a track that is no satellite's but follows minus one's Doppler.
    """
    n_true = n_ok = n_wrong = n_image = 0
    tracked, named = set(), set()
    for tr in res.tracks:
        err = {sid: np.median(np.abs(np.interp(tr.t_s, c[:, 0], c[:, 1]) - tr.doppler_hz)) for sid, c in curves.items()}
        best = min(err, key=err.get)
        real = err[best] < MATCH_HZ
        n_true += real
        n_image += not real and min(np.median(np.abs(np.interp(tr.t_s, c[:, 0], c[:, 1]) + tr.doppler_hz))
                                    for c in curves.values()) < MATCH_HZ
        if real:
            tracked.add(best)
        if tr.sat_id is not None:
            right = err.get(tr.sat_id, np.inf) < MATCH_HZ
            n_ok += right
            n_wrong += not right
            if right:
                named.add(tr.sat_id)
    return n_true, n_ok, n_wrong, len(tracked), len(named), n_image


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    ap.add_argument("--offsets", nargs="+", type=float, default=[0.0, 5e3, 50e3, 500e3, 1e6])
    ap.add_argument("--drifts", nargs="+", type=float, default=[0.0])
    ap.add_argument("--front-end", default="none", choices=("none", *PRESETS),
                    help="the generator's front-end preset (its offset and drift replaced by the sweep's)")
    ap.add_argument("--impair", action="append", default=[], metavar="OPTIONS",
                    help="generator options of one more run at zero offset and drift (repeatable)")
    ap.add_argument("--mask-deg", type=float, default=25.0, help="the generator's elevation mask (default 25)")
    ap.add_argument("--continuous-s", type=float, default=12.0, help="length of a continuous recording (default 12)")
    ap.add_argument("--duration-s", type=float, default=SNAPSHOT_S,
                    help=f"length of a snapshot recording (default {SNAPSHOT_S:g})")
    ap.add_argument("--seeds", nargs="+", type=int, default=[7], help="the generator's seeds (default 7)")
    ap.add_argument("--no-global", action="store_true", help="only with --init 100 km off")
    ap.add_argument("--workdir", help="keep the recordings here (default a temporary directory)")
    ap.add_argument("--rows", help="append every run's numbers to this file (JSON lines)")
    ap.add_argument("--summarise", nargs="+", metavar="FILE", help="print the summary of --rows files, run nothing")
    args = ap.parse_args(argv)
    if args.summarise:
        print_summary([json.loads(line) for f in args.summarise for line in Path(f).read_text().splitlines()])
        return
    const = load_constellation()
    lat, lon = np.radians(SITE[0]), np.radians(SITE[1])
    site = geodetic_to_ecef(lat, lon, SITE[2])
    prior = site + C_e_n(lat, lon) @ np.array([70.7e3, 70.7e3, 0.0])  # 100 km north-east
    searches = [("init", prior)] + ([] if args.no_global else [("global", None)])
    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench_lo_"))
    work.mkdir(parents=True, exist_ok=True)
    # The clean recording (no offset, drift or front end) first: every fix error is compared with its.
    runs = [(0.0, 0.0, "none", "")] + [(o, d, args.front_end, "") for d in args.drifts for o in args.offsets
                                       if (o, d, args.front_end) != (0.0, 0.0, "none")]
    runs += [(0.0, 0.0, "none", imp) for imp in args.impair]
    print(f"{'kind':10} {'fe':8} {'offset_hz':>9} {'drift':>5} {'search':6} {'lo_max':>7} {'tracks':>6} {'true':>4} "
          f"{'id':>3} {'wrong':>5} {'img':>3} {'sats':>4} {'s_id':>4} {'horiz_m':>8} {'err3d_m':>8} {'sig3d_m':>8} "
          f"{'dsig3d_m':>8} "
          f"{'x_zero':>6} {'d_off_hz':>8} {'sig_hz':>6} {'crb_hz':>7} {'d_w_hz':>6} {'crb_w_hz':>8} "
          f"{'d_drift':>8} {'sig':>6} {'lw_hz':>6} {'status':8} {'t_s':>5} {'seed':>4}")
    base, rows = {}, []
    for seed in args.seeds:
        for kind in args.kinds:
            for offset, drift, fe, impair in runs:
                tag = re.sub(r"[^0-9A-Za-z.+-]+", "_", impair.replace("--", "")).strip("_")
                span = f"_{args.duration_s:g}s" if kind == "snapshot" and args.duration_s != SNAPSHOT_S else ""
                path = work / f"{kind}_{fe}_{offset:g}_{drift:g}{span}_seed{seed}{'_' + tag if tag else ''}.sigmf-meta"
                if not path.exists():
                    generate(path, kind, offset, drift, fe, impair, args.mask_deg, args.continuous_s, args.duration_s,
                             seed)
                curves, clock = truth(path)
                lo_max = 100e3 if abs(offset) + 300e3 <= 400e3 else 3e6
                for name, init in searches:
                    row = run_one(path, const, site, init, lo_max, drift, curves, clock)
                    row.update(kind=kind, fe=fe, offset_hz=offset, drift_hz_per_s=drift, search=name, tag=tag,
                               seed=seed)
                    row["x_zero"] = row["err3d_m"] / base.setdefault((seed, kind, name), row["err3d_m"])
                    print_row(row)
                    rows.append(row)
                    if args.rows:
                        with open(args.rows, "a") as f:
                            f.write(json.dumps(row) + "\n")
    if len(args.seeds) > 1:
        print_summary(rows)


def run_one(path, const, site, init, lo_max, drift, curves, clock):
    """Replay one recording with one search and score it: the numbers of one row (a dict)."""
    t0 = time.perf_counter()
    rec = open_sigmf(path)
    res = replay(rec, const, init_pos_ecef_m=init, static=True, lo_offset_max_hz=lo_max)
    elapsed = time.perf_counter() - t0
    n_true, n_ok, n_wrong, n_sats, n_sats_id, n_image = score(res, curves)
    fix = None if res.position is None else res.position.fixes
    err = np.full(3, np.nan) if fix is None else fix.pos_ecef_m - site
    enu = C_e_n(*ecef_to_geodetic(site)[:2]).T @ err
    ids = [tr.sat_id for tr in res.tracks if tr.sat_id is not None]
    true_off = np.mean([clock[s] for s in ids]) if ids else np.nan
    lo = res.lo
    crb, d_w, crb_w, dsig3d = np.nan, np.nan, np.nan, np.nan
    again = _data_fix(res, const, rec.sample_rate_hz)
    if again is not None:
        crb = common_offset_sigma_hz(again)
        dsig3d = float(np.sqrt(np.trace(again.cov[:3, :3])))
        a = _min_variance_weights(again)
        truth_w = a @ [clock[str(s)] for s in again.pass_ids] + drift * _since_start(lo.t_ref_utc)
        d_w = again.rx_clock_poly_hz[0] + a @ again.sat_offset_hz - truth_w
        crb_w = _sum_sigma_hz(again, a)
    return {
        "lo_max_hz": lo_max, "tracks": len(res.tracks), "true": int(n_true), "id": int(n_ok),
        "wrong": int(n_wrong), "img": int(n_image), "sats": n_sats, "s_id": n_sats_id,
        "horiz_m": float(np.hypot(enu[0], enu[1])), "err3d_m": float(np.linalg.norm(err)),
        "sig3d_m": np.nan if fix is None else float(np.sqrt(np.trace(fix.cov[:3, :3]))), "dsig3d_m": dsig3d,
        "d_off_hz": float(lo.offset_hz - (true_off + drift * _since_start(lo.t_ref_utc))) if lo else np.nan,
        "sig_hz": float(lo.offset_sigma_hz) if lo else np.nan, "crb_hz": float(crb), "d_w_hz": float(d_w),
        "crb_w_hz": float(crb_w), "d_drift": float(lo.drift_hz_per_s - drift) if lo else np.nan,
        "sig_drift": float(lo.drift_sigma_hz_per_s) if lo else np.nan, "lw_hz": float(_linewidth(lo)),
        "status": solutions_doc(res.position, res.measurements)[0][0]["status"] if fix is not None else "-",
        "t_s": elapsed,
    }


def print_row(r):
    """One run's line under the header."""
    print(f"{r['kind']:10} {r['fe']:8} {r['offset_hz']:9.0f} {r['drift_hz_per_s']:5.0f} {r['search']:6} "
          f"{r['lo_max_hz']:7.0e} {r['tracks']:6d} {r['true']:4d} {r['id']:3d} {r['wrong']:5d} {r['img']:3d} "
          f"{r['sats']:4d} {r['s_id']:4d} {r['horiz_m']:8.1f} {r['err3d_m']:8.1f} {r['sig3d_m']:8.1f} "
          f"{r['dsig3d_m']:8.2f} {r['x_zero']:6.2f} {r['d_off_hz']:8.2f} {r['sig_hz']:6.2f} {r['crb_hz']:7.2f} "
          f"{r['d_w_hz']:6.2f} {r['crb_w_hz']:8.2f} {r['d_drift']:8.4f} {r['sig_drift']:6.4f} {r['lw_hz']:6.4f} "
          f"{r['status']:8} {r['t_s']:5.0f} {r['seed']:4d} {r['tag']}", flush=True)


def print_summary(rows):
    """Per case (kind, front end, offset, drift, impairment, search), over the seeds; see the module docstring."""
    cases = {}
    for r in rows:
        cases.setdefault((r["kind"], r["fe"], r["offset_hz"], r["drift_hz_per_s"], r["tag"], r["search"]),
                         {})[r["seed"]] = r
    print(f"\n{'kind':10} {'fe':8} {'offset_hz':>9} {'drift':>5} {'search':6} {'seeds':>5} {'all_id':>6} "
          f"{'wrong':>5} {'rms_m':>6} {'x_med':>6} {'x_rms':>6} {'xsig_rms':>8} {'nees':>5} {'off<1Hz':>7} "
          f"{'dr<.05':>6} {'z2_off':>6} {'rms_off_hz':>10} {'impair'}")
    for (kind, fe, offset, drift, tag, search), by_seed in cases.items():
        clean = cases.get((kind, "none", 0.0, 0.0, "", search), {})
        seeds = sorted(s for s in by_seed if s in clean)
        if not seeds:
            continue
        rs, cs = [by_seed[s] for s in seeds], [clean[s] for s in seeds]
        err, err0, dsig, dsig0 = _col(rs, "err3d_m"), _col(cs, "err3d_m"), _col(rs, "dsig3d_m"), _col(cs, "dsig3d_m")
        d_off, d_drift = _col(rs, "d_off_hz"), _col(rs, "d_drift")
        print(f"{kind:10} {fe:8} {offset:9.0f} {drift:5.0f} {search:6} {len(seeds):5d} "
              f"{sum(r['s_id'] == r['sats'] for r in rs):6d} {sum(r['wrong'] for r in rs):5d} {_rms(err):6.2f} "
              f"{np.median(err / err0):6.2f} {_rms(err) / _rms(err0):6.2f} {_rms(dsig) / _rms(dsig0):8.2f} "
              f"{np.mean((err / dsig) ** 2):5.2f} {np.mean(np.abs(d_off) < 1.0):7.2f} "
              f"{np.mean(np.abs(d_drift) < 0.05):6.2f} {np.mean((d_off / _col(rs, 'crb_hz')) ** 2):6.2f} "
              f"{_rms(d_off):10.2f} {tag}")


def _col(rows, key):
    """One number of every row, (n_rows,)."""
    return np.array([r[key] for r in rows], float)


def _rms(x):
    """Root mean square of ``x``."""
    return float(np.sqrt(np.mean(np.square(x))))


def _linewidth(lo):
    """The LO linewidth the replay found in its fix's residuals (NaN without one)."""
    return np.nan if lo is None or lo.linewidth_hz is None else lo.linewidth_hz


def _data_fix(res, const, sample_rate_hz):
    """The replay's fix solved again for the data alone (None without a static fix).

    Solved from the replay's solution with neither the element sets' radial
    and cross-track error nor the passes' disagreement in the covariance:
    what the Doppler rows, their sigmas, the LO noise the replay found (one
    state per block, :func:`leosop.replay.lo.lo_noise`) and the priors tell.
    """
    fix = None if res.position is None else res.position.fixes
    if fix is None or getattr(fix, "rx_clock_poly_hz", None) is None or not np.isfinite(fix.pos_ecef_m).all():
        return None
    meas = res.measurements
    pos, vel, reason, _ = satellite_states(meas, const, fix.pos_ecef_m)
    blocks = {}
    if res.lo.linewidth_hz:
        # Snapshot recordings: every block (capture) as long as the first.
        block_s = res.blocks[0].n_samples / sample_rate_hz
        blocks = {"block_id": meas.time_utc, "block_sigma_hz": wiener_doppler_sigma_hz(res.lo.linewidth_hz, block_s)}
    again = solve_static_passes(meas.doppler_hz, meas.sigma_hz, pos, vel, meas.carrier_hz, meas.t_s, meas.sat_id,
                                pos0_ecef_m=fix.pos_ecef_m, mask=reason == "", clock="common", pass_offsets=False,
                                **blocks)
    return again if np.isfinite(again.pos_ecef_m).all() else None


def _sum_index(fix, a):
    """Coefficients of receiver offset + ``a`` . satellite offsets over the fix's states, (n_states,)."""
    n_rx, n_sat = fix.rx_clock_polys_hz.size, len(fix.sat_offset_hz)
    v = np.zeros(len(fix.cov))
    v[3] = 1.0
    v[3 + n_rx:3 + n_rx + n_sat] = a
    return v


def _sum_sigma_hz(fix, a):
    """Sigma of the receiver offset plus the ``a``-weighted satellite offsets."""
    v = _sum_index(fix, a)
    return float(np.sqrt(v @ fix.cov @ v))


def _min_variance_weights(fix):
    """Satellite weights ``a`` (sum 1) of the least-variance receiver offset + ``a`` . satellite offsets, (n_sat,).

    Lagrange: ``C_ss a = -c_0s + lambda 1`` with ``1 . a = 1``, ``C`` the
    fix's covariance of the receiver offset (0) and the satellite offsets (s).
    """
    n_rx, n_sat = fix.rx_clock_polys_hz.size, len(fix.sat_offset_hz)
    s = 3 + n_rx + np.arange(n_sat)
    C_ss, c_0s, one = fix.cov[np.ix_(s, s)], fix.cov[3, s], np.ones(n_sat)
    a0, a1 = -np.linalg.solve(C_ss, c_0s), np.linalg.solve(C_ss, one)
    return a0 + (1.0 - a0.sum()) / a1.sum() * a1


def _since_start(t_utc):
    """Seconds from the recordings' start to ``t_utc``."""
    return float((t_utc - np.datetime64(START.rstrip("Z"), "ns")) / np.timedelta64(1, "s"))


if __name__ == "__main__":
    main()
