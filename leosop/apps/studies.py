"""Monte Carlo and grid studies on Dask: map a function over parameter chunks.

A study splits its parameter space into chunks (e.g. one pitch angle of an
attitude sweep, one correction period of a fusion study) and calls
``func(chunk, rng)`` on each. Every chunk gets its own random generator from
``numpy.random.SeedSequence(seed).spawn(n_chunks)``, so the results depend
only on the seed and the chunk's index, never on where or in which order the
chunks run: serial and parallel runs are identical.

Where the work runs is ``scheduler`` as in :mod:`leosop.parallel`: ``"serial"``
in this process, one chunk after another (no Dask), None a local cluster, a
scheduler address or a ``distributed.Client``. ``func`` must be picklable (a
module-level function, or a ``functools.partial`` of one) for worker processes.
"""

import numpy as np

from ..parallel import run_tasks
from ..progress import progress

__all__ = ["chunk_generators", "map_chunks"]


def chunk_generators(seed, n_chunks):
    """One independent ``numpy.random.Generator`` per chunk, from ``seed``."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_chunks)]


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
    results = [None] * len(chunks)
    with progress(total=len(chunks), desc=desc, unit="chunk") as bar:
        run_tasks(func, zip(chunks, rngs), n_tasks=len(chunks), scheduler=scheduler,
                  on_result=results.__setitem__, label=lambda i: f"chunk {i}", bar=bar)
    return results
