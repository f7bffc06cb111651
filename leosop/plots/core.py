"""The one way figures are made and written: Agg backend, atomic PNG files.

Matplotlib is imported only when a figure is drawn, so the numerical core
never pays for it.
"""

import numpy as np

from ..fileio import atomic_path

__all__ = ["ENVELOPE_BINS", "envelope", "pyplot", "save_png"]

#: Buckets a long series is drawn through (:func:`envelope`): a few per pixel column of a figure ~8 in wide
#: at ~110 dpi.
ENVELOPE_BINS = 2000


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path, *, dpi=120, **savefig_kw):
    """Write ``fig`` to ``path`` as PNG (complete or absent) and close it."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, **savefig_kw)
    pyplot().close(fig)


def envelope(x, y, n_bins=ENVELOPE_BINS):
    """A long series as the minimum and maximum of each of ``n_bins`` runs of samples, for drawing.

    A line through (first x, min), (last x, max) of every run covers the
    pixels the whole series would (a few runs per pixel column), so a day at
    1 s draws as it did, in a fraction of the time and memory. A run all NaN
    stays NaN: gaps of a run or more stay gaps (shorter ones are bridged, at
    a pixel's scale). Series of at most ``2 n_bins`` points come back as
    they are.

    Parameters
    ----------
    x : ndarray, (n,)
        Increasing (numbers or datetime64).
    y : ndarray, (n,)
    n_bins : int

    Returns
    -------
    x, y : ndarray, (2 n_bins,) or (n,)
    """
    x, y = np.asarray(x), np.asarray(y, dtype=float)
    if x.size <= 2 * n_bins:
        return x, y
    edges = np.linspace(0, x.size, n_bins + 1).astype(np.int64)
    first, last = edges[:-1], edges[1:] - 1
    # fmin/fmax skip NaN (a run of NaN alone stays NaN) and warn of nothing.
    lo, hi = np.fmin.reduceat(y, first), np.fmax.reduceat(y, first)
    return np.stack([x[first], x[last]], 1).ravel(), np.stack([lo, hi], 1).ravel()
