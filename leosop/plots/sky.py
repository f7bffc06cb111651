"""Figures of visibility studies: visible count and GDOP over UTC time, sky plot of a window."""

import numpy as np

from ..timebase import format_utc
from .core import ENVELOPE_BINS, envelope, pyplot, save_png

__all__ = ["plot_visibility", "plot_skyplot"]

#: Sky-plot window: tracks over the first ten minutes read as passes; a day of them is a solid disc.
SKYPLOT_WINDOW_S = 600.0
#: Satellites labelled and coloured at most (the highest first); the others are drawn thin and grey.
MAX_LABELS = 12
#: Label geometry on the plot plane, in degrees of zenith distance: the polar axes of the 6.4 in figure
#: span 180 deg in about 345 pt, so a 7 pt label of 5 digits is ~11 x 4.7 deg, drawn 5 pt right, 3 pt up.
_PT_PER_DEG = 1.9
#: Colours of the labelled satellites: the default cycle less its grey (C7), kept for the unlabelled ones.
_COLOURS = tuple(f"C{k}" for k in range(10) if k != 7)
_LABEL_BOX_DEG = np.array([11.0, 4.7])
_LABEL_OFFSET_DEG = np.array([5.0, 3.0]) / _PT_PER_DEG


def _utc_axis(ax):
    """Concise UTC date ticks on the x axis."""
    import matplotlib.dates as mdates

    locator = mdates.AutoDateLocator()
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    ax.set_xlabel("time [UTC]")


def plot_visibility(path, times_utc, n_visible, gdop, gdop_range, *, mask_deg, title=""):
    """Visible satellites, Doppler GDOP and range GDOP against UTC time, saved to ``path`` (PNG).

    Parameters
    ----------
    path : str or Path
    times_utc : ndarray of datetime64, (n_epochs,)
    n_visible : ndarray of int, (n_epochs,)
    gdop : ndarray, (n_epochs,)
        Doppler GDOP ([Shen 2024] eq. 10); NaN below 7 satellites.
    gdop_range : ndarray, (n_epochs,)
        Classic pseudorange GDOP, for comparison; NaN below 4 satellites.
    mask_deg : float
    title : str
        What was run (element sets, site); drawn above the figure.

    Spans of more than ``2 ENVELOPE_BINS`` epochs are drawn through their :func:`~.core.envelope`.
    """
    plt = pyplot()
    t = np.asarray(times_utc).astype("datetime64[ms]")
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5), constrained_layout=True)
    if t.size > 2 * ENVELOPE_BINS:  # a long span through its envelope: steps this dense draw as a band anyway
        ax1.plot(*envelope(t, n_visible), color="C0")
    else:
        ax1.step(t, n_visible, where="mid", color="C0")
    ax1.axhline(7, color="0.5", ls="--", lw=0.8, label="7 needed for a Doppler fix")
    ax1.set_ylabel(f"visible satellites\n(mask {mask_deg:g} deg)")
    ax1.legend(loc="upper right", fontsize=8)
    fig.suptitle(title, fontsize="medium")
    ax2.semilogy(*envelope(t, gdop), color="C1", label="Doppler, 7 states ([Shen 2024] eq. 10) [m per Hz]")
    ax2.semilogy(*envelope(t, gdop_range), color="C2", lw=0.8, label="pseudorange, 4 states [unitless]")
    ax2.set_ylabel("GDOP")
    ax2.legend(loc="upper right", fontsize=8)
    _utc_axis(ax2)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    save_png(fig, path, dpi=110)


