"""Monte Carlo execution: worker loss, resume, chunking and seeds do not change the numbers.

Tiny studies (a 10 s flight at measurement level, ~0.1 s per run) keep the
module under 30 s including a two-process local cluster.
"""

import logging
import os
import signal
import threading
import time

import numpy as np
import pytest

from leosop.apps.montecarlo import METRICS, REPRODUCIBLE, chunk_runs, run_study, spec_from_dict
from leosop.apps.montecarlo import execute

COLS = [list(METRICS).index(k) for k in REPRODUCIBLE]


def _spec(**changes):
    doc = {"scenario": {"duration_s": 10}, "fixed": {"level": "measurement"},
           "parameters": {"correction_period_s": [1, 5], "coupling": ["loose", "tight"]}, "n_seeds": 3,
           "runs_per_chunk": 2}
    doc.update(changes)
    return spec_from_dict(doc)


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The reference: the 12-run study in this process."""
    spec = _spec()
    return spec, run_study(spec, tmp_path_factory.mktemp("serial"), scheduler="serial").rows


def test_serial_rows_are_results(serial):
    spec, rows = serial
    assert rows.shape == (12, len(METRICS)) and np.isfinite(rows[:, COLS]).all()
    ins = rows[:, list(METRICS).index("ins_pos_err_mean_m")].reshape(spec.shape)
    fused = rows[:, list(METRICS).index("fused_pos_err_mean_m")].reshape(spec.shape)
    # Common random numbers: seed k has the same IMU in every cell, so the INS alone is the same ...
    np.testing.assert_array_equal(ins, np.broadcast_to(ins[:1, :1], ins.shape))
    assert len(set(ins[0, 0])) == 3  # ... and differs between seeds
    assert (fused[1] > 2 * fused[0]).all()  # corrections every 5 s are worse than every 1 s


def test_chunking_does_not_change_the_numbers(serial, tmp_path):
    spec, rows = serial
    other = run_study(_spec(runs_per_chunk=5), tmp_path, scheduler="serial")
    assert other.n_chunks == 3 and [len(c) for c in chunk_runs(_spec(runs_per_chunk=5))] == [5, 5, 2]
    np.testing.assert_array_equal(other.rows[:, COLS], rows[:, COLS])


def test_interrupted_study_resumes_without_redoing_chunks(serial, tmp_path, monkeypatch):
    spec, rows = serial
    real, calls = execute.run_chunk, []

    def interrupted_at_fourth(runs):
        calls.append(len(runs))
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(runs)

    monkeypatch.setattr(execute, "run_chunk", interrupted_at_fourth)
    with pytest.raises(KeyboardInterrupt):
        run_study(spec, tmp_path, scheduler="serial")
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"chunk-00000{i}.npz" for i in range(3)]
    calls.clear()
    monkeypatch.setattr(execute, "run_chunk", lambda runs: calls.append(len(runs)) or real(runs))
    resumed = run_study(spec, tmp_path, scheduler="serial")
    assert resumed.n_resumed == 3 and calls == [2, 2, 2]  # only the 3 unfinished chunks ran
    np.testing.assert_array_equal(resumed.rows[:, COLS], rows[:, COLS])


def test_worker_killed_mid_study_same_results(serial, tmp_path):
    distributed = pytest.importorskip("distributed")
    spec = _spec(runs_per_chunk=1)  # 12 tasks: plenty still to run when the first is done
    rows = serial[1]
    outcome = {}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=logging.CRITICAL) as cluster, distributed.Client(cluster) as client:
        pids = client.run(os.getpid)

        def study():
            try:
                outcome["run"] = run_study(spec, tmp_path, scheduler=client)
            except BaseException as exc:  # reported by the main thread
                outcome["error"] = exc

        thread = threading.Thread(target=study)
        thread.start()
        deadline = time.monotonic() + 60
        while not any(tmp_path.glob("chunk-*.npz")) and time.monotonic() < deadline:
            time.sleep(0.005)
        busy = {w: keys for w, keys in client.processing().items() if keys}
        victim = next(iter(busy))
        n_done = len(list(tmp_path.glob("chunk-*.npz")))
        os.kill(pids[victim], signal.SIGKILL)
        thread.join(timeout=120)
        workers_after = set(client.scheduler_info()["workers"])
    assert "error" not in outcome, outcome.get("error")
    assert 1 <= n_done < 12 and busy[victim]  # killed while it had work, with the study unfinished
    assert victim not in workers_after  # the process really died (its nanny started a new one)
    run = outcome["run"]
    assert run.n_resumed == 0 and run.n_workers == 2
    np.testing.assert_array_equal(run.rows[:, COLS], rows[:, COLS])


def test_constellation_mix_reaches_the_runs(serial, tmp_path):
    spec, rows = serial
    mixes = [["starlink"], ["starlink", "oneweb", "iridium", "orbcomm"]]
    mix = _spec(parameters={"constellations": mixes, "correction_period_s": [1, 5], "coupling": ["loose", "tight"]})
    got = run_study(mix, tmp_path, scheduler="serial").rows.reshape(mix.shape + (len(METRICS),))
    # Starlink alone is the default sky: the same numbers as the study without the parameter.
    np.testing.assert_array_equal(got[0][..., COLS], rows.reshape(spec.shape + (len(METRICS),))[..., COLS])
    seen = list(METRICS).index("n_visible_min")
    assert (got[1][..., seen] > got[0][..., seen]).all()  # the other families' satellites are in the sky
