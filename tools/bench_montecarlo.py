"""Scaling of ``leosop study montecarlo``: serial, 1 and 2 local Dask workers, same study, same run.

Runs one study (default: the bundled Table 5 spec cut to ``--seeds`` seeds
per cell) three times in fresh work directories: in this process, on a local
cluster of 1 worker process and of 2; checks that the three give identical
numbers and prints wall times and the 2-vs-1 speed-up. Then measures what the
chunking argument for a large cluster needs: the mean time per run, the
scheduler's cost per task (round trips of empty tasks) and a worker's peak
memory, and prints the efficiency a cluster of W workers would reach with
this study's chunks (whole chunks per worker, task overhead added).

The machine is shared: the load average before and after is printed with
the times, and the CPU seconds the work took (of this process, or summed
over the workers): on a busy machine the wall-time ratio understates the
scaling, the CPU time shows whether the work itself grew.

    OPENBLAS_NUM_THREADS=1 python tools/bench_montecarlo.py [--spec table5] [--seeds 4] [--runs-per-chunk 2]
"""

import argparse
import json
import math
import os
import resource
import tempfile
import time

import numpy as np

from leosop.apps.montecarlo import REPRODUCIBLE, METRICS, load_spec, run_study, spec_from_dict
from leosop.apps.scenarios import to_dict


def _peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _cpu_s():
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime


def _noop(x):
    return x


def _timed(spec, scheduler):
    with tempfile.TemporaryDirectory() as work:
        tic = time.perf_counter()
        run = run_study(spec, work, scheduler=scheduler)
        return time.perf_counter() - tic, run


def _on_cluster(spec, n_workers, n_empty=400):
    """Study wall time on a local cluster (started beforehand), the workers' CPU time in it, cluster start
    time, workers' peak RSS [MB] and the scheduler's cost per task (round trips of empty tasks)."""
    import logging

    from distributed import Client, LocalCluster, wait

    tic = time.perf_counter()
    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        start_s = time.perf_counter() - tic
        cpu0 = sum(client.run(_cpu_s).values())
        t, run = _timed(spec, client)
        cpu = sum(client.run(_cpu_s).values()) - cpu0
        rss = max(client.run(_peak_rss_mb).values())
        wait(client.map(_noop, range(8), pure=False))  # warm up
        tic = time.perf_counter()
        wait(client.map(_noop, range(n_empty), pure=False))
        return t, cpu, run, start_s, rss, (time.perf_counter() - tic) / n_empty


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spec", default="table5", help="spec file or bundled name (default table5)")
    ap.add_argument("--seeds", type=int, default=4, help="seeds per cell (default 4)")
    ap.add_argument("--runs-per-chunk", type=int, default=2, help="runs per chunk (default 2)")
    a = ap.parse_args()

    base = load_spec(a.spec)
    doc = json.loads(base.to_json())
    doc.update(n_seeds=a.seeds, runs_per_chunk=a.runs_per_chunk, scenario=to_dict(base.scenario))
    spec = spec_from_dict(doc, source=f"{base.name} ({a.seeds} seeds)")
    load0 = os.getloadavg()
    print(f"study {spec.name}: {spec.n_runs} runs in {math.ceil(spec.n_runs / spec.runs_per_chunk)} chunks of "
          f"{spec.runs_per_chunk}; {os.cpu_count()} cores; load average {load0[0]:.2f} (shared machine)")
    cpu0 = _cpu_s()
    t_serial, serial = _timed(spec, "serial")
    cpu_serial = _cpu_s() - cpu0
    t_1, cpu_1, one, start_1, rss_1, _ = _on_cluster(spec, 1)
    t_2, cpu_2, two, start_2, rss_2, task_s = _on_cluster(spec, 2)
    cols = [list(METRICS).index(k) for k in REPRODUCIBLE]
    same = all(np.array_equal(r.rows[:, cols], serial.rows[:, cols], equal_nan=True) for r in (one, two))
    run_s = float(np.mean(serial.rows[:, list(METRICS).index("runtime_s")]))
    print(f"{'where':<26}{'wall s':>8}{'runs/s':>8}{'CPU s':>8}  (CPU: of the process or the workers)")
    for name, t, cpu in (("serial (this process)", t_serial, cpu_serial), ("local cluster, 1 worker", t_1, cpu_1),
                         ("local cluster, 2 workers", t_2, cpu_2)):
        print(f"{name:<26}{t:8.1f}{spec.n_runs / t:8.2f}{cpu:8.1f}")
    print(f"speed-up 2 vs 1 worker: {t_1 / t_2:.2f}x (ideal 2.00); identical numbers in all three: {same}")
    print(f"cluster start (not in the times above): {start_1:.1f} s (1 worker), {start_2:.1f} s (2 workers); "
          f"load average after {os.getloadavg()[0]:.2f}")
    print(f"mean run {run_s:.2f} s; peak RSS of a worker {max(rss_1, rss_2):.0f} MB; "
          f"scheduler cost per task (empty tasks, 2 workers) {task_s * 1e3:.2f} ms")
    full = load_spec(a.spec)
    print(f"chunking of the full {full.name} spec ({full.n_runs} runs of ~{run_s:.1f} s): efficiency on W workers "
          "= work / (W x waves x (chunk + task cost)), whole chunks per worker")
    sizes = sorted({full.runs_per_chunk, 1})[::-1]
    print(f"{'workers':>8}" + "".join(f"{f'{k} run(s)/chunk':>20}" for k in sizes))
    for w in (1, 2, 8, 32, 128, 1024):
        cells = []
        for k in sizes:
            n_chunks, chunk_s = math.ceil(full.n_runs / k), k * run_s
            waves = math.ceil(n_chunks / w)
            cells.append(f"{n_chunks * chunk_s / (w * waves * (chunk_s + task_s)):20.2f}")
        print(f"{w:8d}" + "".join(cells))

if __name__ == "__main__":
    main()