def plot_skyplot(path, az_rad, elev_rad, t_s, sat_label, start_utc, *, mask_deg, window_s=SKYPLOT_WINDOW_S,
                 title=""):
    """Sky plot at the first epoch with the tracks of the following ``window_s``, saved to ``path`` (PNG).

    North up, azimuth clockwise, compass points marked, elevation rings
    labelled in degrees, the sky below the mask shaded. Satellites above the
    mask at the first epoch are dots, each with its track over the window as
    a line starting at the dot; the :data:`MAX_LABELS` highest are coloured
    and labelled with their id, any others drawn thin and grey, so a dense
    shell stays readable.

    Parameters
    ----------
    path : str or Path
    az_rad, elev_rad : ndarray, (m,)
        Visible points (any order).
    t_s : ndarray, (m,)
        Seconds of each point since ``start_utc`` (the first epoch is 0).
    sat_label : ndarray of str, (m,)
        Satellite id of each point; points with the same id form one track.
    start_utc : numpy.datetime64
        The first epoch (the instant shown).
    mask_deg : float
    window_s : float
        Length of the tracks drawn [s].
    title : str
        What was run; the instant and window are added below it.
    """
    plt = pyplot()
    fig = plt.figure(figsize=(6.4, 7))
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.fill_between(np.linspace(0, 2 * np.pi, 181), 90 - mask_deg, 90, color="0.85", zorder=0,
                    label=f"below the {mask_deg:g} deg mask")
    t_s = np.asarray(t_s, float)
    sat_label = np.asarray(sat_label)
    now = t_s == 0.0
    # Only the satellites up at the instant, each with the next window_s of its pass: later risers would
    # turn a day (or a dense shell) into a solid disc.
    sel = np.isin(sat_label, sat_label[now]) & (t_s <= window_s)
    az, zen, t_w, labels = az_rad[sel], 90.0 - np.degrees(elev_rad[sel]), t_s[sel], sat_label[sel]
    order = np.lexsort((t_w, labels))
    ids, start = np.unique(labels[order], return_index=True)
    first = order[start]
    # Label the highest MAX_LABELS satellites; a crowd of labels reads as none.
    labelled = set(np.argsort(zen[first], kind="stable")[:MAX_LABELS].tolist())
    placed = []  # lower-left corners of the labels so far, on the plane of the plot [deg]
    for k, (a, b) in enumerate(zip(start, np.r_[start[1:], len(order)])):
        track, i0 = order[a:b], first[k]
        if k not in labelled:
            ax.plot(az[track], zen[track], lw=0.5, color="0.55", zorder=1)
            ax.plot(az[i0], zen[i0], "o", color="0.55", ms=2.5, zorder=1)
            continue
        color = _COLOURS[len(placed) % len(_COLOURS)]
        ax.plot(az[track], zen[track], lw=1.0, color=color, zorder=2)
        ax.plot(az[i0], zen[i0], "o", color=color, ms=4.5, zorder=3)
        # Lift a label until its box clears every label placed before (neighbours in a shell).
        corner = zen[i0] * np.array([np.sin(az[i0]), np.cos(az[i0])]) + _LABEL_OFFSET_DEG
        while any(abs(corner[0] - c[0]) < _LABEL_BOX_DEG[0] and abs(corner[1] - c[1]) < _LABEL_BOX_DEG[1]
                  for c in placed):
            corner[1] += _LABEL_BOX_DEG[1]
        placed.append(corner)
        lift_pt = (corner[1] - zen[i0] * np.cos(az[i0]) - _LABEL_OFFSET_DEG[1]) * _PT_PER_DEG
        ax.annotate(ids[k], (az[i0], zen[i0]), xytext=(5, 3 + lift_pt), textcoords="offset points",
                    fontsize=7, color=color, zorder=4, bbox=dict(boxstyle="round,pad=0.1", fc="white", alpha=0.7,
                                                                  lw=0))
    ax.set_rlim(0, 90)
    # Elevation rings 60, 30 (unless crowding the mask's) and the mask; their name in the shaded band.
    elevations = [e for e in (60.0, 30.0) if abs(e - mask_deg) > 8] + [mask_deg]
    ax.set_rticks([90.0 - e for e in elevations])
    ax.set_yticklabels([f"{e:g}" for e in elevations], fontsize=7)
    ax.set_rlabel_position(112.5)
    ax.text(np.radians(125.0), 90.0 - mask_deg / 2 if mask_deg >= 10 else 100.0, "elevation [deg]", fontsize=7,
            ha="center", va="center")
    ax.set_xticks(np.radians(np.arange(0, 360, 45)))
    ax.set_xticklabels(["N", "NE", "E", "SE", "S", "SW", "W", "NW"])
    ax.legend(loc="lower right", bbox_to_anchor=(1.1, -0.12), fontsize=8)
    span_min = min(window_s, t_s.max(initial=0.0)) / 60
    stamp = format_utc(start_utc)[:19] + "Z"
    shown = f", the {MAX_LABELS} highest labelled, the others grey" if len(ids) > MAX_LABELS else ""
    ax.set_title(f"{title}\nsky at {stamp}: {len(ids)} satellites above {mask_deg:g} deg (dots{shown}),\n"
                 f"their tracks over the next {span_min:.0f} min", fontsize=9, pad=18)
    save_png(fig, path, dpi=110, bbox_inches="tight")
