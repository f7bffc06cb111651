"""Figures of a simulation: ``trajectory.png``, ``errors_3d.png``, ``visible.png`` and ``gdop.png``.

They follow [Shen 2024]'s Fig. 4 (trajectory), 8 (errors), 9 (visible satellites) and 10 (GDOP).

Every title names the run (scenario, coupling, level, seed) and every time
axis its UTC origin. Besides the paper's four, ``errors_enu.png`` splits the
fused position error into east, north and up with the filter's +-3 sigma,
and a scenario of several constellations adds ``visible_by_family.png``.
Matplotlib is imported lazily with the Agg backend; every figure is written
atomically (:func:`leosop.plots.save_png`).
"""

from pathlib import Path

import numpy as np

from ..apps.scenarios import mask_label
from ..frames import ecef_to_enu, ecef_to_geodetic
from ..timebase import format_utc
from .core import pyplot, save_png

__all__ = ["write_figures", "trajectory_figure", "errors_figure", "errors_enu_figure", "visible_figure",
           "gdop_figure", "visible_by_family_figure", "run_label", "time_label"]


def _save(fig, path):
    save_png(fig, path, bbox_inches="tight")


def run_label(result):
    """``scenario (loose coupling, signal level, seed 0)``: what was run, for titles."""
    return f"{result.scenario.name} ({result.coupling} coupling, {result.level} level, seed {result.seed})"


def time_label(result):
    """Time-axis label with the UTC origin (seconds up to a flight's length read better than clock times)."""
    return f"time since {format_utc(result.times_utc[0])[:19]}Z [s]"


def trajectory_figure(result, path):
    """Fig. 4: truth, INS-only and fused tracks in the local east/north plane of the start, and heights.

    Equal aspect, so a turn looks like a turn; the truth drawn thick and light, the fused solution thin and
    dark on top of it, start and end marked. The fused track lies metres from the truth on a flight of
    kilometres, so an inset shows the end of the flight in metres (:func:`_end_inset`).
    """
    plt = pyplot()
    fig, (ax, ax_h) = plt.subplots(1, 2, figsize=(11, 5), gridspec_kw={"width_ratios": [3, 2]},
                                   layout="constrained")
    origin = result.truth_pos_ecef_m[0]
    lat0, lon0, _ = ecef_to_geodetic(origin)
    positions = (result.truth_pos_ecef_m, result.ins_pos_ecef_m, result.fused.pos_ecef_m)
    enus = [ecef_to_enu(pos - origin, lat0, lon0) for pos in positions]
    unit, scale = ("km", 1e3) if np.ptp(enus[0][:, :2], axis=0).max() > 20e3 else ("m", 1.0)
    styles = (("truth", dict(color="0.75", lw=5, solid_capstyle="round")),
              ("INS only", dict(color="C1", lw=1.2, ls="--")),
              (result.fused_label, dict(color="C0", lw=1.0)))
    for (label, style), enu, pos in zip(styles, enus, positions):
        ax.plot(enu[:, 0] / scale, enu[:, 1] / scale, label=label, **style)
        ax_h.plot(result.t_s, ecef_to_geodetic(pos)[2], **style)
    ends = enus[0][[0, -1], :2] / scale
    ax.plot(*ends[0], "k^", ms=8, label="start", zorder=5)
    ax.plot(*ends[1], "ks", ms=7, label="end", zorder=5)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"east of the start [{unit}]")
    ax.set_ylabel(f"north of the start [{unit}]")
    ax.set_title(f"{run_label(result)}: trajectory\n(local east/north at "
                 f"lat {np.degrees(lat0):.4f} deg, lon {np.degrees(lon0):.4f} deg)", fontsize=10)
    ax.grid(True, alpha=0.3)
    _end_inset(ax, enus, styles, scale)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncol=5, fontsize="small")
    ax_h.set_xlabel(time_label(result))
    ax_h.set_ylabel("height above the ellipsoid [m]")
    ax_h.grid(True, alpha=0.3)
    _save(fig, path)


