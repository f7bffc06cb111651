"""Front-end sweeps at the comb search, and the accuracy of what ``leosop doctor`` measures (issue 26).

    python tools/bench_frontend.py [--seeds N] [--parts doctor,sweep]

1. doctor: recordings of the satellites above 40 deg from Xi'an through the
   ``consumer`` preset (one per seed, 0.3 s at 2.5 MS/s, ci8); the DC, IQ
   imbalance, CW line and rough LO offset measured by
   :func:`leosop.signal.survey.survey` against the generated truth.
2. sweep: 0.1 s blocks (2.5 MS/s, 45 dB-Hz at zenith, geometry C/N0) with one
   impairment varied from an ideal receiver: LO offset (0 to the band edge,
   stated to the search), bits (8 / 12 / 16), a CW line's power, IQ imbalance;
   per setting, the fraction of satellites found within 1 Hz of the truth, the
   spurious combs, and the RMS Doppler error over the found ones against the
   ideal receiver's (same seeds: same noise).
Identification and fixes through these front ends are part B's (leosop replay).
"""

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.cli import main  # noqa: E402
from leosop.signal.iq import open_sigmf  # noqa: E402
from leosop.signal.multicomb import find_combs  # noqa: E402
from leosop.signal.survey import survey  # noqa: E402

FS = 2.5e6


def _generate(path, seed, *options, duration_s=0.1):
    code = main(["generate", "-o", str(path), "--duration-s", str(duration_s), "--sample-rate-hz", str(FS),
                 "--seed", str(seed), "--rx-offset-hz", "0", *options])
    assert code == 0
    return open_sigmf(path)


def part_doctor(tmp, seeds):
    rows = []
    for seed in range(seeds):
        rec = _generate(tmp / f"d{seed}.sigmf-meta", seed, "--front-end", "consumer", "--rx-offset-hz", "620e3",
                        duration_s=0.3)
        doc = survey(rec, n_blocks=3)
        line = doc["interferers"][0] if doc["interferers"] else {"frequency_hz": np.nan, "power_dbhz": np.nan}
        truth_n = len({a["leosop:sat_id"] for a in rec.annotations})
        rows.append([doc["dc_dbhz"] - 60.0, doc["iq_gain_db"] - 0.5, doc["iq_phase_deg"] - 2.0,
                     line["frequency_hz"] - 700e3, line["power_dbhz"] - 70.0, doc["lo_offset_hz_rough"] - 620e3,
                     doc["usable_satellites"] - truth_n, len(doc["interferers"])])
    r = np.array(rows, dtype=float)
    names = ["DC [dB]", "IQ gain [dB]", "IQ phase [deg]", "CW freq [Hz]", "CW power [dB]", "LO rough [Hz]",
             "usable - truth", "lines found"]
    print(f"doctor on the consumer preset, {seeds} recordings (measured - truth): mean, RMS, max |.|")
    for k, name in enumerate(names):
        col = r[:, k]
        print(f"  {name:16} {np.mean(col):+10.4g} {np.sqrt(np.mean(col ** 2)):10.4g} {np.max(np.abs(col)):10.4g}")


def _score(rec, lo_hz):
    """Found fraction within 1 Hz, spurious count, per-sat errors {sat: err} of the first 0.1 s block."""
    truth = {a["leosop:sat_id"]: a["leosop:doppler_hz"] for a in rec.annotations if a["core:sample_start"] == 0}
    found = find_combs(rec.read(0, int(0.1 * FS)), FS, lo_offset_hz=lo_hz)
    errs, used = {}, set()
    for sid, d in truth.items():
        j = int(np.argmin(np.abs(found.doppler_hz - d))) if found.n_found else -1
        if j >= 0 and abs(found.doppler_hz[j] - d) < 1.0:
            errs[sid] = found.doppler_hz[j] - d
            used.add(j)
    return len(errs) / len(truth), found.n_found - len(used), errs


def part_sweep(tmp, seeds):
    settings = [("ideal", [], 0.0)]
    settings += [(f"LO {lo / 1e3:.0f} kHz", ["--rx-offset-hz", str(lo)], lo) for lo in (100e3, 400e3, 700e3, 770e3)]
    settings += [(f"{b} bits", ["--bits", str(b)], 0.0) for b in (16, 12, 8)]
    settings += [(f"CW {p} dB-Hz", ["--cw", "150e3", str(p)], 0.0) for p in (50, 70, 90)]
    settings += [(f"IQ {g} dB/{ph} deg", ["--iq-gain-db", str(g), "--iq-phase-deg", str(ph)], 0.0)
                 for g, ph in ((0.5, 2), (1, 5), (2, 10))]
    ideal = {}
    print(f"\ncomb search, first 0.1 s block, {seeds} skies (all satellites above 40 deg)")
    print(f"  {'setting':18} {'found':>6} {'spurious':>8} {'RMS err [Hz]':>12} {'vs ideal':>8}")
    for name, opts, lo in settings:
        found, spurious, errs = [], 0, []
        for seed in range(seeds):
            rec = _generate(tmp / f"s{seed}.sigmf-meta", seed, *opts)
            f, s, e = _score(rec, lo)
            found.append(f)
            spurious += s
            errs.append(e)
        if name == "ideal":
            ideal = errs
        rms = np.sqrt(np.mean([v ** 2 for e in errs for v in e.values()])) if any(errs) else np.nan
        ref = np.sqrt(np.mean([ideal[k][sid] ** 2 for k, e in enumerate(errs) for sid in e if sid in ideal[k]]))
        print(f"  {name:18} {np.mean(found):6.3f} {spurious:8d} {rms:12.4f} {rms / ref:8.2f}")


def main_bench(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--parts", default="doctor,sweep")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        if "doctor" in args.parts:
            part_doctor(Path(tmp), args.seeds)
        if "sweep" in args.parts:
            part_sweep(Path(tmp), args.seeds)
    return 0


if __name__ == "__main__":
    sys.exit(main_bench())
