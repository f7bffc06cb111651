"""Figures of the PPP and PPP/INS runs: position error or offset with its sigma, satellites, fixed ambiguities."""

import numpy as np

from .core import pyplot, save_png

__all__ = ["ppp_figure", "ppp_ins_figure"]


def ppp_figure(time_gps, d_enu_m, sigma_enu_m, n_sats, path, *, title, n_fixed=None):
    """ENU offsets from a reference in centimetres with the filter's +-3 sigma, the satellites used and fixed.

    The band is drawn with its edges, and each panel prints its median 3 sigma, so a band far thinner than
    the offsets still shows (and says so) instead of vanishing under the line.

    Parameters
    ----------
    time_gps : ndarray of datetime64, shape (n,)
        Epochs (GPS time); the axis counts hours from the first, whose date and time label it.
    d_enu_m, sigma_enu_m : ndarray, shape (n, 3)
        Offsets east, north, up [m] and their 1-sigma [m].
    n_sats : ndarray of int, shape (n,)
    path : str or Path
    title : str
    n_fixed : ndarray of int, shape (n,), optional
        Narrow-lane ambiguities fixed per epoch (ambiguity resolution): fixed
        epochs are drawn in green, float ones in blue, and the count joins
        the satellites' panel.
    """
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    time_gps = np.asarray(time_gps, "datetime64[ns]")
    t_h = (time_gps - time_gps[0]).astype(np.int64) / 3.6e12
    d_cm, band_cm = 100.0 * np.asarray(d_enu_m), 300.0 * np.asarray(sigma_enu_m)
    fig, ax = plt.subplots(4, 1, figsize=(8, 8), sharex=True, constrained_layout=True,
                           gridspec_kw={"height_ratios": [1, 1, 1, 0.7]})
    for i, name in enumerate(("east", "north", "up")):
        ax[i].fill_between(t_h, -band_cm[:, i], band_cm[:, i], color="C1", alpha=0.3, lw=0,
                           label="filter +-3 sigma")
        for sign in (-1, 1):
            ax[i].plot(t_h, sign * band_cm[:, i], color="C1", lw=0.7)
        if n_fixed is None:
            ax[i].plot(t_h, d_cm[:, i], color="C0", lw=0.8, label="offset")
        else:
            fixed = np.asarray(n_fixed) > 0
            ax[i].plot(t_h, np.where(fixed, np.nan, d_cm[:, i]), color="C0", lw=0.8, label="offset, float")
            ax[i].plot(t_h, np.where(fixed, d_cm[:, i], np.nan), color="C2", lw=0.8, label="offset, fixed")
        ax[i].set_ylabel(f"{name} [cm]")
        # The bulk of the run: neither the first epochs' metres nor a lone outlier set the scale.
        lim = 1.2 * np.nanpercentile(np.abs(np.concatenate([d_cm[:, i], band_cm[:, i]])), 99)
        if np.isfinite(lim) and lim > 0:
            ax[i].set_ylim(-lim, lim)
        ax[i].text(0.99, 0.04, f"median 3 sigma {np.nanmedian(band_cm[:, i]):.2f} cm", transform=ax[i].transAxes,
                   ha="right", va="bottom", fontsize="small", bbox={"fc": "white", "alpha": 0.8, "lw": 0})
        ax[i].grid(alpha=0.3)
    ax[0].legend(loc="upper right", fontsize=8, ncol=3)
    ax[3].step(t_h, n_sats, where="post", lw=0.8, label="used")
    if n_fixed is not None:
        ax[3].step(t_h, n_fixed, where="post", lw=0.8, color="C2", label="narrow-lane fixed (SD)")
        ax[3].legend(loc="upper right", fontsize=8, ncol=2)
    ax[3].yaxis.set_major_locator(MaxNLocator(integer=True))
    ax[3].set_ylabel("satellites")
    ax[3].grid(alpha=0.3)
    ax[3].set_xlabel(f"hours since {str(time_gps[0].astype('datetime64[s]')).replace('T', ' ')} GPS time")
    ax[0].set_title(title)
    save_png(fig, path)


def ppp_ins_figure(t_s, err_float_m, err_fixed_m, sigma_3d_m, n_fixed, n_sats, path, *, title):
    """3-D errors of the float and fixed solutions, the float sigma, fixed ambiguities and satellites.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
    err_float_m, err_fixed_m, sigma_3d_m : ndarray, shape (n,)
        NaN where there is no solution.
    n_fixed, n_sats : ndarray of int, shape (n,)
    """
    plt = pyplot()
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    t = t_s / 60.0
    ax[0].semilogy(t, err_float_m, lw=0.8, label="float")
    ax[0].semilogy(t, err_fixed_m, lw=0.8, label="fixed")
    ax[0].semilogy(t, sigma_3d_m, lw=0.8, ls="--", color="0.4", label="float 1-sigma (3-D)")
    ax[0].set_ylabel("3-D error [m]")
    ax[0].legend(fontsize=8)
    ax[0].grid(alpha=0.3, which="both")
    ax[1].step(t, n_sats, where="post", lw=0.8, label="satellites")
    ax[1].step(t, n_fixed, where="post", lw=0.8, label="NL ambiguities fixed")
    ax[1].set_xlabel("time [min]")
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3)
    ax[0].set_title(title)
    save_png(fig, path)
