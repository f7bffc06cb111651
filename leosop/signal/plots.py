"""Spectrogram of a recording with the Doppler track over it."""

import numpy as np

from ..figure import pyplot, save_png

__all__ = ["plot_spectrogram"]


def plot_spectrogram(path, t_s, f_hz, power, *, track_t_s=None, track_hz=None, coarse_t_s=None,
                     coarse_hz=None, f_lim_hz=None, title="", labelled_tracks=()):
    """Write a PNG: power in dB over time and frequency, tracks on top.

    Parameters
    ----------
    path : str or Path
    t_s : ndarray, (n_cols,)
    f_hz : ndarray, (n_rows,), ascending
    power : ndarray, (n_rows, n_cols)
    track_t_s, track_hz : ndarray, optional
        Fine Doppler of the central tone per block.
    coarse_t_s, coarse_hz : ndarray, optional
        STFT coarse track.
    f_lim_hz : float, optional
        Show only |f| <= this.
    labelled_tracks : sequence of (t_s, doppler_hz, label)
        Several satellites' central-tone tracks, each drawn and labelled at its end.
    """
    fig, ax = pyplot().subplots(figsize=(8, 4.5), constrained_layout=True)
    db = 10.0 * np.log10(np.maximum(power, np.max(power) * 1e-12))
    dt = t_s[1] - t_s[0] if len(t_s) > 1 else 1.0
    extent = (t_s[0] - dt / 2, t_s[-1] + dt / 2, f_hz[0] / 1e3, f_hz[-1] / 1e3)
    im = ax.imshow(db, origin="lower", aspect="auto", extent=extent, cmap="viridis",
                   vmin=np.percentile(db, 50), vmax=np.max(db))
    fig.colorbar(im, ax=ax, label="power [dB]")
    if coarse_t_s is not None:
        ax.plot(coarse_t_s, np.asarray(coarse_hz) / 1e3, "w.", ms=3, label="STFT coarse (central tone)")
    if track_t_s is not None:
        ax.plot(track_t_s, np.asarray(track_hz) / 1e3, "r-", lw=1.2, label="fine Doppler (central tone)")
    for k, (t_k, f_k, label) in enumerate(labelled_tracks):
        color = f"C{k % 10}"
        ax.plot(t_k, np.asarray(f_k) / 1e3, ".-", color=color, ms=3, lw=0.8)
        ax.annotate(label, (t_k[-1], f_k[-1] / 1e3), color=color, fontsize=8, xytext=(3, 3),
                    textcoords="offset points", bbox=dict(boxstyle="round,pad=0.15", fc="white", alpha=0.7, lw=0))
    if f_lim_hz is not None:
        ax.set_ylim(-f_lim_hz / 1e3, f_lim_hz / 1e3)
    ax.set_xlabel("time from first sample [s]")
    ax.set_ylabel("baseband frequency [kHz]")
    ax.set_title(title)
    if coarse_t_s is not None or track_t_s is not None:
        ax.legend(loc="upper right", fontsize=8)
    save_png(fig, path)