def _end_inset(ax, enus, styles, scale):
    """The last epochs in metres around the truth's end, in the quarter of ``ax`` the tracks leave emptiest.

    Half-width: 3 x the fused solution's largest horizontal distance from the truth over the last 20
    epochs, at least 5 m, so the two tracks are seen apart.
    """
    truth, _, fused = enus
    last = slice(max(len(truth) - 20, 0), None)
    half_m = max(3 * np.hypot(*(fused[last, :2] - truth[last, :2]).T).max(initial=0.0), 5.0)
    ax.apply_aspect()
    frac = ax.transAxes.inverted().transform(ax.transData.transform(truth[:, :2] / scale))
    corners = [(0.03, 0.04), (0.55, 0.04), (0.03, 0.54), (0.55, 0.54)]
    crowd = [np.sum((frac[:, 0] > x - 0.03) & (frac[:, 0] < x + 0.45) & (frac[:, 1] > y - 0.04)
                    & (frac[:, 1] < y + 0.45)) for x, y in corners]
    inset = ax.inset_axes([*corners[int(np.argmin(crowd))], 0.42, 0.42])
    centre = truth[-1, :2]
    for (_, style), enu in zip(styles, enus):
        inset.plot(enu[:, 0] - centre[0], enu[:, 1] - centre[1], **style)
    inset.plot(0.0, 0.0, "ks", ms=5)
    inset.set_xlim(-half_m, half_m)
    inset.set_ylim(-half_m, half_m)
    inset.set_aspect("equal")
    inset.tick_params(labelsize=6)
    inset.set_title("end of the flight [m]", fontsize=7)
    inset.grid(True, alpha=0.3)


def errors_figure(result, path):
    """Fig. 8: 3D position and velocity errors of INS only, LEO fixes and the fusion."""
    plt = pyplot()
    err = result.errors()
    var = np.diagonal(result.fused.pos_vel_cov_enu(), axis1=-2, axis2=-1)  # [dv_enu, dpos_enu]
    # 3 x the root of the trace: the filter's own 3D bound (the RSS of the three axes' sigmas).
    bound_3d = 3 * np.sqrt(np.stack([var[:, 3:6].sum(axis=1), var[:, 0:3].sum(axis=1)]))
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for i, (ax, unit) in enumerate(zip(axes, ("position error [m]", "velocity error [m/s]"))):
        ax.semilogy(result.t_s, err["leo_fix"][i], ".", color="0.7", ms=2, label="LEO fix")
        ax.semilogy(result.t_s, err["ins_only"][i], "C1-", label="INS only")
        ax.semilogy(result.t_s, err["fused"][i], "C0-", label=result.fused_label)
        ax.semilogy(result.t_s, bound_3d[i], "C0--", lw=0.8, label=f"{result.fused_label} filter 3 sigma (3D)")
        ax.set_ylabel(unit)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(ncol=4, loc="upper left", fontsize="small", framealpha=0.9, markerscale=4)
    axes[0].set_title(f"{run_label(result)}: 3D errors, correction every {result.correction_period_s:g} s")
    axes[1].set_xlabel(time_label(result))
    _save(fig, path)


