"""Figures of the PPP and PPP/INS runs: position error or offset with its sigma, satellites, fixed ambiguities."""

import numpy as np

from .core import pyplot, save_png

__all__ = ["ppp_figure", "ppp_ins_figure"]


def ppp_figure(t_h, d_enu_m, sigma_enu_m, n_sats, path, *, title):
    """ENU offsets from a reference with +-1 sigma, and the satellites used.

    Parameters
    ----------
    t_h : ndarray, shape (n,)
        Hours since the start.
    d_enu_m, sigma_enu_m : ndarray, shape (n, 3)
    n_sats : ndarray of int, shape (n,)
    path : str or Path
    """
    plt = pyplot()
    fig, ax = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for i, name in enumerate("ENU"):
        ax[i].plot(t_h, d_enu_m[:, i], lw=0.8, label=name)
        ax[i].fill_between(t_h, -sigma_enu_m[:, i], sigma_enu_m[:, i], color="0.8", label="+-1 sigma")
        ax[i].set_ylabel(f"{name} [m]")
        lim = np.nanpercentile(np.abs(d_enu_m[:, i]), 99) * 1.5
        if np.isfinite(lim) and lim > 0:
            ax[i].set_ylim(-lim, lim)
        ax[i].grid(alpha=0.3)
    ax[0].legend(loc="upper right", fontsize=8)
    ax[3].step(t_h, n_sats, where="post", lw=0.8)
    ax[3].set_ylabel("satellites")
    ax[3].set_xlabel("time [h]")
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
