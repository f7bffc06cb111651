"""Progress bars on stderr, shown only when stderr is a terminal."""

import sys

from tqdm import tqdm

__all__ = ["progress"]


def progress(iterable=None, *, total=None, desc=None, unit="it"):
    """A tqdm bar on stderr; silent when stderr is not a terminal (CI, pipes)."""
    return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr,
                disable=not sys.stderr.isatty(), leave=False)
