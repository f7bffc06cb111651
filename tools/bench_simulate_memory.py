"""Peak memory of a long ``leosop simulate`` run against a short one (does memory grow with duration?).

For each duration: the xian-baoji scenario with ``duration_s`` set (the last
leg flown on beyond Baoji), run at measurement level as a child process
``python -m leosop simulate --scenario FILE --level measurement --json``;
its peak resident set size from ``os.wait4``'s rusage (``ru_maxrss``, kB
on Linux). Printed beside it: what a run needs to keep, the bytes of the
numpy arrays held by its :class:`leosop.apps.simulate.SimulationResult` (1 Hz
outputs), in all and per fix epoch; the 100 Hz truth and IMU, and the
Doppler and snapshot fixes, are made and consumed a block at a time, so a
flat memory means the peak grows by no more than that. ``peak_ratio`` is
each run's peak over the first's.

Usage: python tools/bench_simulate_memory.py [--durations-s 3600 21600]
"""

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from leosop.apps.scenarios import XIAN_BAOJI


def peak_rss_kb(scenario_file):
    """Run ``leosop simulate`` on ``scenario_file`` in a child; its peak RSS [kB] and JSON output."""
    cmd = [sys.executable, "-m", "leosop", "simulate", "--scenario", str(scenario_file), "--level", "measurement",
           "--json"]
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode:
            raise SystemExit(f"{' '.join(cmd)} failed with exit {proc.returncode}")
        out.seek(0)
        return usage.ru_maxrss, json.loads(out.read())


def result_bytes(result):
    """Bytes of the numpy arrays a SimulationResult holds (nested dataclasses included)."""
    total = 0
    for f in dataclasses.fields(result):
        v = getattr(result, f.name)
        if isinstance(v, np.ndarray):
            total += v.nbytes
        elif dataclasses.is_dataclass(v) and not isinstance(v, type):
            total += result_bytes(v)
    return total


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--durations-s", type=float, nargs="+", default=[3600.0, 21600.0])
    a = ap.parse_args()
    from leosop.apps.simulate import run_scenario

    print(f"{'duration_s':>10} {'peak_rss_MB':>11} {'peak_ratio':>10} {'result_MB':>9} {'result_B_per_epoch':>18} "
          f"{'runtime_s':>9}")
    first_kb = None
    with tempfile.TemporaryDirectory() as tmp:
        for duration_s in a.durations_s:
            path = Path(tmp) / f"xb_{duration_s:.0f}.json"
            path.write_text(json.dumps({"name": f"xian-baoji-{duration_s:.0f}s", "duration_s": duration_s}))
            rss_kb, doc = peak_rss_kb(path)
            first_kb = first_kb or rss_kb
            # Retained outputs, measured in this process (a separate run: its peak does not mix with the child's).
            sc = dataclasses.replace(XIAN_BAOJI, duration_s=duration_s)
            res = run_scenario(sc, level="measurement")
            kept = result_bytes(res)
            print(f"{duration_s:10.0f} {rss_kb / 1024:11.1f} {rss_kb / first_kb:10.2f} {kept / 1e6:9.1f} "
                  f"{kept / res.t_s.size:18.0f} {doc['runtime_s']:9.1f}", flush=True)
            del res


if __name__ == "__main__":
    main()
