"""Differential carrier-phase fix of a static rover: error, NEES and integer fixing over seeds and baselines.

    python tools/bench_differential_carrier.py [--seeds 20] [--tle FILE] [--iq-seeds 5 6 7]

Measurement level (``--seeds``): the scene of tools/bench_differential.py
(seven real Starlink satellites above 25 deg, SGP4 from the 2026-04-08
snapshot), epochs every 0.1 s (replay's blocks); per seed, shared by every
receiver (:mod:`leosop.positioning.differential_sim`): element-set offsets
radial / along / cross-track N(0, 30 / 300 / 100 m), satellite frequency
offsets U(+-5) Hz and drifts N(0, 0.01 Hz/s); each receiver its own clock
(offset N(0, 2 kHz), drift N(0, 1 Hz/s)), white phase noise and whole cycles.
The accumulated phase is :func:`~leosop.positioning.differential_sim.simulate_phase`:
the integral of the Doppler those models give (not IQ), so its double
differences are whole cycles. Phase noise 0.001 cycles per 0.1 s block (the
tracker's sigma on the IQ replay below: median 0.00089 cycles at 43 dB-Hz;
its residuals were 15 % above it) and 0.01 cycles (ten times: weaker combs).
The rover's first guess 30 m off (its differential Doppler fix is metres).
Fits: single differences (``SD``) and the joint fit (``joint``, each
satellite's frequency a line), float and after LAMBDA (ratio 3 and a
bootstrapped success rate of 0.999). Prints per case the median and RMS
3-D error, median 3-D sigma and mean NEES of the float and of the final
(fixed where fixed) fix, and how many seeds fixed all / some ambiguities.

IQ level (``--iq-seeds``): ``leosop generate`` of a continuous pair at 1 MS/s
(``--iq-duration-s``, default 20 s; four satellites, the replay docs'
example, the same error models, base 7.5 km north-east) and ``leosop
replay --base ... --carrier --static`` in this process: the joint and
single-difference fixes (float and final, integers tried) against the truth,
with NEES, the ratio and the float double-difference ambiguities less their
nearest integers; ``--iq-spans-s`` also fixes from the pair's first seconds.
3-7 minutes per seed.

Measured (20 seeds, 7 satellites, 7.5 km unless said; median 3-D error of
the final fix, mean NEES float / final; 95 % interval [2.02, 4.16]):

    case                          sigma 0.001 cycles            sigma 0.01 cycles
    SD 20 s                       0.59 m, 3.79                  0.93 m, 2.95
    joint 20 s                    0.053 m, 2.63                 0.24 m, 4.33
    joint 20 s, 4 satellites      0.16 m, 3.54
    joint 20 s, 50 km             0.22 m, 2.62                  0.84 m, 3.69
    joint 20 s, 200 km            0.92 m, 3.47                  3.6 m, 4.08
    SD 20 s, 50 / 200 km          3.6 / 6.7 m, 3.69 / 3.08      4.8 / 15.8 m, 3.89 / 4.10
    SD 60 s                       0.042 m, 3.44                 0.20 m, 3.25
    joint 60 s                    0.4 mm, 3.64 / 3.00 (20 fixed) 9.9 mm, 2.43
    SD 150 s                                                    1.6 mm, 1.77 / 2.54 (20 fixed)

Since ``simulate_phase`` became ``simulate_receiver``'s phase the phase
noise is drawn differently (the same orbit errors, clocks and sigmas);
the former draws gave joint 20 s 0.037 m, 2.58 and 0.21 m, 3.28, joint
60 s 0.3 mm, 3.39 / 5.38 at 0.001 cycles, SD 150 s 2.2 mm, 2.75 / 3.52.
Two float NEES lay just above the interval (joint 20 s at 0.01 cycles,
joint 60 s at 0.001: 3.28 and 3.39 with the former draws): the first a
draw, the second a model error (below). ``--seeds 100 --cases "joint 20 s, 7.5 km, sigma 0.01"``
(its own noise draws: 3.35 over seeds 0-19) gives mean NEES 3.02, inside
that many seeds' interval [2.54, 3.50]; per seed a chi-square of 3 dof
(quartiles 1.58 / 2.54 / 3.97 against 1.21 / 2.37 / 4.11, 4 % above the
95 % point 7.81, largest 10.5; Kolmogorov-Smirnov p 0.35), fit chi2/dof
0.994, element-set offsets' errors over their sigmas rms 0.98 / 0.94 /
1.04 (radial / along / cross; from the same fixes), the position's 0.96 / 0.97 / 1.08 (E / N / U).

The joint 60 s row at 0.001 cycles over 100 seeds (``--cases "joint 60 s,
7.5 km, sigma 0.001"``) gave NEES 3.84 float and 5.38 fixed (100 of 100;
0.4 mm median, sigma 0.4 mm), and at 1e-6 cycles the fixed fix still
missed by up to 0.5 mm (float 1.4 mm), mostly in height: a model error.
Without orbit offsets or clock terms it stayed; with the rover's first
guess at the truth it went (to 0.06 mm at most): the solver moved the satellite for
the rover's light time by its ECEF rate, not by the apparent position's
sensitivity to the light time, its inertial velocity ``v + w x r`` (~400
m/s more: 0.04 mm of range from a 30 m first guess, which the joint fit's
weak height turns into half a millimetre). With ``w x r`` the 1e-6-cycle
miss is at most 0.06 mm fixed, 0.2 mm float (left with the orbit offsets;
taking them at the transmit time instead of the reception time in the
simulator changed it by under 0.02 mm), and 100 seeds give float 1.1 mm
median, rms 1.8 mm, sigma 1.8 mm, NEES 2.98; fixed (100 of 100) 0.3 mm,
0.4 mm, 0.4 mm, NEES 2.93, both inside [2.54, 3.50]; joint 20 s at 0.01
cycles is unchanged (3.02, 0.22 m median). The 60 s and 150 s rows above
are with it (``--seeds 20 --cases "60 s, 7.5 km" "SD 150 s"``: the full
run's draws; joint 60 s was 0.5 mm, 4.45 / 4.88 and 10 mm, 2.46 before,
SD 150 s 1.5 mm, 1.76 / 2.53, SD 60 s the same).

No 20 s case fixes its integers (the success-rate bound; the ratio test
alone passed wrong integers on 60 s of SD at 0.01 cycles: NEES 48). About
0.03-0.2 s per fix (OPENBLAS_NUM_THREADS=1).

IQ (4 satellites, 7.5 km; seeds 5 / 6 / 7; ``--iq-duration-s 60
--iq-spans-s 20 40``, the tracker started from the comb search, with the
block-centre phase and the comb crossings left out): 20 s joint 0.206 /
0.092 m (seed 7 not rerun) at sigma up 0.19 m, single differences 0.62 /
0.53 m; chi2/dof 0.88-1.01; no integers (DD sigmas 1.3-6.9 cycles). At 40 s
seeds 5 and 6 fix one of three (8.7 mm float to 43 mm, 61 to 25 mm, sigma
up 42 mm). At 60 s the joint fit fixes all three double differences on
every seed (ratio 947 / 495 / 697), 0.7 / 18.7 / 10.5 mm float to 1.1 /
1.2 / 3.1 mm fixed, NEES 1.01 / 1.72 / 2.53 float and 1.72 / 11.7 / 7.36
fixed (seed 6 above the 3-dof bound 7.8: 1.2 mm on 0.2 / 0.1 / 2.4 mm
sigmas); chi2/dof 1.01 / 0.96 / 1.00 at 20 s, 1.01 / 0.98 / 1.01 at 40 s,
1.00 / 0.99 / 1.02 at 60 s; the single differences fix none in 60 s.
Before the two tracker fixes (docs/replay.md): 60 s 9.8 / 9.4 / 1.5 mm
float to 2.5 / 2.3 / 4.3 mm, NEES 1.19 / 1.98 / 6.70 fixed, none at 40 s,
chi2/dof 1.5-2.0 over 40-60 s. Tracked from the truth instead (seeds 5 / 6
/ 7): 60 s 0.98 / 1.13 / 3.1 mm fixed, NEES 1.75 / 11.5 / 7.5.
``--iq-workdir /tmp/pairs_{seed}`` keeps the pairs and replays them again
without generating them (4 minutes a seed alone, 15-16 with two seeds in
parallel on a loaded 2-core machine).
"""

