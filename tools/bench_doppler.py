"""Doppler estimators against the Cramér-Rao bound and against each other's run time.

Usage: python tools/bench_doppler.py [--trials N] [--slow-trials M] [--seed S] [--out DIR]

Blocks of N = 3e5 samples at 2.5 MHz (0.12 s; [Shen 2024]'s Table 2 size).
Part 1 times, in this process and on the same blocks: one pyfftw FFT of the
block (the reference), ``fast`` (everything: comb search FFT, decimation,
rate, Newton), ``fmlef`` at 1e-3 and 1e-4 Hz (fine stage only, from the same
coarse estimate, as the paper times it). Best of 5 repeats per block, median
over blocks; one thread everywhere (OpenBLAS forced to one thread below).
Part 2 is a seeded Monte Carlo of RMSE against the bound over C/N0, for a
steady comb and for blocks along a real LEO pass (Doppler, rate and rate
change of satellite 71585 seen from Xi'an, bundled TLE, 2025-01-01T19:40Z,
rates up to ~3 kHz/s). ``fast`` gets the predicted rate change (as
``leosop simulate`` can from the orbits); "fast, a ignored" shows what
leaving it out costs. Writes bench_doppler.png (and .json) into --out.
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.plots import pyplot, save_png  # noqa: E402
from leosop.fileio import write_json  # noqa: E402
from leosop.frames import geodetic_to_ecef  # noqa: E402
from leosop.orbits import load_constellation  # noqa: E402
from leosop.signal.channel import SiteChannel, doppler_blocks, site_geometry  # noqa: E402
from leosop.signal.coarse import coarse_fft  # noqa: E402
from leosop.signal.doppler import estimate_block  # noqa: E402
from leosop.signal.error_model import doppler_sigma_hz  # noqa: E402
from leosop.signal.fine import fine_fmlef  # noqa: E402
from leosop.signal.fft import fft  # noqa: E402
from leosop.signal.pilot import PilotComb  # noqa: E402

FS = 2.5e6
N = 300_000
CN0S = (25.0, 30.0, 35.0, 40.0, 45.0, 50.0)


def best_of(func, *args, repeats=5, **kw):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        func(*args, **kw)
        times.append(time.perf_counter() - t0)
    return min(times)


def leo_pass(trials, rng):
    """Doppler, rate and rate change at random instants of a real pass above 40 deg."""
    const = load_constellation().select_ids(["71585"])
    xian = geodetic_to_ecef(np.radians(34.342), np.radians(108.940), 400.0)
    start = np.datetime64("2025-01-01T19:40:00", "ns")
    t_nodes, range_m, _ = site_geometry(const, xian, start, 240.0, node_step_s=0.5)
    ch = SiteChannel(t_nodes, range_m, FS, 45.0, 5.0)
    t = rng.uniform(0.0, 240.0, trials)
    d = ch.doppler_hz(t)[0]
    r = ch.doppler_rate_hz_per_s(t)[0]
    h = 0.05
    a = (ch.doppler_rate_hz_per_s(t + h)[0] - ch.doppler_rate_hz_per_s(t - h)[0]) / (2 * h)
    return d, r, a


def timing(seed):
    rng = np.random.default_rng(seed)
    comb = PilotComb()
    rows = []
    for name, rate_max in (("steady", 0.0), ("LEO rate", 4000.0)):
        d = rng.uniform(-2e5, 2e5, 10)
        r = rng.uniform(-rate_max, rate_max, 10)
        blocks = doppler_blocks(FS, N, d, r, 45.0, rng=rng)
        t_fft, t_fast, t_f3, t_f4 = [], [], [], []
        for x in blocks:
            estimate_block(x, FS)  # warm the plans
            coarse = coarse_fft(fft(x), FS, comb)
            t_fft.append(best_of(fft, x))
            t_fast.append(best_of(estimate_block, x, FS))
            t_f3.append(best_of(fine_fmlef, x, FS, coarse.doppler_hz, 1e-3, 1.0, repeats=2))
            t_f4.append(best_of(fine_fmlef, x, FS, coarse.doppler_hz, 1e-4, 1.0, repeats=2))
        rows.append({"case": name, "fft_s": np.median(t_fft), "fast_s": np.median(t_fast),
                     "fmlef_1e-3_s": np.median(t_f3), "fmlef_1e-4_s": np.median(t_f4)})
    return rows


def monte_carlo(scenario, trials, slow_trials, seed):
    rng = np.random.default_rng(seed)
    if scenario == "steady":
        d, r, a = rng.uniform(-2e5, 2e5, trials), np.zeros(trials), np.zeros(trials)
    else:
        d, r, a = leo_pass(trials, rng)
    out = {}
    for cn0 in CN0S:
        x = doppler_blocks(FS, N, d, r, cn0, doppler_accel_hz_per_s2=a, rng=rng)
        err = {"fast": [], "fast, a ignored": [], "fmlef": [], "ml": []}
        for i, block in enumerate(x):
            err["fast"].append(estimate_block(block, FS, doppler_accel_hz_per_s2=a[i])["doppler_hz"] - d[i])
            if scenario != "steady":
                err["fast, a ignored"].append(estimate_block(block, FS)["doppler_hz"] - d[i])
            if i < slow_trials:
                err["fmlef"].append(estimate_block(block, FS, method="fmlef", resolution_hz=1e-3)["doppler_hz"] - d[i])
                err["ml"].append(estimate_block(block, FS, method="ml", resolution_hz=0.1)["doppler_hz"] - d[i])
        out[cn0] = {k: (float(np.sqrt(np.nanmean(np.square(v)))) if v else None,
                        int(np.sum(np.isnan(v)))) for k, v in err.items()}
    return out


def plot(path, results):
    plt = pyplot()

    cn0 = np.array(CN0S)
    comb_bound = doppler_sigma_hz(cn0, N / FS, sample_rate_hz=FS)
    tone_bound = doppler_sigma_hz(cn0, N / FS, method="fmlef", sample_rate_hz=FS)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True, constrained_layout=True)
    styles = {"fast": ("o-", "C0"), "fast, a ignored": ("x--", "C1"), "fmlef": ("s-", "C2"), "ml": ("^-", "C3")}
    for ax, (scenario, res) in zip(axes, results.items()):
        ax.semilogy(cn0, comb_bound, "k-", lw=2, label="CRLB, 9-tone comb")
        ax.semilogy(cn0, tone_bound, "k:", lw=2, label="CRLB, central tone")
        for method, (style, color) in styles.items():
            y = [res[c][method][0] for c in CN0S]
            if any(v is not None for v in y):
                ax.semilogy(cn0, [np.nan if v is None else v for v in y], style, color=color, label=method)
        ax.set_title(f"{scenario}: N = 3e5 at 2.5 MHz (0.12 s)")
        ax.set_xlabel("C/N0 per tone [dB-Hz]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("Doppler RMSE [Hz]")
    axes[1].legend(fontsize=8)
    save_png(fig, path, dpi=110)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=100, help="blocks per C/N0 for fast (default 100)")
    p.add_argument("--slow-trials", type=int, default=25, help="of which for fmlef and ml (default 25)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=".", help="directory for bench_doppler.png/.json")
    p.add_argument("--timing-only", action="store_true", help="part 1 only")
    args = p.parse_args()

    rows = timing(args.seed)
    print("Part 1: seconds per block of 3e5 samples (best of repeats, median over 10 blocks, one thread)")
    print(f"{'case':>9} | {'1 FFT':>8} | {'fast':>8} | {'fmlef 1e-3':>10} | {'fmlef 1e-4':>10} | "
          f"fast/FFT | fmlef(1e-3)/fast | fmlef(1e-4)/fast")
    for r in rows:
        print(f"{r['case']:>9} | {r['fft_s']:8.5f} | {r['fast_s']:8.5f} | {r['fmlef_1e-3_s']:10.4f} | "
              f"{r['fmlef_1e-4_s']:10.4f} | {r['fast_s'] / r['fft_s']:8.2f} | "
              f"{r['fmlef_1e-3_s'] / r['fast_s']:16.1f} | {r['fmlef_1e-4_s'] / r['fast_s']:16.1f}")
    if args.timing_only:
        return

    results = {s: monte_carlo(s, args.trials, args.slow_trials, args.seed + 1) for s in ("steady", "LEO pass")}
    print(f"\nPart 2: RMSE / CRLB (fast: 9-tone comb bound, {args.trials} blocks; fmlef 1e-3 Hz and ml 0.1 Hz: "
          f"central-tone bound, {args.slow_trials} blocks); [n missed detections]")
    for scenario, res in results.items():
        print(f"{scenario}:")
        for cn0 in CN0S:
            cb = float(doppler_sigma_hz(cn0, N / FS, sample_rate_hz=FS))
            tb = float(doppler_sigma_hz(cn0, N / FS, method="fmlef", sample_rate_hz=FS))
            cells = []
            for method, (rmse, missed) in res[cn0].items():
                if rmse is None:
                    continue
                bound = cb if method.startswith("fast") else tb
                cells.append(f"{method} {rmse / bound:8.3g}" + (f" [{missed}]" if missed else ""))
            print(f"  {cn0:4.0f} dB-Hz  comb bound {cb:.3e} Hz | " + " | ".join(cells))
    out = Path(args.out)
    plot(out / "bench_doppler.png", results)
    write_json(out / "bench_doppler.json", {"timing": rows, "rmse_hz": {s: {str(c): v for c, v in r.items()}
                                                                       for s, r in results.items()}})
    print(f"\nwrote {out / 'bench_doppler.png'}")


if __name__ == "__main__":
    main()
