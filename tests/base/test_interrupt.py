"""A stop request (SIGTERM, Ctrl-C) holds even where the KeyboardInterrupt it raised is swallowed.

Python drops an exception raised in a finalizer, and numba's compiler turns
one into a RuntimeError; both were seen to let `leosop generate` run on after
SIGTERM (tests/cli/test_hardening.py). Here the swallowing is done on purpose.
"""

import os
import signal

import pytest

import leosop.cli.visibility
from leosop.cli import main
from leosop.errors import ExternalError, InputError
from leosop.fileio import atomic_outputs, atomic_path
from leosop.interrupt import requested, stop_on_signals
from leosop.progress import progress


def _swallowed_stop(signum=signal.SIGTERM):
    """Send ourselves ``signum`` and swallow the KeyboardInterrupt, as a finalizer would."""
    try:
        os.kill(os.getpid(), signum)
    except KeyboardInterrupt:
        pass


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_no_output_is_moved_into_place_after_a_swallowed_stop(tmp_path, signum):
    with stop_on_signals():
        _swallowed_stop(signum)
        assert requested()
        with pytest.raises(KeyboardInterrupt), atomic_path(tmp_path / "a.csv") as tmp:
            tmp.write_text("x\n")
        with pytest.raises(KeyboardInterrupt), atomic_outputs(tmp_path / "out") as stage:
            (stage / "b.csv").write_text("x\n")
    assert list(tmp_path.iterdir()) == []


def test_a_progress_bar_stops_at_its_next_step():
    seen = []
    with stop_on_signals(), pytest.raises(KeyboardInterrupt):
        for k in progress(range(5)):
            seen.append(k)
            if k == 1:
                _swallowed_stop()
    assert seen == [0, 1]


def test_a_request_ends_with_its_block(tmp_path):
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with stop_on_signals():
        with stop_on_signals():  # nested: the outer block's handlers and request
            _swallowed_stop()
        assert requested()
    assert not requested()
    assert {s: signal.getsignal(s) for s in before} == before
    with stop_on_signals():
        assert not requested()
        with atomic_path(tmp_path / "a.csv") as tmp:
            tmp.write_text("x\n")
    assert (tmp_path / "a.csv").read_text() == "x\n"


@pytest.mark.parametrize("after", ["returns", RuntimeError, InputError, ExternalError, OSError])
def test_the_command_line_reports_the_stop(monkeypatch, capsys, after):
    """Whatever the command does after the swallowed stop (numba raises RuntimeError "no compiled object
    yet"; an error of its own would otherwise be reported as one, status 2 for bad input)."""
    def run(args):
        _swallowed_stop()
        if after != "returns":
            raise after("on the way out")
        return {}

    monkeypatch.setattr(leosop.cli.visibility, "run", run)
    assert main(["visibility"]) == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == "leosop visibility: interrupted"
