"""Dask study runner: results depend on the seed only, not on where chunks run."""

import numpy as np
import pytest

from leosop.parallel import run_tasks
from leosop.apps.repro.alignment import sweep
from leosop.apps.studies import chunk_generators, map_chunks


def _draw(chunk, rng):
    return chunk * 1000 + rng.normal(size=3)


def _square_or_fail(i, fail):
    if i == fail:
        raise ValueError(f"bad input {i}")
    return i * i


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    # In-process cluster of two single-threaded workers: starts in well under a second.
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster, distributed.Client(cluster) as c:
        yield c


def test_chunk_generators_depend_on_seed_and_index_only():
    a = [g.normal() for g in chunk_generators(7, 3)]
    b = [g.normal() for g in chunk_generators(7, 5)]
    assert a == b[:3]  # child i of the SeedSequence is the same however many are spawned
    assert len(set(a)) == 3
    assert a != [g.normal() for g in chunk_generators(8, 3)]


def test_serial_and_parallel_results_are_identical(client):
    chunks = list(range(6))
    serial = map_chunks(_draw, chunks, seed=11, scheduler="serial")
    parallel = map_chunks(_draw, chunks, seed=11, scheduler=client)
    for s, p, c in zip(serial, parallel, chunks):
        np.testing.assert_array_equal(s, p)
        assert abs(s[0] - 1000 * c) < 10  # results come back in chunk order


def test_alignment_sweep_serial_equals_parallel(client):
    grid = dict(pitch_deg=[10.0, 80.0, 89.0], yaw_deg=[-90.0, 0.0, 90.0], roll_deg=[0.0, 120.0], n_shots=10)
    serial = sweep(**grid, seed=5, scheduler="serial")
    parallel = sweep(**grid, seed=5, scheduler=client)
    assert serial == parallel
    assert serial != sweep(**grid, seed=6, scheduler="serial")


@pytest.mark.parametrize("per_worker, window", [(None, 10), (1, 4)])  # 1 x 2 workers is below the floor of 4
def test_run_tasks_window_bounds_what_is_in_flight(client, per_worker, window):
    made, results, in_flight = [], {}, []

    def tasks():
        for i in range(10):
            made.append(i)
            yield i, None

    def keep(i, result):
        in_flight.append(len(made) - len(results))  # made but not yet collected, this one included
        results[i] = result

    workers = run_tasks(_square_or_fail, tasks(), n_tasks=10, scheduler=client, on_result=keep,
                        window_per_worker=per_worker)
    assert workers == 2 and results == {i: i * i for i in range(10)}
    assert max(in_flight) == window  # tasks are made lazily, one more as each finishes


def test_run_tasks_error_names_the_task_or_goes_to_on_error(client):
    with pytest.raises(ValueError, match="bad input 3") as info:
        run_tasks(_square_or_fail, [(i, 3) for i in range(6)], scheduler=client, on_result=lambda i, r: None,
                  label=lambda i: f"chunk {i}")
    assert "in chunk 3 run on Dask" in info.value.__notes__
    results, errors = {}, {}
    run_tasks(_square_or_fail, [(i, 3) for i in range(6)], scheduler=client, on_result=results.__setitem__,
              on_error=lambda i, exc: errors.setdefault(i, str(exc)))
    assert errors == {3: "bad input 3"} and results == {i: i * i for i in (0, 1, 2, 4, 5)}


def _put_squares(handle, idx):
    handle.put(idx, np.asarray(idx) ** 2)


def test_shared_outputs_are_filled_in_place_and_their_files_go(client, monkeypatch):
    """Another process's writes land in the caller's array; the files are gone on exit, the array stays valid;
    a given scheduler, too little room in RAM, a failed reservation or no folder there gets None (the results then
    travel back)."""
    import multiprocessing
    import os

    from leosop import parallel

    if not os.path.isdir(parallel._SHARED_DIR):
        pytest.skip("no /dev/shm on this system")
    before = set(os.listdir(parallel._SHARED_DIR))
    monkeypatch.setattr(parallel, "_SHARED_HEADROOM", 0)  # a container's /dev/shm may hold 64 MB only
    with parallel.shared_outputs(None, [((10,), np.int64), ((2, 3), np.float32)]) as shared:
        (squares, zeros), (handle, _) = shared
        folder = os.path.dirname(handle.path)
        assert not squares.any() and not zeros.any()
        ctx = multiprocessing.get_context("spawn")  # a fresh process, as a Dask worker is
        for idx in ([1, 2, 3], [9]):
            worker = ctx.Process(target=_put_squares, args=(handle, idx))
            worker.start()
            worker.join()
            assert worker.exitcode == 0
    assert not os.path.exists(folder)
    np.testing.assert_array_equal(squares, [0, 1, 4, 9, 0, 0, 0, 0, 0, 81])
    with parallel.shared_outputs(client, [((10,), np.int64)]) as shared:
        assert shared is None
    def full(fd, offset, n_bytes):
        raise OSError(28, "No space left on device")

    with monkeypatch.context() as m:  # another process took the room after the check
        m.setattr(os, "posix_fallocate", full)
        with parallel.shared_outputs(None, [((10,), np.int64)]) as shared:
            assert shared is None
    with monkeypatch.context() as m:  # a place that is no folder
        m.setattr(parallel, "_SHARED_DIR", __file__)
        with parallel.shared_outputs(None, [((10,), np.int64)]) as shared:
            assert shared is None
    monkeypatch.setattr(parallel, "_SHARED_HEADROOM", 1 << 62)
    with parallel.shared_outputs(None, [((10,), np.int64)]) as shared:
        assert shared is None
    assert set(os.listdir(parallel._SHARED_DIR)) <= before
