"""Stop requests (Ctrl-C, SIGTERM) that hold even where a KeyboardInterrupt is swallowed.

Python runs a signal handler between two bytecodes of the main thread and
raises its exception there. Raised inside a finalizer (``__del__``, a
weakref callback) the exception is printed and dropped, and numba's compiler
turns one into a ``RuntimeError``; a stop asked for during a first,
uncached compilation could then be lost and the command run on to write its
outputs. So the handler also records the request: :func:`check` raises
:class:`KeyboardInterrupt` again wherever it is called (before an output is
moved into place, at each step of a progress bar), and :func:`requested`
lets the command line report any failure that follows a request as the
interruption it is.
"""

import contextlib
import signal
import threading

__all__ = ["check", "requested", "stop_on_signals"]

_requested = False


def requested() -> bool:
    """Whether a stop has been asked for (by a signal) in this process."""
    return _requested


def check() -> None:
    """Raise :class:`KeyboardInterrupt` if a stop has been asked for."""
    if _requested:
        raise KeyboardInterrupt


def _handler(signum, frame):
    global _requested
    _requested = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def stop_on_signals():
    """Turn SIGINT and SIGTERM into stop requests recorded while the block runs (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    global _requested
    _requested = False
    previous = {s: signal.signal(s, _handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        _requested = False
