"""A recording's data file against its declared SHA-512 (SigMF ``core:sha512``): the hash, the check, and
the check run beside other work.

The recordings are :class:`~.iq.Recording` objects (their ``data_path`` and ``sha512``).
"""

import hashlib
import threading
from contextlib import contextmanager

from ..errors import InputError

__all__ = ["check_sha512", "sha512_checked", "sha512_hex"]


def sha512_hex(path):
    """SHA-512 of a file's bytes as hex text (``core:sha512``), read in 4 MB pieces."""
    h = hashlib.sha512()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 22), b""):
            h.update(chunk)
    return h.hexdigest()


def check_sha512(rec) -> None:
    """Refuse a recording whose data file does not match its declared ``core:sha512`` (none declared: no check).

    Raises
    ------
    InputError
        Naming the data file and the metadata file (truncated or modified).
    """
    if rec.sha512 and sha512_hex(rec.data_path) != rec.sha512:
        raise InputError(f"{rec.data_path}: contents do not match core:sha512 in "
                         f"{rec.data_path.with_suffix('.sigmf-meta').name} (truncated or modified)")


@contextmanager
def sha512_checked(*recs):
    """Check the recordings' ``core:sha512`` on a background thread while the ``with`` body runs.

    For recordings opened with ``open_sigmf(..., verify=False)``: the hash
    (a whole pass over each data file) overlaps the body's work instead of
    preceding it; hashlib and the file reads release the GIL, so it takes a
    core of its own where one is idle. Leaving the block waits for the check
    and raises its :class:`InputError` on a mismatch, also in place of an
    error the body raised (a modified file is the better explanation of
    that). The body must write nothing that the check could still refuse.
    """
    failure = []

    def check():
        try:
            for rec in recs:
                check_sha512(rec)
        except Exception as exc:  # re-raised in the caller's thread
            failure.append(exc)

    worker = threading.Thread(target=check, name="leosop-sha512", daemon=True)
    worker.start()
    try:
        yield
    except Exception as exc:
        worker.join()
        if failure:
            raise failure[0] from exc
        raise
    worker.join()  # an interrupt (BaseException) leaves the daemon thread to end with the process
    if failure:
        raise failure[0]
