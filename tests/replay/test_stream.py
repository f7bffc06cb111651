"""The streaming stage's thread switch interval: shortened while workers prepare blocks, then restored."""

import sys
import threading

from leosop.replay.stream import SWITCH_INTERVAL_S, _short_switch_interval


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
