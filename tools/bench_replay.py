"""Replay benchmarks: identification, static fix, throughput and memory.

    python tools/bench_replay.py [--quick] [--memory-gb G] [--sats N] [--parts fix,throughput,threads,baseline,memory]
                                 [--tle FILE --start ISO] [--threads N] [--baseline-ref REF] [--repeats R]
                                 [--seconds S]

1. Static fix from 150 snapshots of 20 ms (2.5 MS/s, ``--sats`` of the
   satellites above 40 deg drawn per recording, along-track orbit errors of a few hundred metres and satellite
   clock offsets of a few Hz drawn by ``leosop generate``), identified against
   the element sets with a prior 100 km off. Beside it, in the same run, the
   ideal estimator that knows the identities (the recording's truth labels
   given to the same tracks, then the same solver), and both without the
   per-satellite time-offset states. Errors against the generating site.
2. Throughput: a continuous 2.5 MS/s recording with ``--sats`` of the
   satellites above 40 deg (7, as the goal), replayed in 0.1 s blocks; the
   real-time factor is recording length over processor time (one thread),
   for the streaming stage (read, search, track: what grows with the
   recording) and end to end (identification and fix run once per
   recording, a few seconds). Then one thread against ``--threads``
   (default 2) in the same run, alternating, best of the repeats: recording
   length over elapsed time of the streaming stage, their ratio, the load
   average beside them (on a shared machine other processes take the
   cores: Linux shares the CPU between sessions, so a second thread gains
   only what the others leave idle), and the bound idle cores allow: the
   search and tracking run on one thread, the reading and cleaning of the
   blocks (``leosop.replay.stream``) on all of them (the searching thread
   prepares blocks whenever it would wait), so the larger of the search's
   processor time and the whole over the threads; and the preparation alone
   on ``--threads`` threads with the search left out.
3. This tree against the baseline (``--baseline-ref``, default ``main``,
   exported with ``git archive``; ``none`` skips it), ``leosop replay
   --static --init ... --json`` of the same continuous recording with
   ``--threads 1`` and ``--threads N`` side by side, each run in a child
   process of its own, alternating, best of ``--repeats``: the processor time
   (user + system of all its threads, ``resource.getrusage`` round the
   command, interpreter start and imports left out; ``os.wait4`` of the whole
   child beside it) per second of recording, the real-time factor that gives
   on one core (recording length over processor time) and the elapsed one
   (over wall time), the load average beside them, and whether each code's
   runs give the same JSON byte for byte (and, where this tree's differs
   from the baseline's, by how much the fixes do). On a shared machine the
   elapsed times (and, less, the processor times) grow with the load:
   compare the columns of one run, not runs.
4. Memory: peak RSS of ``leosop replay`` on a large continuous recording
   (``--memory-gb``, generated whole), beside the peak
   RSS on the short one: bounded by the block, not the file.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from baseline_tree import REPO, export_package  # noqa: E402

from leosop.cli import main  # noqa: E402
from leosop.frames import geodetic_to_ecef  # noqa: E402
from leosop.orbits import load_constellation  # noqa: E402
from leosop.positioning.solve import position_static_passes  # noqa: E402
from leosop.replay.lo import LO_OFFSET_MAX_HZ  # noqa: E402
from leosop.replay.pipeline import block_plan, replay, search_band, track_measurements  # noqa: E402
from leosop.replay.stream import prepared_blocks  # noqa: E402
from leosop.signal.iq import open_sigmf  # noqa: E402
from leosop.signal.pilot import PilotComb  # noqa: E402

SITE = (34.342, 108.940, 400.0)
START = "2025-01-01T19:40:00Z"
INIT_ECEF = geodetic_to_ecef(np.radians(34.98), np.radians(109.71), 0.0)  # ~100 km off


#: Element sets and start of the generated recordings (``--tle``, ``--start``; default the bundled set).
SKY = {"tle": None, "start": START}


def _generate(path, *extra):
    argv = ["generate", "-o", str(path), "--site", ",".join(map(str, SITE)), "--start", SKY["start"],
            "--sample-rate-hz", "2.5e6", "--mask-deg", "40", *(["--tle", SKY["tle"]] if SKY["tle"] else []), *extra]
    if main(argv) != 0:
        raise SystemExit("generate failed")


def _visible(tmp, n_sats, seed):
    """``n_sats`` of the satellites above 40 deg at the start, drawn with ``seed`` (all if fewer)."""
    path = Path(tmp) / "probe.sigmf-meta"
    _generate(path, "--duration-s", "0.1")
    ids = [s["sat_id"] for s in json.loads(path.read_text())["global"]["leosop:satellites"]]
    return list(np.random.default_rng(seed).permutation(ids)[:n_sats])


def _truth_ids(rec, tracks):
    """The truth satellite of each track: the annotation nearest in Doppler at the track's blocks."""
    by_start = {}
    for a in rec.annotations:
        if "leosop:doppler_hz" in a:
            by_start.setdefault(round(a["leosop:t_s"], 3), []).append((a["leosop:sat_id"], a["leosop:doppler_hz"]))
    ids = []
    for tr in tracks:
        votes = {}
        for t, f in zip(tr.t_s, tr.doppler_hz):
            cands = by_start.get(round(t, 3)) or []
            if cands:
                sid, f_true = min(cands, key=lambda c: abs(c[1] - f))
                if abs(f_true - f) < 50.0:
                    votes[sid] = votes.get(sid, 0) + 1
        ids.append(max(votes, key=votes.get) if votes else None)
    return ids


