"""The one way figures are made and written: Agg backend, atomic PNG files.

Matplotlib is imported only when a figure is drawn, so the numerical core
never pays for it.
"""

from ..fileio import atomic_path

__all__ = ["pyplot", "save_png"]


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