def errors_enu_figure(result, path):
    """Fused position error east, north, up with the filter's +-3 sigma bounds."""
    plt = pyplot()
    err = ecef_to_enu(result.fused.pos_ecef_m - result.truth_pos_ecef_m, result.truth_lat_rad, result.truth_lon_rad)
    sigma = np.sqrt(np.diagonal(result.fused.pos_vel_cov_enu(), axis1=-2, axis2=-1))[:, 3:6]
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, (ax, name) in enumerate(zip(axes, ("east", "north", "up"))):
        ax.fill_between(result.t_s, -3 * sigma[:, k], 3 * sigma[:, k], color="C0", alpha=0.2,
                        label="filter +-3 sigma")
        ax.plot(result.t_s, err[:, k], "C0-", lw=1, label=f"{result.fused_label} error")
        inside = np.mean(np.abs(err[1:, k]) <= 3 * sigma[1:, k])
        ax.set_ylabel(f"{name} error [m]")
        ax.text(0.99, 0.95, f"{inside:.1%} inside +-3 sigma", transform=ax.transAxes, ha="right", va="top",
                fontsize="small")
        ax.grid(True, alpha=0.3)
    # Bound the axes by the bulk of the run, not the first seconds' large initial covariance.
    skip = min(10, len(result.t_s) // 2)
    bulk = np.abs(np.concatenate([3 * sigma[skip:], err[skip:]], axis=0))
    for ax, col in zip(axes, bulk.T):
        col = col[np.isfinite(col)]
        if col.size and np.percentile(col, 99) > 0:
            ax.set_ylim(-1.2 * np.percentile(col, 99), 1.2 * np.percentile(col, 99))
    axes[0].legend(loc="lower right", fontsize="small")
    axes[0].set_title(f"{run_label(result)}: fused position error")
    axes[-1].set_xlabel(time_label(result))
    _save(fig, path)


def visible_figure(result, path):
    """Fig. 9: number of visible satellites."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.2))
    ax.step(result.t_s, result.n_visible, where="mid")
    ax.axhline(7, color="C3", ls=":", label="7 needed for a snapshot fix")
    ax.set_xlabel(time_label(result))
    ax.set_ylabel(f"visible satellites (mask {mask_label(result.scenario)})")
    ax.set_title(f"{run_label(result)}: visible satellites")
    ax.legend()
    _save(fig, path)


def gdop_figure(result, path):
    """Fig. 10: GDOP of Doppler positioning (eq. 10) along the flight; epochs without a fix shaded."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.4))
    ax.semilogy(result.t_s, result.gdop)
    gap = ~np.isfinite(result.gdop)
    if gap.any():
        ax.fill_between(result.t_s, 0, 1, where=gap, transform=ax.get_xaxis_transform(), color="0.85",
                        step="mid", label="< 7 satellites: no fix")
        ax.legend(loc="upper left", fontsize="small")
    ax.set_xlabel(time_label(result))
    # [Shen 2024] eq. 10: root of the trace over position [m^2], velocity [(m/s)^2] and
    # clock [Hz^2] per 1 Hz of Doppler noise; the position part dominates (docs/visibility.md).
    ax.set_ylabel("Doppler GDOP\n[~m of position per Hz]")
    ax.set_title(f"{run_label(result)}: Doppler GDOP ([Shen 2024] eq. 10)")
    ax.grid(True, which="both", alpha=0.3)
    _save(fig, path)


def visible_by_family_figure(result, path):
    """Tracked satellites of each family, stacked, with the states a snapshot fix needs (6 + k)."""
    plt = pyplot()
    families = result.scenario.leo.constellations
    counts = result.n_visible_by_family
    fig, ax = plt.subplots(figsize=(9, 3.4))
    ax.stackplot(result.t_s, counts.T, labels=families, step="mid", alpha=0.8)
    need = 6 + (counts > 0).sum(axis=1)
    ax.step(result.t_s, np.where(counts.sum(axis=1) > 0, need, np.nan), "k:", where="mid",
            label="6 + k needed for a snapshot fix")
    ax.set_xlabel(time_label(result))
    ax.set_ylabel("tracked satellites")
    ax.set_title(f"{run_label(result)}: satellites above the {mask_label(result.scenario)} mask per family")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")  # beside: the stack fills the axes
    _save(fig, path)


def write_figures(result, out_dir):
    """The five figures, and ``visible_by_family.png`` for several constellations, into ``out_dir``; their paths."""
    out = Path(out_dir)
    figures = [("trajectory.png", trajectory_figure), ("errors_3d.png", errors_figure),
               ("errors_enu.png", errors_enu_figure), ("visible.png", visible_figure), ("gdop.png", gdop_figure)]
    if len(result.scenario.leo.constellations) > 1:
        figures.append(("visible_by_family.png", visible_by_family_figure))
    paths = []
    for name, func in figures:
        func(result, out / name)
        paths.append(out / name)
    return paths
