"""Spectrogram of a recording with the Doppler track over it."""

import numpy as np
from scipy.optimize import isotonic_regression

from .core import pyplot, save_png

__all__ = ["plot_spectrogram", "plot_survey"]


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
        Several satellites' central-tone tracks, each drawn and labelled in a column right of the data,
        tied to its track's end by a thin line that crosses no label.
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
    """Label every track in one column right of the data, tied to its track's end by a thin leader line.

    The labels keep the order of the ends' frequencies and stand at least :data:`_LABEL_GAP` apart; as every
    leader line runs left of the column and every label sits in it, no line crosses a label. The time axis
    is widened to hold the column.
    """
    t_end = np.array([t[-1] for t, _, _ in tracks], float)
    f_end_khz = np.array([f[-1] / 1e3 for _, f, _ in tracks], float)
    y_lo, y_hi = ax.get_ylim()
    gap = _LABEL_GAP * (y_hi - y_lo)
    span = extent[1] - extent[0]
    order = np.argsort(f_end_khz, kind="stable")
    steps = gap * np.arange(len(order))
    # Labels as near their ends as `gap` apart in the ends' order allows (least squares), inside the axes.
    y_text = isotonic_regression(f_end_khz[order] - steps).x + steps
    y_text = np.clip(y_text, y_lo + gap / 2 + steps, y_hi - gap / 2 - steps[::-1])
    x_text = extent[1] + 0.03 * span
    for rank, k in enumerate(order):
        color = f"C{k % 10}"
        ax.annotate(tracks[k][2], (t_end[k], f_end_khz[k]), xytext=(x_text, y_text[rank]), textcoords="data",
                    color=color, fontsize=7, ha="left", va="center", annotation_clip=False,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", alpha=0.8, lw=0),
                    arrowprops=dict(arrowstyle="-", color=color, lw=0.6, shrinkA=0, shrinkB=0))
    ax.set_xlim(extent[0], extent[1] + 0.16 * span)



def plot_survey(path, doc, *, title=""):
    """Write a PNG: one block's spectrum (dB over the noise per bin) with ``leosop doctor``'s findings.

    Marked: the DC offset, each interferer (red), the tones of the strongest
    combs (green ticks on top), the rough or stated LO offset (dashed), the
    noise (0 dB) and the findings as text.
    """
    spec = doc["spectrum"]
    f_khz = spec["frequency_hz"] / 1e3
    db = np.asarray(spec["power_db"])
    # Peak-hold over groups of bins: a 0.1 s block has far more bins than a figure has pixels.
    group = max(1, db.size // 4000)
    m = db.size // group * group
    f_plot = f_khz[:m].reshape(-1, group).mean(axis=1)
    db_plot = db[:m].reshape(-1, group).max(axis=1)
    fig, ax = pyplot().subplots(figsize=(9, 4.8), constrained_layout=True)
    ax.plot(f_plot, db_plot, lw=0.5, color="0.3")
    ax.axhline(0.0, color="0.5", lw=0.8, ls=":", label="noise")
    top = float(np.max(db_plot)) + 3.0
    comb = spec["comb"]
    for k, c in enumerate(doc["strongest_combs"][:8]):
        tones = (c["doppler_hz"] + comb.offsets_hz * (1.0 + c["doppler_hz"] / comb.carrier_hz)) / 1e3
        ax.plot(tones, np.full(tones.size, top), "v", color="tab:green", ms=4,
                label="tones of the strongest combs" if k == 0 else None)
    for k, ln in enumerate(doc["interferers"]):
        ax.axvline(ln["frequency_hz"] / 1e3, color="tab:red", lw=0.8, alpha=0.7,
                   label="interferers (excised)" if k == 0 else None)
    if doc["dc_dbhz"] is not None:
        ax.axvline(0.0, color="tab:orange", lw=0.8, alpha=0.7, label=f"DC ({doc['dc_dbhz']:.0f} dB-Hz)")
    lo = doc["lo_offset_hz_stated"] if doc["lo_offset_hz_stated"] is not None else doc["lo_offset_hz_rough"]
    if lo is not None:
        ax.axvline(lo / 1e3, color="tab:blue", ls="--", lw=1.0,
                   label=f"LO offset, {'stated' if doc['lo_offset_hz_stated'] is not None else 'rough'}")
    ax.set_xlabel("baseband frequency [kHz]")
    ax.set_ylabel(f"power over the noise per bin [dB] (peak of {group})" if group > 1
                  else "power over the noise per bin [dB]")
    ax.set_ylim(-10.0, top + 5.0)
    ax.legend(loc="upper left", fontsize=7)
    text = "\n".join(doc["findings"][:6]) or "no front-end problem found"
    ax.text(0.99, 0.02, text, transform=ax.transAxes, ha="right", va="bottom", fontsize=7,
            bbox={"facecolor": "white", "alpha": 0.8, "lw": 0})
    ax.set_title(title, fontsize=9)
    save_png(fig, path)
