"""Figure of a multi-constellation simulation: tracked satellites per family (the families' Fig. 9).

Beside :mod:`leosop.plots` (the single-constellation figures of [Shen 2024]);
written by ``leosop simulate --out`` when the scenario mixes families.
"""

import numpy as np

from .figure import pyplot, save_png
from .plots import run_label, time_label

__all__ = ["visible_by_family_figure"]


def visible_by_family_figure(result, path):
    """Tracked satellites of each family, stacked, with the states a snapshot fix needs (6 + k)."""
    plt = pyplot()
    families = result.scenario.leo.constellations
    counts = result.n_visible_by_family
    fig, ax = plt.subplots(figsize=(9, 3.4))
    ax.stackplot(result.t_s, counts.T, labels=families, step="mid", alpha=0.8)
    need = 6 + (counts > 0).sum(axis=1)
    ax.step(result.t_s, np.where(counts.sum(axis=1) > 0, need, np.nan), "k:", where="mid",
            label="6 + k needed for a snapshot fix")
    ax.set_xlabel(time_label(result))
    ax.set_ylabel("tracked satellites")
    ax.set_title(f"{run_label(result)}: satellites above the {result.scenario.mask_deg:g} deg mask per family")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")  # beside: the stack fills the axes
    save_png(fig, path, bbox_inches="tight")
