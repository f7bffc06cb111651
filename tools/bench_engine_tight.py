"""Benchmark: the engine's tight coupling alone (``simulate --coupling tight``'s filter), one BLAS thread and two.

The inputs of :func:`leosop.apps.simulate.tight.run` are made once by
:func:`leosop.apps.simulate.run_scenario` (measurement level, seed 0; its tight
filter is intercepted, not run) and pickled to a temporary file; a child
process per BLAS thread count (``OPENBLAS_NUM_THREADS``, read when numpy
loads) then times the filter alone, best of ``--repeat`` runs, and prints
the time per Doppler offered and a digest of the result (final position,
number of updates, the NIS sum) so that two versions of the engine can be
compared for speed and output at once.

Measured (issue 21, busy 2-core machine, best of 2): one full-covariance Joseph
update per Doppler before, one per epoch after; xian-baoji 9.6 -> 8.0 s with
one thread; xian-baoji-multi (11 k Doppler, ~90 states) 30.2 -> 9.3 s with one
thread and 182 -> 50 s with two; the digests equal to rounding.

Usage: python tools/bench_engine_tight.py [--scenario xian-baoji] [--threads 1 2] [--repeat 2] [--json]
"""

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time

import numpy as np


class _Captured(Exception):
    """Raised by the stand-in filter once it holds the inputs."""


def capture(scenario_name, path):
    """Run the scenario up to its tight filter and pickle the filter's arguments to ``path``."""
    from leosop.apps import simulate
    from leosop.apps.simulate import tight
    from leosop.apps.scenarios import load_scenario

    def stand_in(*args, **kwargs):
        with open(path, "wb") as f:
            pickle.dump((args, kwargs), f)
        raise _Captured

    real, tight.run = tight.run, stand_in
    try:
        simulate.run_scenario(load_scenario(scenario_name), level="measurement", coupling="tight", seed=0)
    except _Captured:
        pass
    finally:
        tight.run = real


def time_filter(path, repeat):
    """Best wall time of the tight filter on the pickled inputs, and a digest of its result."""
    from leosop.apps.simulate import tight

    with open(path, "rb") as f:
        args, kwargs = pickle.load(f)
    best = np.inf
    for _ in range(repeat):
        tic = time.perf_counter()
        res = tight.run(*args, **kwargs)
        best = min(best, time.perf_counter() - tic)
    pairs = args[3]
    n_dopplers = int(np.count_nonzero((pairs["epoch_index"] > 0) & np.isfinite(pairs["doppler_hz"])))
    return {"threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"), "time_s": best,
            "n_dopplers": n_dopplers, "us_per_doppler": 1e6 * best / max(n_dopplers, 1),
            "n_updates": int(res.updated.sum()), "n_rejected": int(res.rejected.sum()),
            "nis_sum": float(np.nansum(res.nis)), "lat_end_rad": float(res.lat_rad[-1]),
            "lon_end_rad": float(res.lon_rad[-1]), "alt_end_m": float(res.alt_m[-1])}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="xian-baoji")
    p.add_argument("--threads", nargs="+", default=["1", "2"])
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--json", action="store_true")
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(time_filter(args.child, args.repeat)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "inputs.pkl")
        capture(args.scenario, path)
        rows = []
        for n in args.threads:
            env = dict(os.environ, OPENBLAS_NUM_THREADS=n)
            proc = subprocess.run([sys.executable, __file__, "--child", path, "--repeat", str(args.repeat)], env=env,
                                  check=False, capture_output=True, text=True)
            if proc.returncode:
                raise SystemExit(f"timing with {n} thread(s) failed:\n{proc.stderr}")
            rows.append(json.loads(proc.stdout))
    if args.json:
        print(json.dumps({"scenario": args.scenario, "runs": rows}, indent=1))
        return
    for r in rows:
        print(f"{args.scenario}: {r['threads']} thread(s): {r['time_s']:.2f} s, {r['n_dopplers']} Doppler, "
              f"{r['us_per_doppler']:.0f} us each; {r['n_updates']} updates, {r['n_rejected']} rejected epochs, "
              f"NIS sum {r['nis_sum']:.6f}, end {r['lat_end_rad']:.12f} {r['lon_end_rad']:.12f} "
              f"{r['alt_end_m']:.6f}")


if __name__ == "__main__":
    main()
