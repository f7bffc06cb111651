"""``leosop replay A B C ...``: a batch serially and on a local Dask cluster of 2 workers, same recordings, one run.

Generates ``--n`` small recordings with ``leosop generate`` in a temporary
folder (snapshot captures at the bundled scenario's site, one start time and
seed each), then runs the batch command three times into fresh folders:

1. ``--scheduler serial`` (this process): the reference;
2. on a local cluster of ``--workers`` single-threaded worker processes,
   started beforehand (its start time is printed apart): the speed-up;
3. on a fresh cluster of the same size, one worker killed (SIGKILL) once the
   first recording is done while it is replaying another: the scheduler gives
   that recording to another worker (its nanny starts a new one).

Runs 2 and 3 must give the serial results: every file of every recording's
folder byte for byte, and the batch summaries equal apart from runtimes.
Finally the serial command run again on run 3's folder must resume
everything (nothing replayed). Progress on stderr, the table on stdout; the
load average is printed because the machine is shared.

    OPENBLAS_NUM_THREADS=1 python tools/bench_replay_batch.py [--n 8] [--duration-s 10] [--workers 2]
"""

import argparse
import contextlib
import io
import json
import logging
import os
import resource
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

from leosop.cli import main as leosop
from leosop.replay.batch import LEDGER

SITE = "34.342,108.94,400"  # Xi'an, the bundled scenario's start
INIT = "34.98,109.71,0"  # a prior 100 km off, as the replay tests use


def _cpu_s():
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime


def _say(text):
    print(text, file=sys.stderr, flush=True)


def _cli(argv):
    """Exit status and stdout of one ``leosop`` command run in this process."""
    with contextlib.redirect_stdout(io.StringIO()) as out:
        code = leosop(argv)
    return code, out.getvalue()


def _generate(folder, n, duration_s):
    paths = []
    for k in range(n):
        path = folder / f"rec{k:02d}.sigmf-meta"
        start = f"2025-01-01T19:{40 + k // 2:02d}:{30 * (k % 2):02d}Z"  # 30 s apart
        code, _ = _cli(["generate", "-o", str(path), "--site", SITE, "--start", start, "--sample-rate-hz", "1e6",
                        "--seed", str(k), "--duration-s", str(duration_s), "--snapshot-s", "0.01",
                        "--period-s", "1", "--mask-deg", "40"])
        if code:
            raise SystemExit(f"leosop generate failed for {path}")
        paths.append(path)
        _say(f"generated {k + 1}/{n}: {path.name}")
    return paths


def _batch(paths, out, scheduler):
    tic = time.perf_counter()
    code, text = _cli(["replay", *map(str, paths), "--init", INIT, "--static", "--mask-deg", "40",
                       "--scheduler", scheduler, "--out", str(out), "--json"])
    if code:
        raise SystemExit(f"leosop replay batch on {scheduler} failed (exit {code})")
    return time.perf_counter() - tic, json.loads(text)


def _same(out, ref, doc, ref_doc):
    """Every file of every recording folder equal byte for byte, and the entries apart from runtimes."""
    strip = lambda d: [{k: v for k, v in e.items() if k not in ("runtime_s", "resumed")}  # noqa: E731
                       for e in d["recordings"]]
    files = sorted(p.relative_to(ref) for p in ref.rglob("*") if p.is_file() and p.name != LEDGER)
    other = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file() and p.name != LEDGER)
    return (files == other and all((out / f).read_bytes() == (ref / f).read_bytes() for f in files)
            and strip(doc) == strip(ref_doc))


def _warm():
    """Import what a replay imports (this process did so while generating): not part of the batch's time."""
    import leosop.cli.replay  # noqa: F401
    import leosop.plots.spectra  # noqa: F401
    import leosop.replay.pipeline  # noqa: F401
    from leosop.plots.core import pyplot

    pyplot()


@contextlib.contextmanager
def _cluster(n_workers):
    """Scheduler address, client and start time (workers up and warmed) of a local cluster."""
    from distributed import Client, LocalCluster

    tic = time.perf_counter()
    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster) as client:
        client.run(_warm)
        yield cluster.scheduler_address, client, time.perf_counter() - tic