import argparse
import contextlib
import io
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: a threaded QR of 3000 x 50 took 20x longer here
import numpy as np  # noqa: E402
from scipy.stats import chi2  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_static_time_offset import LAT_DEG, LON_DEG, TLE, scene  # noqa: E402

from leosop.frames import C_e_n, geodetic_to_ecef  # noqa: E402
from leosop.positioning.differential_carrier import solve_differential_carrier  # noqa: E402
from leosop.positioning.differential_sim import draw_satellite_errors, simulate_phase  # noqa: E402
from leosop.timebase import seconds_since  # noqa: E402

#: Rover offsets from the base, east / north / up [m], as tools/bench_differential.py.
ROVERS_ENU_M = {"7.5 km": (6e3, 4.5e3, 30.0), "50 km": (40e3, 30e3, 0.0), "200 km": (160e3, 120e3, 0.0)}
#: Cases: (label, rover, span [s], phase sigma [cycles], sat_clock_degree, number of satellites).
CASES = [(f"{fit} {span:g} s, {rover}, sigma {sig:g}", rover, span, sig, deg, 7)
         for sig in (0.001, 0.01) for rover, span in (("7.5 km", 20.0), ("50 km", 20.0), ("200 km", 20.0),
                                                      ("7.5 km", 60.0))
         for fit, deg in (("SD", None), ("joint", 1))]
