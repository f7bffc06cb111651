"""Replay of many recordings, serially or on Dask, one output folder each, resumable.

``leosop replay A B C ... --out DIR`` (or a folder of ``*.sigmf-meta``) runs
the single-recording replay on every recording and writes its files (the
same names and contents as ``leosop replay REC --out DIR/REC``) into
``DIR/<name>/``, where ``<name>`` is the file name without ``.sigmf-meta``.
The caller gives the work as ``run_one(meta_path) -> (doc, files)``: the
replay document and the bytes of each output file, made in a private
temporary folder wherever it runs; this module times it, writes the files on
the client (:func:`leosop.fileio.atomic_files`: a folder is complete or keeps
what it had) and keeps the ledger.

The ledger is ``DIR/batch.json``, the batch summary, rewritten atomically
after every recording: per recording its status, identified count, fix and
runtime, and a key (SHA-256 of the options the caller passes, the
recording's files, size and modification time, and :func:`leosop.chunkstore.code_digest`).
A recording whose ledger entry is ``done`` with the same key and whose
``replay.json`` is on disk is not run again: the same command resumes an
interrupted batch, and a changed option, recording or code reruns it.

Where it runs is ``scheduler`` as in :mod:`leosop.parallel`: ``"serial"`` in
this process, None a local cluster of single-threaded worker processes, an
address or a ``distributed.Client``. A recording depends only on its own
file and the options, never on where or in which order it runs, so the
results are those of the serial run; a worker that dies has its recording
given to another by the scheduler. On a remote cluster the recordings and
the element-set file must be readable at the same paths on every worker;
the output folder only on the client.
"""

import hashlib
import json
import time
from pathlib import Path

from ..chunkstore import code_digest
from ..errors import InputError
from ..fileio import atomic_files, write_json
from ..parallel import run_tasks
from ..progress import progress

__all__ = ["LEDGER", "batch_recordings", "run_batch"]

#: The batch summary and resume ledger in the output folder.
LEDGER = "batch.json"
_SUFFIX = ".sigmf-meta"


def batch_recordings(paths):
    """The recordings of ``paths`` (files, or folders of ``*.sigmf-meta``), with their output folder names.

    Parameters
    ----------
    paths : sequence of str or Path
        As given on the command line.

    Returns
    -------
    list of (Path, str)
        Each recording's ``.sigmf-meta`` path and its name (the file name
        without the suffix), in the order given, folders sorted by name.

    Raises
    ------
    InputError
        A folder without recordings, or two recordings of one name (their
        results would share a folder).
    """
    metas = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob(f"*{_SUFFIX}"))
            if not found:
                raise InputError(f"{p}: no *{_SUFFIX} recording in this folder")
            metas += found
        else:
            metas.append(p)
    seen = {}
    for meta in metas:
        name = meta.name[:-len(_SUFFIX)] if meta.name.endswith(_SUFFIX) else meta.stem
        if name in seen:
            raise InputError(f"{meta}: same name as {seen[name]}; their results would share the folder {name}/")
        seen[name] = meta
    return [(meta, name) for name, meta in seen.items()]


