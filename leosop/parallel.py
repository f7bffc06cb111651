"""Where tasks run on Dask: one client connection and one submit-and-collect loop.

Every parallel study (:mod:`leosop.apps.studies`, :mod:`leosop.apps.montecarlo`, the
GDOP maps of :mod:`leosop.orbits.gridmap`, the replay batch of
:mod:`leosop.replay.batch`) runs its tasks through :func:`run_tasks`, which
hands each result to the caller as it finishes, so the caller stores it (and
a rerun resumes) without waiting for the others.

Where the work runs is chosen by ``scheduler``:

``"serial"``
    in this process, one task after another (no Dask; the callers' own loop);
``None``
    a temporary ``distributed.LocalCluster`` of single-threaded worker
    processes on this machine (the default of the CLI);
``"tcp://host:port"``
    an existing Dask scheduler (unreachable: :class:`leosop.errors.ExternalError`,
    exit status 1);
a ``distributed.Client``
    an existing client (tests use an in-process cluster).

A task's function must be picklable (a module-level function, or a
``functools.partial`` of one) for worker processes.

Large results of a local cluster's tasks need not travel back over TCP:
:func:`shared_outputs` gives arrays mapped from files in RAM (``/dev/shm``)
that the tasks fill in place (:class:`SharedArray`).
"""

import contextlib
import itertools
import logging
import os
import shutil
import tempfile
from dataclasses import dataclass

import numpy as np

from .errors import ExternalError

__all__ = ["CONNECT_TIMEOUT", "SharedArray", "dask_client", "run_tasks", "shared_outputs"]

#: How long to try reaching a scheduler given by address.
CONNECT_TIMEOUT = "10s"
#: glibc settings of the local cluster's worker processes. Dask's default
#: ``MALLOC_TRIM_THRESHOLD_=65536`` also freezes glibc's mmap threshold at
#: 128 KiB, so every numpy temporary above it is mapped and unmapped again,
#: page faults each time: ``study gdop-map`` took 2.3x the CPU time of the
#: same task in the main process. Temporaries up to 32 MiB (glibc's own
#: ceiling) come from the heap, which keeps up to 256 MiB free.
#:
#: The bookkeeping of a local cluster runs on the same cores as its workers:
#: Dask's statistical profiler samples each worker's stack every 10 ms, the
#: system monitors poll every 0.5 s, the memory monitor every 0.1 s and the
#: active memory manager every 2 s. On 2 cores, ``study gdop-map`` spent
#: ~2 CPU-s per worker and ~3.5 in the client's event loop outside the tasks
#: (8 % of the cores); with the profiler off, the system monitors at 2 s
#: and no memory manager (a task's result goes to the client alone, no
#: replicas to manage), 0.8 and 2.2-2.7 s (``tools/bench_gdop_map.py
#: --dask-workers 2 --split 2``; measured with the memory monitor at 1 s
#: too, now left at its 0.1 s so that memory limits act as promptly). The
#: event loops' tick (a callback every 20 ms that times how late it runs,
#: for the "event loop was unresponsive" warning) at 1 s: 0.25-0.6 CPU-s
#: less in the client over a 40 s map and 0.1-0.9 in the workers (two
#: alternating pairs of one-off runs); the warning still comes.
_LOCAL_CLUSTER = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": 256 << 20,
    "distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": 32 << 20,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.scheduler.active-memory-manager.start": False,
    "distributed.admin.tick.interval": "1s",
}
#: The fewest tasks kept in flight by a bounded window, whatever the worker count.
_MIN_WINDOW = 4
#: A file system in RAM, where :func:`shared_outputs` maps its arrays: writing and mapping cost no disk I/O.
_SHARED_DIR = "/dev/shm"
#: Room :func:`shared_outputs` leaves free there for others (a full tmpfs kills a process writing to it).
_SHARED_HEADROOM = 256 << 20


@dataclass(frozen=True)
class SharedArray:
    """An array of :func:`shared_outputs` as a task sees it: where it lies, its shape and type (picklable)."""

    path: str
    shape: tuple
    dtype: str

    def put(self, index, values):
        """``array[index] = values`` in the caller's array (no copy travels back)."""
        np.memmap(self.path, dtype=self.dtype, mode="r+", shape=self.shape)[index] = values