CASES += [("joint 20 s, 7.5 km, sigma 0.001, 4 sats", "7.5 km", 20.0, 0.001, 1, 4),
          ("SD 150 s, 7.5 km, sigma 0.01", "7.5 km", 150.0, 0.01, None, 7)]
STEP_MS = 100
CARRIER_HZ = 11.325e9
#: The IQ pair: the replay docs' satellites and site, the base 7.5 km north-east (as the measurement-level rover).
IQ_ROVER, IQ_BASE = (34.342, 108.94, 400.0), (34.38256, 109.00527, 400.0)
IQ_SATS = ("71563", "71585", "71607", "72129")


def trial(const, base, rovers, t0, seed, cases=CASES):
    """One seed: per case of ``cases`` (float error, float cov, final error, final cov, status, seconds)."""
    rng = np.random.default_rng(seed)
    err = draw_satellite_errors(const.sat_ids, t0, rng)
    clocks = {k: {"clock_offset_hz": rng.normal(0.0, 2e3), "clock_drift_hz_per_s": rng.normal(0.0, 1.0)}
              for k in ("base", *rovers)}
    offset0 = rng.normal(0.0, 30.0, 3)
    t = t0 + (np.arange(int(max(c[2] for c in cases) * 1000 / STEP_MS)) * STEP_MS).astype("timedelta64[ms]")
    sims = {}
    for sig in sorted({c[3] for c in cases}):
        noise = np.random.default_rng([seed, int(sig * 1e6)])
        sims[sig] = {"base": simulate_phase(const, err, base, t, noise, sigma_cycles=sig, **clocks["base"])}
        for name, pos in rovers.items():
            sims[sig][name] = simulate_phase(const, err, pos, t, noise, sigma_cycles=sig,
                                             pos_light_ecef_m=pos + offset0, **clocks[name])
    out = []
    for label, rover, span, sig, deg, n_sats in cases:
        n = int(round(span * 1000 / STEP_MS))
        b, r = sims[sig]["base"], sims[sig][rover]

        def cut(a):
            return a[:n_sats, :n]

        tic = time.perf_counter()
        fix = solve_differential_carrier(seconds_since(t[:n], t[0]), cut(r.phase_cycles), cut(r.sigma_cycles),
                                         cut(r.arc), cut(b.phase_cycles), cut(b.sigma_cycles), cut(b.arc),
                                         cut(r.pos_sv_ecef_m), cut(b.pos_sv_ecef_m), cut(b.vel_sv_ecef_mps), base,
                                         rovers[rover] + offset0, carrier_hz=CARRIER_HZ, sat_clock_degree=deg)
        truth = rovers[rover]
        out.append((label, fix.pos_float_ecef_m - truth, fix.cov_float, fix.pos_ecef_m - truth, fix.cov, fix.status,
                    time.perf_counter() - tic))
    return out


