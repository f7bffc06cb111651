"""Figures of a Monte Carlo study: fused error against each swept parameter, with its spread.

One PNG per parameter axis with more than one value, ``error_vs_<name>.png``:
position (top) and velocity (bottom) error, the mean over seeds as a line and
the 10-90 percentile band over seeds shaded (for a categorical axis such as
``coupling``: points with 10-90 percentile bars), one line per combination of
the other axes (up to :data:`MAX_LINES`; beyond that the other axes are pooled).
"""

import itertools
import warnings

import numpy as np

from .core import pyplot, save_png

__all__ = ["plot_study", "MAX_LINES"]

MAX_LINES = 8
_PANELS = (("fused_pos_err_mean_m", "fused position error [m]\n(3D, mean over the flight)"),
           ("fused_vel_err_mean_mps", "fused velocity error [m/s]\n(3D, mean over the flight)"))


def _x(ds, axis):
    values = ds[axis].values
    numeric = np.issubdtype(values.dtype, np.number)
    return (values.astype(float) if numeric else np.arange(values.size)), numeric, values


def _lines(ds, axis):
    """(label, DataArray over (axis, seed)) per line."""
    others = [d for d in ds["fused_pos_err_mean_m"].dims if d not in (axis, "seed")]
    combos = list(itertools.product(*[ds[o].values for o in others]))
    if len(combos) > MAX_LINES:
        return [(f"pooled over {', '.join(others)}", None, others)]
    return [(", ".join(f"{o}={v}" for o, v in zip(others, c)) or None, dict(zip(others, c)), ()) for c in combos]


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
        fig, axes = plt.subplots(2, 1, figsize=(7, 7), sharex=True, constrained_layout=True)
        for ax, (metric, ylabel) in zip(axes, _PANELS):
            lines = _lines(ds, axis)
            for k, (label, where, pooled) in enumerate(lines):
                v = _select(ds, metric, axis, where, pooled)
                with warnings.catch_warnings():  # cells without a fused output plot as gaps
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mean = np.nanmean(v, axis=1)
                    lo, hi = np.nanpercentile(v, [10, 90], axis=1)
                if numeric:
                    line, = ax.plot(x, mean, "o-", label=label)
                    ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2)
                else:  # categories: no line between them; the band as an error bar, lines side by side
                    dx = 0.08 * (k - (len(lines) - 1) / 2)
                    ax.errorbar(x + dx, mean, yerr=[mean - lo, hi - mean], fmt="o", capsize=4, label=label)
            finite = ds[metric].values[np.isfinite(ds[metric].values)]
            if finite.size and finite.min() > 0 and finite.max() / finite.min() > 30:
                ax.set_yscale("log")
            ax.set_ylabel(ylabel)
            ax.grid(True, alpha=0.3)
        if not numeric:
            axes[-1].set_xticks(x, labels)
            axes[-1].set_xlim(-0.5, len(x) - 0.5)
        units = ds[axis].attrs.get("units")
        axes[-1].set_xlabel(axis + (f" [{units}]" if units else ""))
        if axes[0].get_legend_handles_labels()[1]:
            axes[0].legend(fontsize=7)
        spread = "band" if numeric else "bar"
        axes[0].set_title(f"{title}\npoint: mean over the {ds.sizes['seed']} seeds; {spread}: their 10-90 % range",
                          fontsize=9)
        path = out_dir / f"error_vs_{axis}.png"
        save_png(fig, path)
        paths.append(path)
    return paths