def _killed_run(paths, out, n_workers):
    """The batch on a fresh cluster with one busy worker killed after the first recording is done."""
    with _cluster(n_workers) as (address, client, _):
        pids = client.run(os.getpid)
        outcome = {}

        def run():
            try:
                outcome["result"] = _batch(paths, out, address)
            except BaseException as exc:  # reported by the main thread
                outcome["error"] = exc

        thread = threading.Thread(target=run)
        thread.start()
        deadline = time.monotonic() + 600
        while not (out / LEDGER).is_file() and time.monotonic() < deadline and thread.is_alive():
            time.sleep(0.01)
        busy = [w for w, keys in client.processing().items() if keys]
        n_done = len(json.loads((out / LEDGER).read_text())["recordings"]) if (out / LEDGER).is_file() else 0
        if busy:
            os.kill(pids[busy[0]], signal.SIGKILL)
            _say(f"killed worker {busy[0]} (pid {pids[busy[0]]}) with {n_done} of {len(paths)} recordings done")
        thread.join()
        if "error" in outcome:
            raise outcome["error"]
        alive = set(client.scheduler_info()["workers"])
    return outcome["result"], bool(busy) and busy[0] not in alive, n_done


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=8, help="recordings in the batch (default 8)")
    ap.add_argument("--duration-s", type=float, default=10.0, help="span of each recording (default 10 s: "
                                                                      "10 snapshots of 10 ms at 1 MS/s)")
    ap.add_argument("--workers", type=int, default=2, help="local Dask workers (default 2)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-replay-batch-") as tmp:
        tmp = Path(tmp)
        (tmp / "recs").mkdir()
        paths = _generate(tmp / "recs", a.n, a.duration_s)
        load0 = os.getloadavg()[0]
        _say("serial batch ...")
        cpu0 = _cpu_s()
        t_serial, serial = _batch(paths, tmp / "serial", "serial")
        cpu_serial = _cpu_s() - cpu0
        _say(f"serial: {t_serial:.1f} s; batch on {a.workers} Dask workers ...")
        with _cluster(a.workers) as (address, client, start_s):
            cpu0, cpu_client0 = sum(client.run(_cpu_s).values()), _cpu_s()
            t_dask, dask = _batch(paths, tmp / "dask", address)
            cpu_dask, cpu_client = sum(client.run(_cpu_s).values()) - cpu0, _cpu_s() - cpu_client0
        _say(f"dask: {t_dask:.1f} s; batch with a worker killed ...")
        tic = time.perf_counter()
        (_, killed), died, n_done = _killed_run(paths, tmp / "killed", a.workers)
        t_killed = time.perf_counter() - tic
        same = {"dask": _same(tmp / "dask", tmp / "serial", dask, serial),
                "killed": _same(tmp / "killed", tmp / "serial", killed, serial)}
        _say("the serial command again on the killed run's folder ...")
        _, again = _batch(paths, tmp / "killed", "serial")
        mean_s = {k: sum(e["runtime_s"] for e in d["recordings"]) / a.n for k, d in (("serial", serial),
                                                                                      ("dask", dask))}
        print(f"{a.n} recordings of {a.duration_s:g} s (10 ms snapshots every 1 s at 1 MS/s); {os.cpu_count()} cores; "
              f"load average {load0:.2f} before, {os.getloadavg()[0]:.2f} after (shared machine)")
        print(f"{'run':<40}{'wall s':>8}{'CPU s':>8}{'replay s':>10}  identical to serial")
        print(f"{'serial (this process)':<40}{t_serial:8.1f}{cpu_serial:8.1f}{mean_s['serial']:10.2f}  -")
        print(f"{f'local Dask, {a.workers} workers':<40}{t_dask:8.1f}{cpu_dask:8.1f}{mean_s['dask']:10.2f}  "
              f"{same['dask']}")
        print(f"{f'local Dask, {a.workers} workers, one killed':<40}{t_killed:8.1f}{'':>18}  {same['killed']}  "
              "(incl. cluster start)")
        print("CPU s: of this process, or summed over the workers (the client's own: "
              f"{cpu_client:.1f} s); replay s: mean wall time of one recording's replay where it ran")
        print(f"speed-up serial / {a.workers} workers: {t_serial / t_dask:.2f}x (cluster start and worker imports "
              f"{start_s:.1f} s not included); identified per recording: "
              f"{[e['n_identified'] for e in serial['recordings']]}")
        print(f"killed run: worker died and was replaced: {died} ({n_done} recording(s) done at the kill); "
              f"failed {killed['n_failed']}; the serial command again resumed {again['n_resumed']} of {a.n}, "
              f"replayed {again['n_run']}")


if __name__ == "__main__":
    main()
