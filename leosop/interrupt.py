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
interruption it is. The request lasts as long as the outermost
:func:`stop_on_signals` block.
"""

import contextlib
import signal
import threading

__all__ = ["check", "requested", "stop_on_signals"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_requested = False
_depth = 0


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
def _signals_held():
    """SIGINT and SIGTERM held back (delivered at the end) while the handlers change, where the OS allows."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def stop_on_signals():
    """Turn SIGINT and SIGTERM into stop requests recorded while the block runs (main thread only).

    Nested blocks share the outermost one's handlers and request.
    """
    global _requested, _depth
    if threading.current_thread() is not threading.main_thread() or _depth:
        yield
        return
    previous = {}
    try:
        with _signals_held():
            _requested, _depth = False, 1
            previous = {s: signal.signal(s, _handler) for s in _SIGNALS}
        yield
    finally:
        with _signals_held():
            for s, h in previous.items():
                signal.signal(s, h)
            _requested, _depth = False, 0
