"""Progress bars on stderr, shown only when stderr is a terminal."""

import sys

from tqdm import tqdm

from .interrupt import check

__all__ = ["progress"]


class _Bar(tqdm):
    """A tqdm bar whose every step first honours a pending stop request (:mod:`leosop.interrupt`)."""

    def __iter__(self):
        for item in super().__iter__():
            check()
            yield item

    def update(self, n=1):
        check()
        return super().update(n)


def progress(iterable=None, *, total=None, desc=None, unit="it"):
    """A tqdm bar on stderr; silent when stderr is not a terminal (CI, pipes)."""
    return _Bar(iterable, total=total, desc=desc, unit=unit, file=sys.stderr,
                disable=not sys.stderr.isatty(), leave=False)
