"""Figures of a simulation, after [Shen 2024]'s Fig. 4 (trajectory), 8 (errors), 9 (visible satellites), 10 (GDOP).

Matplotlib is imported lazily with the Agg backend; every figure is written
atomically (:func:`leosop.figure.save_png`).
"""

from pathlib import Path

import numpy as np

from .figure import pyplot, save_png
from .frames import ecef_to_geodetic

__all__ = ["write_figures", "trajectory_figure", "errors_figure", "visible_figure", "gdop_figure"]


def _save(fig, path):
    save_png(fig, path, bbox_inches="tight")


def trajectory_figure(result, path):
    """Fig. 4: truth, INS-only and fused tracks in longitude/latitude and height."""
    plt = pyplot()
    fig, (ax, ax_h) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [2, 1]})
    for label, pos, style in (("truth", result.truth_pos_ecef_m, "k-"), ("INS only", result.ins_pos_ecef_m, "C1--"),
                              ("Starlink/INS", result.fused.pos_ecef_m, "C0:")):
        lat, lon, alt = ecef_to_geodetic(pos)
        ax.plot(np.degrees(lon), np.degrees(lat), style, label=label)
        ax_h.plot(result.t_s, alt, style, label=label)
    ax.set_xlabel("longitude [deg]")
    ax.set_ylabel("latitude [deg]")
    ax.set_title(f"{result.scenario.name}: flight trajectory")
    ax.legend()
    ax_h.set_xlabel("time [s]")
    ax_h.set_ylabel("height [m]")
    _save(fig, path)


def errors_figure(result, path):
    """Fig. 8: 3D position and velocity errors of INS only, LEO fixes and the fusion."""
    plt = pyplot()
    err = result.errors()
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for i, (ax, unit) in enumerate(zip(axes, ("position error [m]", "velocity error [m/s]"))):
        ax.semilogy(result.t_s, err["leo_fix"][i], ".", color="0.7", ms=2, label="LEO fix")
        ax.semilogy(result.t_s, err["ins_only"][i], "C1-", label="INS only")
        ax.semilogy(result.t_s, err["fused"][i], "C0-", label="Starlink/INS")
        ax.set_ylabel(unit)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend()
    axes[0].set_title(f"{result.scenario.name}: errors ({result.level} level, correction every "
                      f"{result.correction_period_s:g} s)")
    axes[1].set_xlabel("time [s]")
    _save(fig, path)


def visible_figure(result, path):
    """Fig. 9: number of visible satellites."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.2))
    ax.step(result.t_s, result.n_visible, where="mid")
    ax.axhline(7, color="C3", ls=":", label="7 needed for a snapshot fix")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("visible satellites")
    ax.legend()
    _save(fig, path)


def gdop_figure(result, path):
    """Fig. 10: GDOP of Doppler positioning (eq. 10) along the flight."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.2))
    ax.semilogy(result.t_s, result.gdop)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("GDOP")
    _save(fig, path)


def write_figures(result, out_dir):
    """All four figures into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    paths = []
    for name, func in (("fig4_trajectory.png", trajectory_figure), ("fig8_errors.png", errors_figure),
                       ("fig9_visible.png", visible_figure), ("fig10_gdop.png", gdop_figure)):
        func(result, out / name)
        paths.append(out / name)
    return paths