def _error_m(position, site_ecef):
    f = position.fixes
    return float(np.linalg.norm(f.pos_ecef_m - site_ecef))


def bench_fix(tmp, seeds, n_sats):
    const = load_constellation(SKY["tle"])
    site = geodetic_to_ecef(np.radians(SITE[0]), np.radians(SITE[1]), SITE[2])
    rows = []
    for seed in seeds:
        path = Path(tmp) / f"snap{seed}.sigmf-meta"
        _generate(path, "--duration-s", "150", "--snapshot-s", "0.02", "--period-s", "1", "--seed", str(seed),
                  "--orbit-error-along-m", "300", "--sat-offset-max-hz", "5", "--sat", *_visible(tmp, n_sats, seed))
        rec = open_sigmf(path)
        t0 = time.perf_counter()
        res = replay(rec, const, block_s=0.02, init_pos_ecef_m=INIT_ECEF, static=True)
        run_s = time.perf_counter() - t0
        truth = _truth_ids(rec, res.tracks)
        got = [tr.sat_id for tr in res.tracks]
        right = sum(g is not None and g == t for g, t in zip(got, truth))
        wrong = sum(g is not None and g != t for g, t in zip(got, truth))
        for tr, t in zip(res.tracks, truth):
            tr.sat_id = t
        meas = track_measurements(res.tracks, rec.center_hz)
        ideal = position_static_passes(meas, meas.sat_id, constellation=const, init_pos_ecef_m=INIT_ECEF,
                                       clock="common")
        ideal_no_dt = position_static_passes(meas, meas.sat_id, constellation=const, init_pos_ecef_m=INIT_ECEF,
                                             clock="common", time_bias=False)
        rows.append((seed, len(got), right, wrong, _error_m(res.position, site), _error_m(ideal, site),
                     _error_m(ideal_no_dt, site), run_s))
        print(f"seed {seed}: {len(got)} tracks, {right} right, {wrong} wrong; fix {rows[-1][4]:.1f} m, "
              f"ideal {rows[-1][5]:.1f} m, ideal without time offsets {rows[-1][6]:.1f} m, replay {run_s:.1f} s",
              flush=True)
    a = np.array([r[1:] for r in rows], dtype=float)
    print(f"static fix, {len(const)} candidates, {n_sats} satellites, 150 x 20 ms snapshots, 300 m along-track "
          f"errors, {len(rows)} recordings: tracks "
          f"{int(a[:, 0].sum())}, identified right {int(a[:, 1].sum())}, wrong {int(a[:, 2].sum())}; "
          f"median error replay {np.median(a[:, 3]):.1f} m, ideal (identities known) {np.median(a[:, 4]):.1f} m, "
          f"ratio {np.median(a[:, 3]) / np.median(a[:, 4]):.2f}; without orbit-error states "
          f"{np.median(a[:, 5]):.1f} m")


