"""Run a study's chunks serially or on Dask, keeping every finished chunk on disk.

The runs of a study are numbered in C order over ``spec.shape`` (grid cells,
then seeds) and cut into chunks of ``spec.runs_per_chunk`` consecutive runs.
A run's numbers depend only on its cell and its seed (:func:`run_seeds`), never
on the chunking, the worker or the order: serial, local-cluster and remote
runs are identical.

Dask: the client keeps at most ``2 x workers`` chunks in flight (at least 4)
and submits the next as one finishes, so the scheduler and the client hold a
bounded number of tasks however large the study; a worker runs one simulation
at a time (single-threaded workers), so its memory is that of one run. When a
worker dies, the scheduler gives its chunks to another worker; they are pure
functions of their runs, so the result is unchanged. Each finished chunk is
written by the client to the work directory (:class:`leosop.chunkstore.ChunkStore`,
``chunk-NNNNNN.npz``: its run indices and metric rows); a study run again with
the same work directory skips those chunks. On a remote
cluster the element-set file (``spec.tle``) must be readable at the same path
on every worker.
"""

import dataclasses
import time

import numpy as np

from ...chunkstore import ChunkStore
from ...parallel import run_tasks
from ...progress import progress
from .parameters import apply
from .runs import METRICS, run_chunk
from .spec import run_seeds

__all__ = ["StudyRun", "chunk_runs", "run_study"]


@dataclasses.dataclass(frozen=True)
class StudyRun:
    """The outcome of :func:`run_study`.

    Attributes
    ----------
    rows : ndarray, (n_runs, n_metrics)
        One row of :data:`leosop.apps.montecarlo.runs.METRICS` per run, C order over ``spec.shape``.
    n_chunks, n_resumed : int
        Chunks in the study, and those found finished in the work directory.
    elapsed_s : float
        Wall time of this call.
    n_workers : int
        Dask workers at the start (0 for a serial run).
    """

    rows: np.ndarray
    n_chunks: int
    n_resumed: int
    elapsed_s: float
    n_workers: int


def chunk_runs(spec):
    """Run indices of each chunk: list of (n,) int arrays."""
    starts = range(0, spec.n_runs, spec.runs_per_chunk)
    return [np.arange(a, min(a + spec.runs_per_chunk, spec.n_runs)) for a in starts]


def _name(index):
    return f"chunk-{index:06d}"


def _load(store, index, run_index):
    """Rows of a finished chunk holding exactly ``run_index``, else None."""
    data = store.load(_name(index))
    if data is None or not np.array_equal(data.get("run_index"), run_index):
        return None
    rows = data.get("rows")
    return rows if rows is not None and rows.shape == (len(run_index), len(METRICS)) else None


def _save(store, index, run_index, rows):
    store.save(_name(index), run_index=run_index, rows=rows)


def _payloads(spec):
    """A function from a chunk's run indices to its picklable ``run_chunk`` argument."""
    configs = [apply(spec.scenario, cell, spec.source) for cell in spec.cells()]
    seeds = run_seeds(spec)

    def payload(run_index):
        return [(*configs[i // spec.n_seeds], spec.tle, int(seeds[i % spec.n_seeds])) for i in run_index]

    return payload


def run_study(spec, work_dir, *, scheduler=None, n_workers=None, desc="montecarlo"):
    """Every run of ``spec``, resuming from the chunks already in ``work_dir``.

    Parameters
    ----------
    spec : leosop.apps.montecarlo.spec.StudySpec
    work_dir : path-like
        The study's chunk directory (created if needed, kept: the caller
        removes it once the final output is written).
    scheduler : None, "serial", str or distributed.Client
        As in :mod:`leosop.parallel`: a local cluster (None), this process,
        a scheduler address (unreachable: ExternalError) or a client.
    n_workers : int, optional
        Workers of the local cluster (default: the cores).
    desc : str
        Progress-bar label (stderr, terminals only).

    Returns
    -------
    StudyRun
    """
    tic = time.perf_counter()
    store = ChunkStore(work_dir)
    chunks = chunk_runs(spec)
    todo = [i for i, runs in enumerate(chunks) if _load(store, i, runs) is None]
    payload = _payloads(spec)
    workers = 0
    with progress(total=len(todo), desc=desc, unit="chunk") as bar:
        if scheduler == "serial":
            for i in todo:
                _save(store, i, chunks[i], run_chunk(payload(chunks[i])))
                bar.update(1)
        elif todo:
            workers = run_tasks(run_chunk, ((payload(chunks[i]),) for i in todo), n_tasks=len(todo),
                                scheduler=scheduler, n_workers=n_workers, window_per_worker=2, bar=bar,
                                on_result=lambda k, rows: _save(store, todo[k], chunks[todo[k]], rows),
                                label=lambda k: f"chunk {todo[k]}")
    rows = np.empty((spec.n_runs, len(METRICS)))
    for i, runs in enumerate(chunks):
        done = _load(store, i, runs)
        if done is None:
            raise RuntimeError(f"chunk {i} missing from {store.folder} after the run")
        rows[runs] = done
    return StudyRun(rows=rows, n_chunks=len(chunks), n_resumed=len(chunks) - len(todo),
                    elapsed_s=time.perf_counter() - tic, n_workers=workers)

