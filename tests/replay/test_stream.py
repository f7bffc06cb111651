"""The streaming stage: its thread switch interval (shortened while workers prepare blocks, then restored), the
blocks' order, and memory bounded by the block, not the recording."""

import json
import sys
import threading

from leosop.cli import main
from leosop.replay.stream import SWITCH_INTERVAL_S, _short_switch_interval
from tests.helpers import peak_rss_mb


def test_switch_interval_is_restored_after_overlapping_replays():
    before = sys.getswitchinterval()
    entered, release = threading.Event(), threading.Event()

    def other_replay():
        with _short_switch_interval():
            entered.set()
            release.wait(10.0)

    t = threading.Thread(target=other_replay)
    with _short_switch_interval():
        assert sys.getswitchinterval() == min(before, SWITCH_INTERVAL_S)
        t.start()
        assert entered.wait(10.0)
    # The first replay ended while the other still streams: its workers keep the short interval.
    assert sys.getswitchinterval() == min(before, SWITCH_INTERVAL_S)
    release.set()
    t.join(10.0)
    assert sys.getswitchinterval() == before


def test_switch_interval_is_restored_once_every_block_is_taken(monkeypatch):
    # The replay's loop zips the blocks first, so it never asks the generator for more after the last
    # block: the interval must be back by then (the generator still suspended), and on an early close.
    import leosop.replay.stream as stream

    monkeypatch.setattr(stream, "_prepare", lambda rec, factor, comb, every, kernel, item: item[0])
    before = sys.getswitchinterval()
    blocks = list(range(7))
    gen = stream.prepared_blocks(None, blocks, 1, None, threads=2)
    taken = [k for _, k in zip(blocks, gen)]
    assert taken == blocks and sys.getswitchinterval() == before
    gen = stream.prepared_blocks(None, blocks, 1, None, threads=3)
    assert next(gen) == 0 and sys.getswitchinterval() == min(before, SWITCH_INTERVAL_S)
    gen.close()
    assert sys.getswitchinterval() == before


def test_blocks_come_in_order_prepared_by_the_caller_too(monkeypatch):
    # Worker threads and the caller's thread share the blocks (the caller prepares the next unstarted block
    # while the one it needs is not ready); the blocks come back in their order whoever prepared them, and an
    # error is raised when its block's turn comes, after the blocks before it.
    import time

    import pytest

    import leosop.replay.stream as stream

    ran_on = {}

    def prepare(rec, factor, comb, every, kernel, item):
        k = item[0]
        ran_on[k] = threading.current_thread()
        time.sleep(0.002 * (k % 3))  # uneven work: blocks finish out of order
        if k == 9:
            raise ValueError("block 9")
        return k

    monkeypatch.setattr(stream, "_prepare", prepare)
    blocks = list(range(12))
    for threads in (2, 3):
        ran_on.clear()
        gen = stream.prepared_blocks(None, blocks, 1, None, threads=threads)
        assert [next(gen) for _ in range(9)] == list(range(9))
        with pytest.raises(ValueError, match="block 9"):
            next(gen)
        assert threading.current_thread() in ran_on.values()  # the caller prepared some blocks
        assert len(set(ran_on.values())) > 1  # and the workers others


def test_peak_memory_stays_flat_when_the_recording_doubles(tmp_path):
    """``leosop replay`` streams its recording block by block: 6 s instead of 3 s (120 instead of 60 MB of cf32)
    raise its peak by the tracks' few kB a block, not by the samples. Measured: +3.5 MB for +80 MB (4 and 8 s);
    15 MB leaves the allocator room and still fails a whole-file read (+60 MB of samples, +120 MB as complex64
    spectra) by 4x."""
    peaks = []
    for seconds in (3, 6):
        rec = tmp_path / f"rec{seconds}.sigmf-meta"
        assert main(["generate", "-o", str(rec), "--site", "34.342,108.94,400", "--start", "2025-01-01T19:40:00Z",
                     "--sample-rate-hz", "2.5e6", "--mask-deg", "40", "--duration-s", str(seconds), "--seed", "1"]) == 0
        out = tmp_path / f"out{seconds}"
        peaks.append(peak_rss_mb("replay", str(rec), "--static", "--init", "34.98,109.71,0", "--out", str(out)))
        fix = json.loads((out / "replay.json").read_text())
        assert fix["n_blocks"] == 10 * seconds and [s["status"] for s in fix["solutions"]] == ["ok"]
    assert peaks[1] - peaks[0] < 15.0, peaks