def bench_throughput(tmp, seconds, n_sats, repeats=3):
    path = Path(tmp) / "cont.sigmf-meta"
    visible = _visible(tmp, n_sats, 1)
    _generate(path, "--duration-s", str(seconds), "--seed", "1", "--sat", *visible)
    rec = open_sigmf(path)
    const = load_constellation(SKY["tle"])
    runs = []
    for _ in range(repeats):  # the least CPU of a few runs: other processes only ever add to it
        t0 = time.process_time()
        res = replay(rec, const, block_s=0.1, init_pos_ecef_m=INIT_ECEF, static=True)
        runs.append((res.cpu_s["blocks"], time.process_time() - t0, res))
    blocks_s, total_s, res = min(runs, key=lambda r: r[0])
    cpu = res.cpu_s
    print(f"throughput: {seconds:g} s at 2.5 MS/s with {len(visible)} satellites (best of {repeats}; "
          f"load {os.getloadavg()[0]:.1f}): blocks (read, search, track) {blocks_s:.2f} s CPU = "
          f"{seconds / blocks_s:.1f}x real time (runs: {', '.join(f'{seconds / r[0]:.1f}x' for r in runs)}); "
          f"identification {cpu['identify']:.1f} s and fix {cpu['fix']:.1f} s once per recording; end to end "
          f"{seconds / total_s:.1f}x ({len(res.tracks)} tracks, {sum(t.sat_id is not None for t in res.tracks)} "
          "identified)")
    return path, rec, const


