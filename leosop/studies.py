"""Monte Carlo and grid studies on Dask: map a function over parameter chunks.

A study splits its parameter space into chunks (e.g. one pitch angle of an
attitude sweep, one correction period of a fusion study) and calls
``func(chunk, rng)`` on each. Every chunk gets its own random generator from
``numpy.random.SeedSequence(seed).spawn(n_chunks)``, so the results depend
only on the seed and the chunk's index, never on where or in which order the
chunks run: serial and parallel runs are identical.

Where the work runs is chosen by ``scheduler``:

``"serial"``
    in this process, one chunk after another (no Dask);
``None``
    a temporary ``distributed.LocalCluster`` of single-threaded worker
    processes on this machine (the default of the CLI);
``"tcp://host:port"``
    an existing Dask scheduler (unreachable: :class:`leosop.errors.ExternalError`,
    exit status 1);
a ``distributed.Client``
    an existing client (tests use an in-process cluster).

``func`` must be picklable (a module-level function, or a
``functools.partial`` of one) for worker processes.
"""

import contextlib
import logging
import os

import numpy as np

from .errors import ExternalError
from .progress import progress

__all__ = ["chunk_generators", "map_chunks"]

#: How long to try reaching a scheduler given by address.
CONNECT_TIMEOUT = "10s"
#: glibc settings of the local cluster's worker processes. Dask's default
#: ``MALLOC_TRIM_THRESHOLD_=65536`` also freezes glibc's mmap threshold at
#: 128 KiB, so every numpy temporary above it is mapped and unmapped again,
#: page faults each time: ``study gdop-map`` took 2.3x the CPU time of the
#: same task in the main process. Temporaries up to 32 MiB (glibc's own
#: ceiling) come from the heap, which keeps up to 256 MiB free.
_WORKER_MALLOC = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": 256 << 20,
    "distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": 32 << 20,
}


def chunk_generators(seed, n_chunks):
    """One independent ``numpy.random.Generator`` per chunk, from ``seed``."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_chunks)]


@contextlib.contextmanager
def dask_client(scheduler, n_chunks, n_workers=None):
    """A client for ``scheduler``; a local cluster gets ``n_workers`` (default: the cores) but no more than chunks."""
    from distributed import Client, LocalCluster

    if isinstance(scheduler, Client):
        yield scheduler
        return
    if scheduler is None:
        import dask

        n_workers = max(1, min(n_workers or os.cpu_count() or 1, n_chunks))
        with dask.config.set(_WORKER_MALLOC), LocalCluster(
                n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ExternalError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler ({first})") from None
    with client:
        yield client


def map_chunks(func, chunks, *, seed=0, scheduler=None, desc=None):
    """Results of ``func(chunk, rng)`` for every chunk, in the order of ``chunks``.

    Parameters
    ----------
    func : callable
        ``func(chunk, rng) -> result``; ``rng`` is the chunk's
        ``numpy.random.Generator``.
    chunks : sequence
        Parameter chunks (picklable).
    seed : int or None
        Root of the per-chunk seeds (``numpy.random.SeedSequence``).
    scheduler : None, "serial", str or distributed.Client
        Where to run (module docstring).
    desc : str, optional
        Label of the progress bar (stderr, terminals only).

    Returns
    -------
    list
        One result per chunk.
    """
    chunks = list(chunks)
    rngs = chunk_generators(seed, len(chunks))
    if scheduler == "serial":
        return [func(c, r) for c, r in progress(zip(chunks, rngs), total=len(chunks), desc=desc, unit="chunk")]
    from distributed import as_completed

    with dask_client(scheduler, len(chunks)) as client:
        futures = client.map(func, chunks, rngs, pure=False)
        for _ in progress(as_completed(futures), total=len(futures), desc=desc, unit="chunk"):
            pass
        return client.gather(futures)