def stats(e, P):
    e3 = np.linalg.norm(e, axis=-1)
    nees = np.einsum("si,sij,sj->s", e, np.linalg.inv(P), e)
    return np.median(e3), np.sqrt(np.mean(e3**2)), np.median(np.sqrt(np.trace(P, axis1=-2, axis2=-1))), nees.mean()


def measurement_level(args):
    const, base, t = scene(args.tle)
    C = C_e_n(np.radians(LAT_DEG), np.radians(LON_DEG))
    rovers = {k: base + C @ np.array(v) for k, v in ROVERS_ENU_M.items()}
    print(f"{len(const)} Starlink satellites, epochs every {STEP_MS} ms, {args.seeds} seeds (measurement level)")
    cases = [c for c in CASES if any(k in c[0] for k in args.cases)] if args.cases else CASES
    runs = [trial(const, base, rovers, t[0], seed, cases) for seed in range(args.seeds)]
    lo, hi = chi2.ppf([0.025, 0.975], 3 * args.seeds) / args.seeds
    print(f"{'case':40s} {'float: med':>10s} {'rms':>7s} {'sig':>7s} {'NEES':>6s} | {'final: med':>10s} {'rms':>7s} "
          f"{'sig':>7s} {'NEES':>6s} {'fixed/partial':>13s} {'ms':>5s}")
    for k, label in enumerate(r[0] for r in runs[0]):
        rows = [run[k] for run in runs]
        f = stats(np.array([r[1] for r in rows]), np.array([r[2] for r in rows]))
        g = stats(np.array([r[3] for r in rows]), np.array([r[4] for r in rows]))
        status = [r[5] for r in rows]
        print(f"{label:40s} {f[0]:10.4f} {f[1]:7.4f} {f[2]:7.4f} {f[3]:6.2f} | {g[0]:10.4f} {g[1]:7.4f} {g[2]:7.4f} "
              f"{g[3]:6.2f} {status.count('fixed'):6d}/{status.count('partial'):<6d} "
              f"{1e3 * np.median([r[6] for r in rows]):5.0f}")
    print(f"errors and sigmas in m; NEES: mean of e^T P^-1 e over the seeds, 95 % interval for a consistent fix "
          f"[{lo:.2f}, {hi:.2f}]")


def iq_level(seeds, duration_s, spans_s, workdir=None):
    """Per seed, generate the pair, replay it (in this process) and print the fixes of its first ``spans_s``.

    ``workdir`` (a path with ``{seed}``): the pair is kept there, and a pair already there (``rover.sigmf-meta``
    and ``rover-base.sigmf-meta``, made with these settings and ``duration_s``) is replayed, not generated again.
    """
    from leosop.cli import main as leosop_main

    truth = geodetic_to_ecef(np.radians(IQ_ROVER[0]), np.radians(IQ_ROVER[1]), IQ_ROVER[2])
    enu = C_e_n(np.radians(IQ_ROVER[0]), np.radians(IQ_ROVER[1]))
    site, base_site = ",".join(map(str, IQ_ROVER)), ",".join(map(str, IQ_BASE))
    for seed in seeds:
        keep = workdir is not None
        with (contextlib.nullcontext(workdir.format(seed=seed)) if keep else tempfile.TemporaryDirectory()) as tmp:
            Path(tmp).mkdir(parents=True, exist_ok=True)
            rover = Path(tmp) / "rover.sigmf-meta"
            tic = time.perf_counter()
            if not (keep and rover.exists() and (Path(tmp) / "rover-base.sigmf-meta").exists()):
                subprocess.run([sys.executable, "-m", "leosop", "generate", "-o", str(rover), "--site", site,
                                "--start", "2025-01-01T19:40:00Z", "--duration-s", f"{duration_s:g}",
                                "--sample-rate-hz", "1e6",
                                "--seed", str(seed), "--sat", *IQ_SATS, "--orbit-error-along-m", "300",
                                "--orbit-error-radial-m", "30", "--orbit-error-cross-m", "100",
                                "--sat-drift-sigma-hz-per-s", "0.01", "--base-site", base_site, "--out", tmp],
                               check=True, capture_output=True)
            pairs = []
            with _spans_fixed(spans_s, pairs), contextlib.redirect_stdout(io.StringIO()):
                code = leosop_main(["replay", str(rover), "--base", str(Path(tmp) / "rover-base.sigmf-meta"),
                                    "--base-site", base_site, "--init", site, "--static", "--carrier", "--json"])
            if code:
                raise SystemExit(f"replay of seed {seed} failed")
            for span, pair in pairs:
                for name, f in (("joint", pair.joint), ("SD", pair.single_difference)):
                    fl, fi = (_error_nees(pos, cov, truth) for pos, cov in ((f.pos_float_ecef_m, f.cov_float),
                                                                           (f.pos_ecef_m, f.cov)))
                    amb = ", ".join(f"{a - np.round(a):+.3f}+-{s:.3f}" for a, s in zip(f.ambiguity_cycles,
                                                                                   f.ambiguity_sigma_cycles))
                    sig = " / ".join(f"{v:.4f}" for v in np.sqrt(np.diag(enu.T @ f.cov @ enu)))
                    print(f"IQ seed {seed} {span:3g} s {name:5s}: float {fl[0]:.4f} m (NEES {fl[1]:.2f}), final "
                          f"{fi[0]:.4f} m (NEES {fi[1]:.2f}, sigma E/N/U {sig} m), {f.status} "
                          f"{f.n_fixed}/{f.n_ambiguities} ratio "
                          f"{f.ratio:.2f}; float ambiguities less the nearest integer {amb} cycles; chi2/dof "
                          f"{f.chi2 / f.dof:.2f}; {time.perf_counter() - tic:.0f} s")


