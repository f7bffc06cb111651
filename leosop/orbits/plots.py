"""Figures of visibility studies: visible count and GDOP over time, sky plot."""

import numpy as np

from ..figure import pyplot, save_png

__all__ = ["plot_visibility", "plot_skyplot"]


def plot_visibility(path, t_s, n_visible, gdop, gdop_range, *, mask_deg, title=""):
    """Visible satellites, Doppler GDOP and range GDOP against time, saved to ``path`` (PNG).

    Parameters
    ----------
    path : str or Path
    t_s : ndarray, (n_epochs,)
        Seconds from the start.
    n_visible : ndarray of int, (n_epochs,)
    gdop : ndarray, (n_epochs,)
        Doppler GDOP ([Shen 2024] eq. 10); NaN below 7 satellites.
    gdop_range : ndarray, (n_epochs,)
        Classic pseudorange GDOP, for comparison; NaN below 4 satellites.
    """
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5))
    ax1.step(t_s, n_visible, where="mid", color="C0")
    ax1.axhline(7, color="0.5", ls="--", lw=0.8, label="7 needed for a Doppler fix")
    ax1.set_ylabel(f"visible (mask {mask_deg:g} deg)")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_title(title)
    ax2.semilogy(t_s, gdop, color="C1", label="Doppler, 7 states ([Shen 2024] eq. 10)")
    ax2.semilogy(t_s, gdop_range, color="C2", lw=0.8, label="pseudorange, 4 states")
    ax2.set_ylabel("GDOP")
    ax2.legend(loc="upper right", fontsize=8)
    ax2.set_xlabel("time since start [s]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path, dpi=110)


def plot_skyplot(path, az_rad, elev_rad, track_id, *, mask_deg, title=""):
    """Sky plot of satellite tracks (north up, azimuth clockwise), saved to ``path``.

    Parameters
    ----------
    az_rad, elev_rad : ndarray, (m,)
    track_id : ndarray, (m,)
        Points with the same id are drawn as one track.
    """
    plt = pyplot()
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    zen = 90.0 - np.degrees(elev_rad)
    order = np.lexsort((np.arange(len(track_id)), track_id))
    ids, start = np.unique(np.asarray(track_id)[order], return_index=True)
    for a, b in zip(start, np.r_[start[1:], len(order)]):
        sel = order[a:b]
        ax.plot(az_rad[sel], zen[sel], lw=0.8)
    ax.set_rlim(0, 90)
    ax.set_rticks([0, 30, 60, 90 - mask_deg])
    ax.set_yticklabels(["90", "60", "30", f"{mask_deg:g}"])
    ax.set_title(title or f"{len(ids)} satellites above {mask_deg:g} deg")
    save_png(fig, path, dpi=110)
