"""World-map figures of gridded studies (``leosop study gdop-map``).

Plate carree (longitude, latitude in degrees) with the bundled Natural Earth
1:110m coastline (``leosop/data/coastline_110m.npz``, public domain; see the
README there). Matplotlib is loaded only here, through :mod:`leosop.plots.core`.
"""

import functools
from importlib.resources import files

import numpy as np

from .core import pyplot, save_png

__all__ = ["coastline_lon_lat_deg", "plot_fix_fraction", "plot_small_multiples", "MAX_PANELS"]

#: Maps in one small-multiples figure at most (a 3 x 3 grid).
MAX_PANELS = 9


@functools.lru_cache(maxsize=1)
def coastline_lon_lat_deg():
    """Coastline polylines, NaN-separated: ndarray (n, 2) of lon, lat in degrees."""
    with np.load(str(files("leosop") / "data" / "coastline_110m.npz")) as data:
        return data["lon_lat_deg"].astype(float)


def _world_axes(ax):
    xy = coastline_lon_lat_deg()
    ax.plot(xy[:, 0], xy[:, 1], color="k", lw=0.5)
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_aspect("equal")
    ax.set_xticks(np.arange(-180, 181, 60))
    ax.set_yticks(np.arange(-90, 91, 30))
    ax.tick_params(labelsize=7)


def _wrap_lon(lon_deg, values):
    """Repeat the first longitude column at +360 deg when the grid closes the circle.

    Cells are drawn centred on their longitude (``shading="nearest"``): without the repeat, the cell at -180
    covers -182.5..-177.5 on a 5 deg grid and the last half cell before +180 stays blank.

    Parameters
    ----------
    lon_deg : ndarray, (n_lon,)
    values : ndarray, (..., n_lat, n_lon)
    """
    step = lon_deg[1] - lon_deg[0] if lon_deg.size > 1 else 0.0
    if step > 0 and np.isclose(lon_deg[0] + 360.0 - lon_deg[-1], step):
        return np.r_[lon_deg, lon_deg[0] + 360.0], np.concatenate([values, values[..., :1]], axis=-1)
    return lon_deg, values


def plot_fix_fraction(path, lat_deg, lon_deg, fix_fraction, *, title=""):
    """Fraction of epochs with a Doppler fix (>= 7 satellites) per cell.

    Parameters
    ----------
    lat_deg : ndarray, (n_lat,)
    lon_deg : ndarray, (n_lon,)
    fix_fraction : ndarray, (n_lat, n_lon)
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.6), constrained_layout=True)
    lon_wrapped, fraction = _wrap_lon(lon_deg, fix_fraction)
    mesh = ax.pcolormesh(lon_wrapped, lat_deg, fraction, shading="nearest", cmap="viridis", vmin=0, vmax=1)
    _world_axes(ax)
    fig.colorbar(mesh, ax=ax, shrink=0.8, label="fraction of epochs with >= 7 satellites")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("longitude [deg]")
    ax.set_ylabel("latitude [deg]")
    save_png(fig, path, bbox_inches="tight")


def plot_small_multiples(path, lat_deg, lon_deg, values, labels, *, cbar_label, vmin=None, vmax=None,
                         cmap="viridis", log_colors=False, title=""):
    """One world map per epoch, shared colour scale; beyond :data:`MAX_PANELS` epochs, evenly spaced ones.

    The title says how many of the epochs are shown when not all are.

    Parameters
    ----------
    values : ndarray, (n_epochs, n_lat, n_lon)
    labels : list of str, (n_epochs,)
    log_colors : bool
        Logarithmic colour scale (for quantities spanning decades, like GDOP); ``vmin`` must then be > 0.
    """
    n_epochs = len(values)
    pick = np.unique(np.linspace(0, n_epochs - 1, min(MAX_PANELS, n_epochs)).round().astype(int))
    if len(pick) < n_epochs:
        title = f"{title}\n{len(pick)} of the {n_epochs} epochs, evenly spaced"
    lon_deg, values = _wrap_lon(lon_deg, values[pick])
    labels = [labels[k] for k in pick]
    plt = pyplot()
    n = len(values)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols + 1.0, 2.3 * rows + 0.7), squeeze=False,
                             sharex=True, sharey=True, constrained_layout=True)
    finite = values[np.isfinite(values)]
    vmin = vmin if vmin is not None else (float(finite.min()) if finite.size else 0.0)
    vmax = vmax if vmax is not None else (float(finite.max()) if finite.size else 1.0)
    if log_colors:
        from matplotlib.colors import LogNorm

        scale = {"norm": LogNorm(vmin=vmin, vmax=vmax)}
    else:
        scale = {"vmin": vmin, "vmax": vmax}
    mesh = None
    for ax, v, label in zip(axes.ravel(), values, labels):
        mesh = ax.pcolormesh(lon_deg, lat_deg, v, shading="nearest", cmap=cmap, **scale)
        _world_axes(ax)
        ax.set_title(label, fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("longitude [deg]", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("latitude [deg]", fontsize=8)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    if mesh is not None:
        fig.colorbar(mesh, ax=axes.ravel().tolist(), shrink=0.8, label=cbar_label)
    fig.suptitle(title, fontsize=9)
    save_png(fig, path, bbox_inches="tight")