def _prepare_s(rec, threads=1):
    """Processor and elapsed time of reading, narrowing and cleaning every 0.1 s block, in one thread, or on
    ``threads`` threads with nothing else to do (the caller's thread among them: it only takes the blocks)."""
    comb = PilotComb(carrier_hz=rec.center_hz or PilotComb.carrier_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    factor = search_band(rec.sample_rate_hz, comb, LO_OFFSET_MAX_HZ)[0]
    t0, w0 = time.process_time(), time.perf_counter()
    for _ in prepared_blocks(rec, block_plan(rec, 0.1), factor, comb, threads=threads):
        pass
    return time.process_time() - t0, time.perf_counter() - w0


def _count(n):
    """A pure-Python loop of ``n`` steps (holds its own process's GIL throughout)."""
    s = 0
    for i in range(n):
        s += i
    return s


def _cores_available(workers, n=20_000_000):
    """Elapsed time of ``n`` loop steps in one process over the same split across ``workers`` processes.

    What the machine gives this benchmark's extra threads right now: ~``workers`` on idle cores, ~1
    when other sessions take them (Linux shares the CPU between sessions, not threads).
    """
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(_count, [1] * workers))  # started
        elapsed = []
        for k in (1, workers):
            t0 = time.perf_counter()
            list(pool.map(_count, [n // k] * k))
            elapsed.append(time.perf_counter() - t0)
    return elapsed[0] / elapsed[1]


def bench_threads(rec, const, seconds, threads, repeats=3):
    """One thread against ``threads`` on the same recording, alternating; best elapsed time of each."""
    wall = {1: [], threads: []}
    cpu = {1: [], threads: []}
    results = {}
    for _ in range(repeats):
        for n in wall:
            t0 = time.perf_counter()
            res = replay(rec, const, block_s=0.1, init_pos_ecef_m=INIT_ECEF, static=True, threads=n)
            wall[n].append((res.wall_s["blocks"], time.perf_counter() - t0))
            cpu[n].append(res.cpu_s["blocks"])
            results[n] = res
    same = all(np.array_equal(getattr(a, c), getattr(b, c)) and a.sat_id == b.sat_id
               for a, b in zip(results[1].tracks, results[threads].tracks)
               for c in ("t_s", "doppler_hz", "doppler_rate_hz_per_s", "cn0_dbhz", "sigma_hz"))
    same = same and len(results[1].tracks) == len(results[threads].tracks) and np.array_equal(
        results[1].position.fixes.pos_ecef_m, results[threads].position.fixes.pos_ecef_m)
    (b1, e1), (bn, en) = (min(wall[n]) for n in wall)
    prep = _prepare_s(rec)[0]
    prep_alone = min(_prepare_s(rec, threads)[1] for _ in range(repeats))
    serial_cpu = min(cpu[1])
    control = _cores_available(threads)
    bound = max(serial_cpu - prep, serial_cpu / threads)
    print(f"threads: {seconds:g} s recording, best of {repeats} alternating (load average "
          f"{', '.join(f'{v:.1f}' for v in os.getloadavg())} on {os.cpu_count()} cores): streaming 1 thread "
          f"{b1:.2f} s = {seconds / b1:.1f}x real time, {threads} threads {bn:.2f} s = {seconds / bn:.1f}x, "
          f"ratio {b1 / bn:.2f}; end to end {seconds / e1:.1f}x and {seconds / en:.1f}x, ratio {e1 / en:.2f}; "
          f"results {'identical' if same else 'DIFFERENT'}. Processor time of the streaming stage "
          f"{serial_cpu:.2f} s (1 thread), {min(cpu[threads]):.2f} s ({threads}); reading and cleaning {prep:.2f} s, "
          f"search and tracking {serial_cpu - prep:.2f} s: on idle cores at most "
          f"{serial_cpu / bound:.2f}x the serial speed, {seconds / bound:.1f}x real time (the search runs on one "
          f"thread, the preparation on all). The preparation alone on {threads} "
          f"threads (no search) {prep_alone:.2f} s = {seconds / prep_alone:.1f}x real time. "
          f"Control: a pure-Python loop split across "
          f"{threads} processes ran {control:.2f}x as fast as in one (the cores this run was given)")


#: A child's replay: the CLI with its JSON to a file, processor and elapsed time round it (after the imports,
#: the command's lazy ones too: they are once per process, not per second of recording).
_CHILD = """
import json, os, resource, sys, time
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
from leosop.cli import main
import leosop.cli.replay, leosop.positioning.solve, leosop.replay.pipeline  # the command's own imports, untimed
out, argv = sys.argv[1], sys.argv[2:]
r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
with open(out, "w") as fh:
    sys.stdout = fh
    rc = main(argv)
    sys.stdout = sys.__stdout__
r1 = resource.getrusage(resource.RUSAGE_SELF)
cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
print(json.dumps({"rc": rc, "cpu_s": cpu, "wall_s": time.perf_counter() - t0}), file=sys.stderr)
"""


def _child_replay(code_dir, rec_path, threads, out):
    """One ``leosop replay`` of ``rec_path`` in a child importing ``code_dir``'s package:
    (processor s of the replay, elapsed s of it, processor s of the whole child)."""
    env = dict(os.environ, PYTHONPATH=str(code_dir), OPENBLAS_NUM_THREADS="1")
    argv = ["replay", str(rec_path), "--static", "--init", ",".join(map(str, (34.98, 109.71, 0.0))), "--json",
            "--threads", str(threads)]
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(out), *argv], cwd=code_dir, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stderr = proc.stderr.read().decode()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{code_dir}: replay failed: {stderr.strip()[-2000:]}")
    got = json.loads(stderr.strip().splitlines()[-1])
    return got["cpu_s"], got["wall_s"], usage.ru_utime + usage.ru_stime


def bench_baseline(tmp, rec_path, seconds, threads, ref, repeats=3):
    """This tree and the baseline ``ref``, one thread and ``threads``, alternating; best of ``repeats`` each."""
    codes = [("this tree", REPO)]
    if ref != "none":
        base = Path(tmp) / "baseline"
        base.mkdir()
        export_package(ref, base)
        codes.append((ref, base))
    runs = {(name, n): [] for name, _ in codes for n in (1, threads)}
    outputs = {name: [] for name, _ in codes}
    for r in range(repeats):
        for name, code_dir in codes:
            for n in (1, threads):
                out = Path(tmp) / f"replay_{sum(map(len, outputs.values()))}.json"
                runs[name, n].append(_child_replay(code_dir, rec_path, n, out) + (os.getloadavg()[0],))
                outputs[name].append(out.read_bytes())
    print(f"replay of {seconds:g} s (2.5 MS/s, continuous) in child processes, best of {repeats} alternating, "
          f"{os.cpu_count()} cores; CPU = user + system of all threads round the command (whole child with "
          f"interpreter start in brackets); x real time on one core = recording / CPU, elapsed = recording / wall")
    print(f"{'code':>16} {'threads':>7} {'CPU s':>7} {'CPU s/s':>8} {'x (1 core)':>10} {'wall s':>7} "
          f"{'x elapsed':>9} {'load':>5}")
    for (name, n), rows in runs.items():
        cpu, wall, whole, load = min(rows)
        best_wall = min(rw[1] for rw in rows)
        print(f"{name:>16} {n:>7} {cpu:>7.2f} {cpu / seconds:>8.3f} {seconds / cpu:>10.1f} {best_wall:>7.2f} "
              f"{seconds / best_wall:>9.1f} {load:>5.1f}   ({whole:.2f} s whole child)")
    for name, docs in outputs.items():
        print(f"JSON of the {len(docs)} runs of {name}: "
              f"{'identical' if all(o == docs[0] for o in docs) else 'DIFFERENT'}")
    if len(outputs) == 2:
        a, b = (json.loads(docs[0]) for docs in outputs.values())
        if a == b:
            print("JSON of this tree and the baseline identical")
        else:
            fix = [np.array([s[c] for s in d["solutions"] for c in ("x_m", "y_m", "z_m")]) for d in (a, b)]
            gap = (f"{np.max(np.abs(fix[0] - fix[1])):.2g} m" if fix[0].shape == fix[1].shape and fix[0].size
                   else "different fixes" if fix[0].shape != fix[1].shape else "none in either (other keys)")
            print(f"JSON of this tree and the baseline differ: fix positions by {gap}")


def _peak_rss_mb(argv):
    code = ("import resource, sys; from leosop.cli import main; rc = main(sys.argv[1:]); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, file=sys.stderr); sys.exit(rc)")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    return float(out.stderr.strip().splitlines()[-1])


def bench_memory(tmp, small, gigabytes, n_sats):
    """Peak RSS of replay on a continuous recording of ``gigabytes`` beside the short one's.

    The long recording is generated whole (cf32 at 2.5 MS/s: 20 MB per second), not tiled from
    the short one: tiling breaks every track at each seam, and hundreds of fragments would
    measure the identification of fragments rather than a recording people make.
    """
    big = Path(tmp) / "big.sigmf-meta"
    seconds = gigabytes * 1e9 / (2.5e6 * 8)
    _generate(big, "--duration-s", f"{seconds:.1f}", "--seed", "1", "--sat", *_visible(tmp, n_sats, 1))
    size_gb = big.with_suffix(".sigmf-data").stat().st_size / 1e9
    init = "34.98,109.71,0"
    small_mb = _peak_rss_mb(["replay", str(small), "--static", "--init", init, "--json"])
    t0 = time.perf_counter()
    big_mb = _peak_rss_mb(["replay", str(big), "--static", "--init", init, "--json"])
    print(f"memory: peak RSS {small_mb:.0f} MB on {small.with_suffix('.sigmf-data').stat().st_size / 1e6:.0f} MB, "
          f"{big_mb:.0f} MB on {size_gb:.1f} GB ({seconds:.0f} s continuous; ratio {big_mb / small_mb:.2f}; "
          f"{time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="2 recordings instead of 10, 5 s continuous")
    ap.add_argument("--memory-gb", type=float, default=3.0, help="size of the memory test file (0 to skip)")
    ap.add_argument("--sats", type=int, default=7, help="satellites per recording, drawn from those above "
                    "40 deg (default 7)")
    ap.add_argument("--tle", help="element sets to draw the satellites from and identify against (default the "
                    "bundled Walker set), e.g. ../shared/data/tle/starlink_3le_2026-04-08_Bochika.txt")
    ap.add_argument("--start", default=START, help=f"UTC start of the recordings (default {START})")
    ap.add_argument("--parts", default="fix,throughput,threads,baseline,memory", help="which benchmarks, "
                    "comma-separated (default fix,throughput,threads,baseline,memory)")
    ap.add_argument("--baseline-ref", default="main", help="git ref the baseline part compares with (default main; "
                    "'none': this tree alone)")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each configuration in the baseline part")
    ap.add_argument("--threads", type=int, default=2, help="threads compared with one (default 2)")
    ap.add_argument("--seconds", type=float, help="length of the continuous recording (default 20 s, 5 s with "
                    "--quick): what is once per recording (imports, identification, fix) weighs less in a "
                    "longer one")
    a = ap.parse_args()
    parts = set(a.parts.split(","))
    SKY.update(tle=a.tle, start=a.start)
    with tempfile.TemporaryDirectory() as tmp:
        if "fix" in parts:
            bench_fix(tmp, range(2) if a.quick else range(10), a.sats)
        seconds = a.seconds or (5.0 if a.quick else 20.0)
        if parts & {"throughput", "threads", "baseline", "memory"}:
            small, rec, const = bench_throughput(tmp, seconds, a.sats)
        if "threads" in parts:
            bench_threads(rec, const, seconds, a.threads)
        if "baseline" in parts:
            bench_baseline(tmp, small, seconds, a.threads, a.baseline_ref, a.repeats)
        if "memory" in parts and a.memory_gb > 0:
            bench_memory(tmp, small, a.memory_gb, a.sats)
