"""Throughput of the IQ readers per sample format, ratios in one run (issue 26: ci8 / cu8 at least ci16).

    python tools/bench_frontend_readers.py [--duration-s S] [--repeat N]

One recording of the satellites above 40 deg from Xi'an (``leosop generate``,
2.5 MS/s, cf32) is written again as ci16, ci8 and cu8 (the same samples,
quantised with 4 sigmas of headroom). For each format, in the same run:

1. read: :meth:`Recording.read` over the file in 0.1 s blocks (page cache
   warm: the first pass is discarded), million samples per second of CPU time;
2. stream: read plus :func:`~leosop.signal.multicomb.find_combs` on every
   block (full search: what the replay's streaming stage does when it has no
   track yet, its most expensive block).

Ratios are ci8 / ci16 and cu8 / ci16 throughput (>= 1 is the goal).
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.cli import main  # noqa: E402
from leosop.signal.iq import open_sigmf  # noqa: E402
from leosop.signal.iq_write import write_sigmf  # noqa: E402
from leosop.signal.multicomb import find_combs  # noqa: E402

FORMATS = ("cf32_le", "ci16_le", "ci8", "cu8")
FS_HZ = 2.5e6
BLOCK = 250_000


def _recordings(folder, duration_s):
    """The same signal in every format: {datatype: Recording}."""
    base = folder / "cf32.sigmf-meta"
    assert main(["generate", "-o", str(base), "--duration-s", str(duration_s), "--sample-rate-hz", str(FS_HZ),
                 "--seed", "1"]) == 0
    rec = open_sigmf(base)
    x = rec.read(0, rec.n_samples)
    full_scale = 4.0 * float(np.sqrt(np.mean(np.abs(x) ** 2) / 2.0))
    out = {"cf32_le": rec}
    for dt in FORMATS[1:]:
        meta = folder / f"{dt}.sigmf-meta"
        write_sigmf(meta, (x[i:i + BLOCK] for i in range(0, x.size, BLOCK)), sample_rate_hz=FS_HZ,
                    center_hz=rec.center_hz, start_utc=rec.start_utc, datatype=dt, full_scale=full_scale)
        out[dt] = open_sigmf(meta)
    return out


def _rates(recs, repeat):
    """Million samples per CPU second, {datatype: (read, stream)}: block by block, the formats
    interleaved (each block read, and read and searched, in every format in turn) so that a change
    of the machine's load during the run hits all alike; reads best of ``repeat`` passes, the page
    cache warmed first."""
    n = recs[FORMATS[0]].n_samples
    starts = range(0, n - BLOCK + 1, BLOCK)
    read = {dt: np.inf for dt in FORMATS}
    stream = dict.fromkeys(FORMATS, 0.0)
    for k in range(repeat + 1):
        spent = dict.fromkeys(FORMATS, 0.0)
        for start in starts:
            for dt in FORMATS:
                t0 = time.process_time()
                recs[dt].read(start, BLOCK, check_finite=False)
                spent[dt] += time.process_time() - t0
        if k:
            read = {dt: min(read[dt], spent[dt]) for dt in FORMATS}
    for start in starts:
        for dt in FORMATS:
            t0 = time.process_time()
            find_combs(recs[dt].read(start, BLOCK, check_finite=False), FS_HZ)
            stream[dt] += time.process_time() - t0
    return {dt: (n / read[dt] / 1e6, n / stream[dt] / 1e6) for dt in FORMATS}


def main_bench(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=4.0)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        recs = _recordings(Path(tmp), args.duration_s)
        rates = _rates(recs, args.repeat)
        read = {dt: r[0] for dt, r in rates.items()}
        stream = {dt: r[1] for dt, r in rates.items()}
        size = {dt: recs[dt].data_path.stat().st_size / 1e6 for dt in FORMATS}
    print(f"{args.duration_s:g} s at {FS_HZ / 1e6:g} MS/s, 0.1 s blocks, one thread (CPU time)")
    print(f"{'format':8} {'file MB':>8} {'read MS/s':>10} {'stream MS/s':>12}")
    for dt in FORMATS:
        print(f"{dt:8} {size[dt]:8.1f} {read[dt]:10.1f} {stream[dt]:12.2f}")
    for dt in ("ci8", "cu8"):
        print(f"{dt} / ci16_le: read {read[dt] / read['ci16_le']:.2f}x, stream {stream[dt] / stream['ci16_le']:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main_bench())
