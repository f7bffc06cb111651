"""Snapshot Doppler errors over their stated sigmas, one front-end impairment at a time (issue 26).

    python tools/bench_frontend_sigma.py [--snapshots 30] [--seeds 1] [--cases none wiener ...]

One snapshot recording per case (20 ms every second, 4 MS/s as
tools/bench_lo_offset.py, satellites above 25 deg from Munich, 45 dB-Hz at
zenith, geometry C/N0, same seed: same satellites, noise and phases), with
one impairment of the ``consumer`` preset (or all of them) at zero LO offset
unless the case sets one; every capture searched for combs as the replay
does (cleaned, :func:`~leosop.signal.multicomb.find_combs`), each detection
matched to its satellite's truth Doppler (the annotation of its capture,
within 20 Hz) and its error divided by its sigma. Reported per case: the
detections matched (``n``), those matching no satellite (``spur``) and
those beyond 5 sigma (``out``, set aside: the replay's tracks and robust
fix drop them), the mean and RMS of error / sigma, the same RMS with the
LO's Wiener sigma of the generated linewidth added to each sigma
(``z_lo``, :func:`~leosop.signal.frontend.wiener_doppler_sigma_hz`: what the
replay prices in once it has estimated the linewidth), the RMS of the
errors and of the sigmas, and the RMS over the snapshots of the errors'
mean over the satellites of a snapshot (the part common to them, which a
receiver LO moves alike) with its sigma (that mean's spread were the errors
independent at their sigmas).
"""

import argparse
import contextlib
import io
import json
import os
import shlex
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.cli import main as leosop_main  # noqa: E402
from leosop.signal.iq import open_sigmf  # noqa: E402
from leosop.signal.frontend import wiener_doppler_sigma_hz  # noqa: E402
from leosop.signal.multicomb import find_combs  # noqa: E402

FS = 4e6
SITE = "48.137,11.575,520.0"
START = "2025-01-01T19:40:00Z"
MATCH_HZ = 20.0
SNAPSHOT_S = 0.02
#: Combs searched per capture: the replay's (``MAX_NEW_COMBS`` of a snapshot block).
MAX_COMBS = 10
#: Detections beyond this many sigmas are outliers, which the replay's tracks and robust fix drop.
OUTLIER_Z = 5.0
#: Generator options of each case (the consumer preset's values, one impairment at a time).
CASES = {
    "none": "",
    "wiener": "--phase-noise-linewidth-hz 0.01",
    "pll_floor": "--phase-noise-dbc-hz -75 --phase-noise-corner-hz 30e3",
    "iq": "--iq-gain-db 0.5 --iq-phase-deg 2",
    "dc": "--dc-dbhz 60",
    "cw": "--cw 700e3 70",
    "cw_in_band": "--cw 150e3 70",
    "bits8": "--bits 8",
    "agc": "--agc-step-db 6 --agc-period-s 1 --bits 8 --headroom-db 18",
    "lo_drift": "--rx-drift-hz-per-s 50",
    "consumer": "--front-end consumer --rx-offset-hz 0 --rx-drift-hz-per-s 0",
    "consumer_lo": "--front-end consumer --rx-offset-hz 620e3 --rx-drift-hz-per-s 25",
}


def generate(path, options, snapshots, seed):
    cmd = ["generate", "-o", str(path), "--site", SITE, "--start", START, "--sample-rate-hz", f"{FS:g}",
           "--mask-deg", "25", "--seed", str(seed), "--rx-offset-hz", "0", "--duration-s", str(snapshots),
           "--snapshot-s", f"{SNAPSHOT_S:g}", "--period-s", "1", *shlex.split(options)]
    with contextlib.redirect_stdout(io.StringIO()):
        assert leosop_main(cmd) == 0
    return open_sigmf(path)


def measure(rec):
    """(error, sigma, snapshot index) of every matched detection, the detections unmatched, and the LO's
    Wiener linewidth the recording was generated with [Hz]."""
    meta = json.loads(Path(rec.data_path).with_suffix(".sigmf-meta").read_text())["global"]
    lo0, drift = meta.get("leosop:rx_offset_hz", 0.0), meta.get("leosop:rx_drift_hz_per_s", 0.0)
    linewidth = (meta.get("leosop:front_end") or {}).get("phase_noise_linewidth_hz", 0.0)
    rows, spurious = [], 0
    for k, cap in enumerate(rec.captures):
        truth = np.array([a["leosop:doppler_hz"] for a in rec.annotations
                          if a["core:sample_start"] == cap.sample_start])
        t_s = (cap.start_utc - rec.start_utc) / np.timedelta64(1, "s") + 0.5 * cap.n_samples / FS
        found = find_combs(rec.read(cap.sample_start, cap.n_samples), FS, max_combs=MAX_COMBS,
                           lo_offset_hz=lo0 + drift * t_s)
        for d, s in zip(found.doppler_hz, found.sigma_hz):
            j = np.argmin(np.abs(truth - d)) if truth.size else None
            if j is None or abs(truth[j] - d) > MATCH_HZ:
                spurious += 1
                continue
            rows.append((d - truth[j], s, k))
    return np.array(rows), spurious, linewidth


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--snapshots", type=int, default=30)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--workdir", help="keep the recordings here (default a temporary directory)")
    args = ap.parse_args(argv)
    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench_fe_sigma_"))
    work.mkdir(parents=True, exist_ok=True)
    print(f"{'case':12} {'n':>5} {'spur':>4} {'out':>4} {'mean z':>7} {'rms z':>6} {'z_lo':>6} {'rms err':>8} "
          f"{'rms sig':>8} {'common':>7} {'its sig':>7}")
    for name in args.cases:
        parts = []
        spurious = 0
        for seed in range(args.seeds):
            path = work / f"{name}_{seed}_{args.snapshots}.sigmf-meta"
            rec = open_sigmf(path) if path.exists() else generate(path, CASES[name], args.snapshots, seed)
            r, sp, linewidth = measure(rec)
            r[:, 2] += 10_000 * seed
            parts.append(r)
            spurious += sp
        r = np.concatenate(parts)
        inlier = np.abs(r[:, 0] / r[:, 1]) <= OUTLIER_Z
        err, sig, snap = r[inlier].T
        z = err / sig
        z_lo = err / np.hypot(sig, wiener_doppler_sigma_hz(linewidth, SNAPSHOT_S))
        _, inv = np.unique(snap, return_inverse=True)
        count = np.bincount(inv)
        common = np.bincount(inv, err) / count
        common_sig = np.sqrt(np.bincount(inv, sig**2)) / count
        rms = lambda x: np.sqrt(np.mean(x**2))  # noqa: E731
        print(f"{name:12} {z.size:5d} {spurious:4d} {np.sum(~inlier):4d} {np.mean(z):+7.3f} {rms(z):6.3f} "
              f"{rms(z_lo):6.3f} {rms(err):8.4f} {rms(sig):8.4f} {rms(common):7.4f} {rms(common_sig):7.4f}", flush=True)


if __name__ == "__main__":
    main()