@contextlib.contextmanager
def shared_outputs(scheduler, specs):
    """Zero-filled arrays that the tasks of a local cluster fill in place, or None.

    With ``scheduler=None`` (the local cluster :func:`run_tasks` starts, whose
    workers share this machine's memory) and ``/dev/shm`` with room, each
    ``(shape, dtype)`` of ``specs`` becomes a file there, its memory
    reserved at once, mapped here: yields ``(arrays, handles)``, the tasks
    get the :class:`SharedArray` handles and write their parts with
    :meth:`SharedArray.put` instead of returning them. The files are removed
    on exit; the arrays stay valid (the mapping holds the memory until they
    are freed). Otherwise (a remote or given scheduler, no ``/dev/shm`` or
    ``posix_fallocate``, too little room) yields None and the results travel
    back as usual. A process killed meanwhile leaves its ``leosop-*`` folder
    there.

    Parameters
    ----------
    scheduler : None, str or distributed.Client
    specs : sequence of (tuple, dtype)
    """
    made = _shared_files(specs) if scheduler is None else None
    if made is None:
        yield None
        return
    folder, arrays, handles = made
    try:
        yield arrays, handles
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _shared_files(specs):
    """``(folder, arrays, handles)`` of :func:`shared_outputs`, or None where they cannot be made."""
    specs = [(tuple(int(n) for n in shape), np.dtype(dtype)) for shape, dtype in specs]
    sizes = [int(np.prod(shape)) * dtype.itemsize for shape, dtype in specs]
    try:
        fs = os.statvfs(_SHARED_DIR)
        room = fs.f_bavail * fs.f_frsize
    except (AttributeError, OSError):  # not POSIX, or no RAM file system
        room = 0
    if not hasattr(os, "posix_fallocate") or sum(sizes) == 0 or sum(sizes) + _SHARED_HEADROOM > room:
        return None
    folder = None
    try:
        folder = tempfile.mkdtemp(prefix="leosop-", dir=_SHARED_DIR)
        handles = [SharedArray(os.path.join(folder, f"{k}.bin"), shape, dtype.str)
                   for k, (shape, dtype) in enumerate(specs)]
        for h, size in zip(handles, sizes):
            _reserve(h.path, size)
        arrays = [np.asarray(np.memmap(h.path, dtype=h.dtype, mode="r+", shape=h.shape)) for h in handles]
    except OSError:  # not writable, or the room went to another process meanwhile
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
        return None
    return folder, arrays, handles


def _reserve(path, n_bytes):
    """A file of ``n_bytes`` zeros with its memory taken now: a worker writing to a RAM file system that has
    filled meanwhile would die of SIGBUS; here the caller gets an OSError instead (0.13 s for 560 MB)."""
    fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o600)
    try:
        os.posix_fallocate(fd, 0, n_bytes)
    finally:
        os.close(fd)


@contextlib.contextmanager
def dask_client(scheduler, n_tasks, n_workers=None):
    """A client for ``scheduler``; a local cluster gets ``n_workers`` (default: the cores) but no more than tasks."""
    from distributed import Client, LocalCluster

    if isinstance(scheduler, Client):
        yield scheduler
        return
    if scheduler is None:
        import dask

        n_workers = max(1, min(n_workers or os.cpu_count() or 1, n_tasks))
        with dask.config.set(_LOCAL_CLUSTER), LocalCluster(
                n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ExternalError(f"scheduler {scheduler}: cannot connect to a Dask scheduler ({first})",
                            param="scheduler") from None
    with client:
        yield client


def run_tasks(fn, tasks, *, scheduler, on_result, n_tasks=None, n_workers=None, on_error=None, label=None,
              window_per_worker=None, bar=None):
    """Run ``fn(*args)`` on Dask for every ``args`` of ``tasks``; ``on_result(i, result)`` as each finishes.

    Parameters
    ----------
    fn : callable
        The task function (picklable).
    tasks : iterable of tuple
        Positional arguments of each task, taken lazily: with a window, task
        ``i`` is made only when it is submitted.
    scheduler : None, str or distributed.Client
        Where to run (module docstring); ``"serial"`` is the caller's loop.
    on_result : callable
        ``on_result(i, result)``, called in this process in the order the
        tasks finish; ``i`` is the task's position in ``tasks``.
    n_tasks : int, optional
        Number of tasks; default ``len(tasks)``.
    n_workers : int, optional
        Workers of a local cluster (default: the cores, at most one per task).
    on_error : callable, optional
        ``on_error(i, exc)`` for a task that raised (or killed too many
        workers); the others go on. Default: the task's exception propagates,
        with a note naming the task (``label``), and the unfinished tasks are
        dropped with the client.
    label : callable, optional
        ``label(i) -> str``, the task's name in that note; default ``task i``.
    window_per_worker : int, optional
        Keep at most ``max(window_per_worker x workers, 4)`` tasks in flight,
        submitting the next as one finishes, so that the scheduler and the
        client hold a bounded number of tasks however many there are.
        Default: submit every task at once.
    bar : tqdm, optional
        Progress bar (:func:`leosop.progress.progress`) advanced once per
        finished task.

    Returns
    -------
    int
        Dask workers at the start (at least 1).
    """
    from distributed import as_completed

    n_tasks = len(tasks) if n_tasks is None else n_tasks
    queue = enumerate(tasks)
    with dask_client(scheduler, n_tasks, n_workers) as client:
        workers = max(len(client.scheduler_info()["workers"]), 1)
        window = n_tasks if window_per_worker is None else max(window_per_worker * workers, _MIN_WINDOW)
        position = {}

        def submit(i, args):
            future = client.submit(fn, *args, pure=False)
            position[future.key] = i
            return future

        running = as_completed([submit(i, args) for i, args in itertools.islice(queue, window)])
        for future in running:
            i = position.pop(future.key)
            try:
                result = future.result()
            except Exception as exc:  # the task raised, or killed too many workers
                if on_error is None:
                    exc.add_note(f"in {label(i) if label else f'task {i}'} run on Dask")
                    raise
                on_error(i, exc)
            else:
                on_result(i, result)
            future.release()
            if bar is not None:
                bar.update(1)
            for i, args in itertools.islice(queue, 1):
                running.add(submit(i, args))
    return workers