@contextlib.contextmanager
def _spans_fixed(spans_s, out):
    """Replay's differential carrier fix also made of each pair's first ``spans_s`` seconds: (span, CarrierPair)
    appended to ``out`` (the last the whole pair's, which replay reports)."""
    import leosop.replay.differential_carrier as dc

    original = dc.differential_carrier_fix

    def first(rc, span_s):
        keep = seconds_since(rc.time_utc, rc.time_utc[0]) < span_s - 1e-6
        tracks = SimpleNamespace(**{k: getattr(rc.tracks, k)[:, keep] for k in ("phase_cycles", "phase_sigma_cycles",
                                                                                "arc")})
        return SimpleNamespace(sat_id=rc.sat_id, time_utc=rc.time_utc[keep], tracks=tracks)

    def fix(rover, base, *args, **kwargs):
        span = seconds_since(rover.time_utc[-1], rover.time_utc[0])
        for s in sorted(v for v in spans_s if v < span):
            out.append((s, original(first(rover, s), first(base, s), *args, **kwargs)))
        out.append((round(float(span)), original(rover, base, *args, **kwargs)))
        return out[-1][1]

    dc.differential_carrier_fix = fix
    try:
        yield
    finally:
        dc.differential_carrier_fix = original


def _error_nees(pos_ecef_m, cov, truth):
    """3-D error [m] and NEES of a position and its covariance."""
    e = pos_ecef_m - truth
    return np.linalg.norm(e), float(e @ np.linalg.solve(cov, e))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--tle", type=Path, default=TLE)
    parser.add_argument("--cases", nargs="*", default=[],
                        help="only the cases whose label holds one of these (e.g. 'joint 60 s, 7.5 km'); their "
                             "noise draws then differ from the full run's (the simulated span is theirs)")
    parser.add_argument("--iq-seeds", type=int, nargs="*", default=[], help="also these seeds at IQ level")
    parser.add_argument("--iq-duration-s", type=float, default=20.0, help="the IQ pair's length (default 20)")
    parser.add_argument("--iq-spans-s", type=float, nargs="*", default=[],
                        help="also fix from the pair's first S seconds (e.g. 20 40 with --iq-duration-s 60)")
    parser.add_argument("--iq-workdir", help="keep each seed's pair in this directory ({seed} in it: the seed) and "
                                             "replay a pair already there instead of generating it")
    args = parser.parse_args()
    if args.seeds:
        measurement_level(args)
    iq_level(args.iq_seeds, args.iq_duration_s, args.iq_spans_s, args.iq_workdir)


if __name__ == "__main__":
    main()
