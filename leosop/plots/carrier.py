"""Residuals of a differential carrier-phase fix per satellite over time."""

import numpy as np

from .core import pyplot, save_png

__all__ = ["plot_carrier_residuals"]


def plot_carrier_residuals(path, t_s, residuals_m, sat_ids, *, title=""):
    """One line per satellite: its single-difference residual after the epoch's clock [mm] over time.

    Parameters
    ----------
    path : path-like
        The PNG written (atomically).
    t_s : array_like, (n_epochs,)
    residuals_m : array_like, (n_sats, n_epochs)
        NaN where the satellite has no row.
    sat_ids : sequence of str, (n_sats,)
    title : str
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    res_mm = 1e3 * np.asarray(residuals_m, dtype=float)
    for sat, r in zip(sat_ids, res_mm):
        rms = np.sqrt(np.nanmean(r**2)) if np.any(np.isfinite(r)) else np.nan
        ax.plot(t_s, r, lw=0.8, label=f"{sat} (rms {rms:.3f} mm)")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("residual [mm]")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    save_png(fig, path)
