"""Spectrogram of a recording with the Doppler track over it."""

import numpy as np

from .core import pyplot, save_png

__all__ = ["plot_spectrogram"]


#: Smallest vertical gap between two track labels, as a fraction of the frequency axis.
_LABEL_GAP = 0.045


def plot_spectrogram(path, t_s, f_hz, power, *, track_t_s=None, track_hz=None, coarse_t_s=None,
                     coarse_hz=None, f_lim_hz=None, title="", labelled_tracks=(),
                     x_label="time from the first sample [s]"):
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
        Several satellites' central-tone tracks, each drawn and labelled at its end; labels that would
        overprint are moved apart and tied to their track's end by a thin line.
    x_label : str
        Time-axis label (say the UTC origin).
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
        ax.plot(track_t_s, np.asarray(track_hz) / 1e3, "r.-", lw=0.8, ms=5,
                label="fine Doppler per block (strongest comb, central tone)")
    if f_lim_hz is not None:
        ax.set_ylim(-f_lim_hz / 1e3, f_lim_hz / 1e3)
    for k, (t_k, f_k, _) in enumerate(labelled_tracks):
        ax.plot(t_k, np.asarray(f_k) / 1e3, ".-", color=f"C{k % 10}", ms=3, lw=0.8)
    if len(labelled_tracks):
        _label_track_ends(ax, labelled_tracks, extent)
    ax.set_xlabel(x_label)
    ax.set_ylabel("baseband frequency [kHz]")
    ax.set_title(title)
    if coarse_t_s is not None or track_t_s is not None:
        ax.legend(loc="upper right", fontsize=8)
    save_png(fig, path)


def _label_track_ends(ax, tracks, extent):
    """Label each track at its end; labels of ends close in time are spread apart in frequency.

    The time axis is widened so labels at the right edge stay inside it.
    """
    t_end = np.array([t[-1] for t, _, _ in tracks], float)
    f_end_khz = np.array([f[-1] / 1e3 for _, f, _ in tracks], float)
    y_lo, y_hi = ax.get_ylim()
    gap = _LABEL_GAP * (y_hi - y_lo)
    span = extent[1] - extent[0]
    y_text = f_end_khz.copy()
    # Groups of ends close in time; in each, from the bottom, every label at least `gap` above the previous.
    by_time = np.argsort(t_end, kind="stable")
    groups = np.split(by_time, np.flatnonzero(np.diff(t_end[by_time]) > 0.15 * span) + 1)
    for group in groups:
        previous = -np.inf
        for i in group[np.argsort(f_end_khz[group], kind="stable")]:
            y_text[i] = previous = max(f_end_khz[i], previous + gap)
    x_text = t_end + 0.02 * span
    for k, (_, _, label) in enumerate(tracks):
        color = f"C{k % 10}"
        ax.annotate(label, (t_end[k], f_end_khz[k]), xytext=(x_text[k], y_text[k]), textcoords="data",
                    color=color, fontsize=7, va="center",
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", alpha=0.8, lw=0),
                    arrowprops=dict(arrowstyle="-", color=color, lw=0.6))
    ax.set_xlim(extent[0], extent[1] + 0.14 * span)