def _key(options, meta):
    """SHA-256 (hex) of what a recording's result depends on: options, its two files, the code."""
    files = [meta, meta.with_suffix(".sigmf-data")]
    stats = [[str(f.resolve()), f.stat().st_size, f.stat().st_mtime_ns] if f.is_file() else None for f in files]
    text = json.dumps({"options": options, "files": stats, "code": code_digest()}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _timed(run_one, meta):
    """``run_one(meta)`` and its wall time in seconds, measured where it runs."""
    tic = time.perf_counter()
    doc, files = run_one(meta)
    return doc, files, time.perf_counter() - tic


def _entry(name, meta, key, doc, runtime_s):
    """The summary of one finished replay (a ``replay`` document, DESIGN 4.1)."""
    sols = doc["solutions"]
    fix = None
    if doc["mode"] == "static" and sols:
        fix = {k: sols[0].get(k) for k in ("lat_deg", "lon_deg", "alt_m", "status", "sigma_enu_m", "n_sats")}
    return {"name": name, "recording": str(meta), "status": "done", "n_tracks": len(doc["tracks"]),
            "n_identified": doc["n_identified"], "n_blocks": doc["n_blocks"], "mode": doc["mode"],
            "n_solutions": len(sols), "n_solutions_ok": sum(s.get("status") == "ok" for s in sols), "fix": fix,
            "runtime_s": runtime_s, "resumed": False, "key": key}


def _failed(name, meta, key, exc):
    kind = "input" if isinstance(exc, InputError) else "error"
    return {"name": name, "recording": str(meta), "status": "failed", "error_kind": kind,
            "error": " ".join(f"{'' if kind == 'input' else type(exc).__name__ + ': '}{exc}".split()),
            "runtime_s": None, "resumed": False, "key": key}


def _ledger(out_dir):
    """Entries of a previous batch in ``out_dir`` by name ({} when absent or unreadable)."""
    try:
        doc = json.loads((out_dir / LEDGER).read_text())
        return {e["name"]: e for e in doc["recordings"]}
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def run_batch(run_one, recordings, out_dir, *, options, scheduler=None, n_workers=None, desc="replay"):
    """Replay every recording not already done in ``out_dir``; write each one's files and the ledger.

    Parameters
    ----------
    run_one : callable
        ``run_one(meta_path) -> (doc, files)``: the ``replay`` document and
        ``{file name: bytes}``; picklable (a ``functools.partial`` of a
        module-level function) for worker processes.
    recordings : list of (Path, str)
        From :func:`batch_recordings`.
    out_dir : Path
        Receives ``<name>/`` per recording and :data:`LEDGER`.
    options : dict
        JSON-able values of everything besides the recording that the result
        depends on (part of the resume key).
    scheduler, n_workers
        Where it runs (module docstring); workers of a local cluster
        (default: the cores, at most one per recording).
    desc : str
        Progress-bar label (stderr, terminals only).

    Returns
    -------
    dict
        The batch summary, also in ``out_dir/batch.json``: ``recordings``
        (one entry per recording, in the order given), ``n_recordings``,
        ``n_run`` (replayed now), ``n_resumed``, ``n_failed``, ``n_workers``
        (Dask workers at the start; 0 in this process or with nothing to
        run), ``elapsed_s`` (this call) and ``out``. Entry keys: ``name``,
        ``recording``, ``status`` (``done`` or ``failed``), ``runtime_s`` (of
        the replay where it ran; of the first run when resumed), ``resumed``,
        ``key``; when done ``n_tracks``, ``n_identified``, ``n_blocks``,
        ``mode``, ``n_solutions``, ``n_solutions_ok`` and ``fix`` (the static
        fix's position, status and sigmas, else null); when failed ``error``
        and ``error_kind`` (``input`` for bad input found in the recording,
        else ``error``).
    """
    tic = time.perf_counter()
    out_dir = Path(out_dir)
    old = _ledger(out_dir)
    entries, todo = {}, []
    for meta, name in recordings:
        key = _key(options, meta)
        prev = old.get(name)
        if (prev and prev.get("key") == key and prev.get("status") == "done"
                and (out_dir / name / "replay.json").is_file()):
            entries[name] = {**prev, "recording": str(meta), "resumed": True}
        else:
            todo.append((meta, name, key))
    order = [name for _, name in recordings]

    def summary(workers):
        done = [entries[n] for n in order if n in entries]
        return {"recordings": done, "n_recordings": len(order), "n_run": sum(not e["resumed"] for e in done),
                "n_resumed": sum(e["resumed"] for e in done), "n_failed": sum(e["status"] == "failed" for e in done),
                "n_workers": workers, "elapsed_s": time.perf_counter() - tic, "out": str(out_dir)}

    def finish(meta, name, key, outcome):
        if isinstance(outcome, Exception):
            entries[name] = _failed(name, meta, key, outcome)
        else:
            doc, files, runtime_s = outcome
            with atomic_files([out_dir / name / f for f in files]) as tmps:
                for tmp, data in zip(tmps, files.values()):
                    tmp.write_bytes(data)
            entries[name] = _entry(name, meta, key, doc, runtime_s)
        write_json(out_dir / LEDGER, summary(None))  # the ledger so far: what a rerun resumes

    def done(k, outcome):  # a Dask task's result, or its exception: a recording's failure is data
        finish(*todo[k], outcome)

    workers = 0
    with progress(total=len(todo), desc=desc, unit="recording") as bar:
        if scheduler == "serial":
            for meta, name, key in todo:
                try:
                    outcome = _timed(run_one, meta)
                except Exception as exc:  # a recording's failure is data; the batch goes on
                    outcome = exc
                finish(meta, name, key, outcome)
                bar.update(1)
        elif todo:
            workers = run_tasks(_timed, ((run_one, meta) for meta, _, _ in todo), n_tasks=len(todo),
                                scheduler=scheduler, n_workers=n_workers, bar=bar,
                                on_result=done, on_error=done)
    doc = summary(workers)
    write_json(out_dir / LEDGER, doc)
    return doc

