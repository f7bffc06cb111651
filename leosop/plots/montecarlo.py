"""Figures of a Monte Carlo study: fused error against each swept parameter, with its spread.

One PNG per parameter axis with more than one value, ``error_vs_<name>.png``:
position (top) and velocity (bottom) error, the mean over seeds as a line with
the 10-90 percentile range over seeds as bars and a shaded band (for a
categorical axis such as ``coupling``: points and bars only), one line per
combination of the other axes (up to :data:`MAX_LINES`; beyond that the other
axes are pooled). Lines that nearly coincide stay visible: each has its own
colour, marker (filled and open alternately) and dash, and their points stand
side by side. Axes and legends are labelled by the parameters' long names and
units (the dataset's CF attributes), not their variable names.
"""

import itertools
import warnings

import numpy as np

from .core import pyplot, save_png

__all__ = ["plot_study", "MAX_LINES"]

MAX_LINES = 8
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
_DASHES = ("-", "--", ":", "-.")
_PANELS = (("fused_pos_err_mean_m", "fused position error [m]\n(3D, mean over the flight)"),
           ("fused_vel_err_mean_mps", "fused velocity error [m/s]\n(3D, mean over the flight)"))


def _x(ds, axis):
    values = ds[axis].values
    numeric = np.issubdtype(values.dtype, np.number)
    return (values.astype(float) if numeric else np.arange(values.size)), numeric, values


def _axis_label(ds, name):
    """``time between EKF corrections of the INS [s]``: the axis's long name and units, else its name."""
    attrs = ds[name].attrs
    units = attrs.get("units", "")
    return attrs.get("long_name", name) + (f" [{units}]" if units not in ("", "1") else "")


def _value_label(ds, name, value):
    units = ds[name].attrs.get("units", "")
    return f"{value} {units}" if units not in ("", "1") else f"{value}"


def _lines(ds, axis):
    """(legend title, [(label, selection, pooled axes)] per line)."""
    others = [d for d in ds["fused_pos_err_mean_m"].dims if d not in (axis, "seed")]
    combos = list(itertools.product(*[ds[o].values for o in others]))
    if len(combos) > MAX_LINES:
        return None, [(f"pooled over {', '.join(ds[o].attrs.get('long_name', o) for o in others)}", None, others)]
    title = "; ".join(ds[o].attrs.get("long_name", o) for o in others) or None
    return title, [(", ".join(_value_label(ds, o, v) for o, v in zip(others, c)) or None, dict(zip(others, c)), ())
                   for c in combos]


def _select(ds, metric, axis, where, pooled):
    da = ds[metric]
    if where:
        da = da.sel(where)
    da = da.transpose(axis, *pooled, "seed")
    return da.values.reshape(da.sizes[axis], -1)  # (n_axis, samples)


def plot_study(ds, out_dir, title):
    """Write ``error_vs_<axis>.png`` for every axis of ``ds`` with two or more values; returns their paths."""
    plt = pyplot()
    paths = []
    for axis in [d for d in ds["fused_pos_err_mean_m"].dims if d != "seed" and ds.sizes[d] > 1]:
        x, numeric, labels = _x(ds, axis)
        legend_title, lines = _lines(ds, axis)
        # Lines that nearly coincide stay apart: own marker and dash, and points side by side.
        width = 0.015 * (np.ptp(x) or 1.0) if numeric else 0.08
        fig, axes = plt.subplots(2, 1, figsize=(7, 7), sharex=True, constrained_layout=True)
        for ax, (metric, ylabel) in zip(axes, _PANELS):
            for k, (label, where, pooled) in enumerate(lines):
                v = _select(ds, metric, axis, where, pooled)
                with warnings.catch_warnings():  # cells without a fused output plot as gaps
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mean = np.nanmean(v, axis=1)
                    lo, hi = np.nanpercentile(v, [10, 90], axis=1)
                xk = x + width * (k - (len(lines) - 1) / 2)
                bars = np.maximum([mean - lo, hi - mean], 0.0)  # equal seeds: rounding must not go negative
                style = dict(marker=_MARKERS[k % len(_MARKERS)], ms=6, mfc="none" if k % 2 else None,
                             color=f"C{k % 10}", capsize=4, label=label)
                if numeric:
                    ax.errorbar(xk, mean, yerr=bars, ls=_DASHES[k % len(_DASHES)], **style)
                    ax.fill_between(xk, lo, hi, color=style["color"], alpha=0.12, lw=0)
                else:  # categories: no line between them
                    ax.errorbar(xk, mean, yerr=bars, ls="none", **style)
            finite = ds[metric].values[np.isfinite(ds[metric].values)]
            if finite.size and finite.min() > 0 and finite.max() / finite.min() > 30:
                ax.set_yscale("log")
            ax.set_ylabel(ylabel)
            ax.grid(True, alpha=0.3)
        if not numeric:
            axes[-1].set_xticks(x, labels)
            axes[-1].set_xlim(-0.5, len(x) - 0.5)
        axes[-1].set_xlabel(_axis_label(ds, axis))
        if axes[0].get_legend_handles_labels()[1]:
            axes[0].legend(fontsize=8, title=legend_title, title_fontsize=8)
        side = ", lines' points side by side" if len(lines) > 1 else ""
        axes[0].set_title(f"{title}\npoint: mean over the {ds.sizes['seed']} seeds; bar and band: their 10-90 % "
                          f"range{side}", fontsize=9)
        path = out_dir / f"error_vs_{axis}.png"
        save_png(fig, path)
        paths.append(path)
    return paths

