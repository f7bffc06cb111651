"""[Qu 2024] reproduced: Monte Carlo of the coarse alignment over all attitudes.

``fig2``: for every pitch of the sweep, the attitude grid (yaw -180..180,
roll 0..360) times ``n_shots`` random sensor errors (accelerometer 1 mg,
gyro 0.1 deg/h, 1 sigma per axis, latitude 30 deg); the maximum absolute
pitch, roll and yaw errors per pitch for algorithms 1, 2 and the Wahba
solution ([Qu 2024] Fig. 1-2). The three methods see the same errors.

``table1``: the turntable setting (gyro 1 deg/h, accelerometer 0.1 mg,
pitch 80 deg, the 12 attitudes of [Qu 2024] Table 1). The paper gives one
measured alignment per attitude; we give the spread of the yaw error per
attitude and, comparable with the paper's "max yaw error 20 deg vs 7.5
deg", the distribution of the maximum over the 12 attitudes of one trial.
The latitude of the turntable is not stated; we take Mianyang (31.5 N),
where the authors' institute is.
"""

import numpy as np

from ...constants import G0_MPS2, OMEGA_E_RAD_PER_S
from ...earth import normal_gravity_mps2
from ...fileio import write_csv
from ...ins.alignment import align
from ...plots import pyplot, save_png
from ...rotations import euler_to_dcm
from ..studies import map_chunks

__all__ = ["attitude_errors", "sweep", "fig2", "table1"]

#: Method labels in the JSON documents, in the order of the sweep.
LABELS = {"1": "alg1", "2": "alg2", "wahba": "wahba"}

DEG_PER_H = np.radians(1.0) / 3600.0

# [Qu 2024] section 2 (Fig. 1-2) and section 3 (Table 1), as published.
PAPER_FIG2 = {
    "max_yaw_err_at_80_deg": {"alg1": 11.0, "alg2": 2.2},
    "pitch_err_below_0p6_deg_up_to_pitch_deg": 64.6,
    "roll_err_below_0p6_deg_up_to_pitch_deg": 68.0,
    "pitch_and_roll_err_below_1p6_deg_up_to_pitch_deg": 80.5,
    "max_roll_err_at_89p5_deg": 21.8,
    "max_roll_err_at_90_deg": 330.0,
    "max_pitch_err_at_90_deg": 5.1,
    "yaw_ambiguous_above_pitch_deg": {"alg1": 88.4, "alg2": 89.0},
}
PAPER_TABLE1 = [
    # designed [yaw, pitch, roll], alignment by eq. 12 (alg. 1), by eq. 15 (alg. 2), deg
    ([45, 80, 45], [66.4, 80.0, 45.0], [39.6, 80.0, 45.0]),
    ([45, 80, 90], [65.3, 80.0, 90.1], [40.0, 80.0, 90.1]),
    ([45, 80, 135], [60.5, 80.0, 135.2], [44.0, 80.0, 135.2]),
    ([45, 80, 180], [60.2, 80.0, 180.2], [47.5, 80.0, 180.2]),
    ([45, 80, 225], [57.2, 80.0, 225.1], [51.7, 80.0, 225.1]),
    ([45, 80, 270], [60.0, 80.0, 269.0], [51.5, 80.0, 269.0]),
    ([45, 80, 315], [58.5, 80.0, 314.9], [46.4, 80.0, 314.9]),
    ([90, 80, 315], [108.0, 80.0, 135.2], [85.2, 80.0, 135.2]),
    ([90, 80, -135], [103.3, 80.0, -134.9], [92.6, 80.0, -134.9]),
    ([90, 80, -45], [109.8, 80.0, -45.1], [97.5, 80.0, 45.0]),
    ([90, 80, 45], [115.0, 80.0, 45.0], [89.2, 80.0, 45.0]),
    ([90, 80, 135], [107.7, 80.0, 135.2], [89.1, 80.0, 135.2]),
]
PAPER_TABLE1_MAX_YAW_ERR_DEG = {"alg1": 20.0, "alg2": 7.5}


def _wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def attitude_errors(pitch_deg, roll_deg, heading_deg, n_shots, *, accel_sigma_mps2, gyro_sigma_rad_per_s,
                    lat_rad, rng, same_errors_for_all_attitudes=False, methods=("1", "2", "wahba")):
    """Alignment errors of random sensor errors at given attitudes.

    Parameters
    ----------
    pitch_deg, roll_deg, heading_deg : array_like, broadcastable, shape (...)
        True attitudes (heading clockwise from North, as [Qu 2024]'s yaw).
    n_shots : int
        Random error draws per attitude, common to all methods.
    accel_sigma_mps2, gyro_sigma_rad_per_s : float
        1-sigma error of each axis of the mean specific force and rate.
    lat_rad : float
    rng : numpy.random.Generator
    same_errors_for_all_attitudes : bool
        Draw one error vector per shot, fixed in the body frame and shared by
        all attitudes (one IMU rotated on a turntable); otherwise independent
        draws per attitude ([Qu 2024]'s simulation).
    methods : sequence of str

    Returns
    -------
    dict
        ``{method: (d_pitch_deg, d_roll_deg, d_heading_deg)}``, each of shape
        ``(..., n_shots)``, wrapped to [-180, 180).
    """
    p, r, h = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (pitch_deg, roll_deg, heading_deg)))
    C_n_b = euler_to_dcm(np.radians(p), np.radians(r), -np.radians(h))
    g = normal_gravity_mps2(lat_rad, 0.0)
    w_n = OMEGA_E_RAD_PER_S * np.array([0.0, np.cos(lat_rad), np.sin(lat_rad)])
    f_b = np.einsum("...ji,j->...i", C_n_b, [0.0, 0.0, g])
    w_b = np.einsum("...ji,j->...i", C_n_b, w_n)
    shape = (n_shots, 3) if same_errors_for_all_attitudes else p.shape + (n_shots, 3)
    f_meas = f_b[..., None, :] + rng.normal(0.0, accel_sigma_mps2, shape)
    w_meas = w_b[..., None, :] + rng.normal(0.0, gyro_sigma_rad_per_s, shape)
    out = {}
    for m in methods:
        pe, re, ye = align(f_meas, w_meas, lat_rad, method=m, g_mps2=g, accel_sigma_mps2=accel_sigma_mps2,
                           gyro_sigma_rad_per_s=gyro_sigma_rad_per_s)
        out[m] = (_wrap_deg(np.degrees(pe) - p[..., None]), _wrap_deg(np.degrees(re) - r[..., None]),
                  _wrap_deg(-np.degrees(ye) - h[..., None]))
    return out


def _sweep_chunk(chunk, rng):
    """Maximum absolute errors over one pitch's attitude grid (a Dask task)."""
    pitch_deg, yaw_deg, roll_deg, n_shots, accel_sigma, gyro_sigma, lat_rad = chunk
    h, r = np.meshgrid(yaw_deg, roll_deg, indexing="ij")
    errs = attitude_errors(pitch_deg, r, h, n_shots, accel_sigma_mps2=accel_sigma,
                           gyro_sigma_rad_per_s=gyro_sigma, lat_rad=lat_rad, rng=rng)
    return {m: [float(np.abs(e).max()) for e in errs[m]] for m in errs}


def sweep(pitch_deg, yaw_deg, roll_deg, *, n_shots=100, accel_sigma_mps2=1e-3 * G0_MPS2,
          gyro_sigma_rad_per_s=0.1 * DEG_PER_H, lat_rad=np.radians(30.0), seed=0, scheduler=None):
    """Maximum pitch/roll/yaw errors per pitch over a yaw x roll grid (one chunk per pitch).

    Parameters
    ----------
    pitch_deg, yaw_deg, roll_deg : array_like, 1-D
        Grid; yaw is [Qu 2024]'s azimuth (clockwise from North).
    n_shots : int
    accel_sigma_mps2, gyro_sigma_rad_per_s : float
    lat_rad : float
    seed : int
    scheduler : see :func:`leosop.apps.studies.map_chunks`

    Returns
    -------
    dict
        ``{"max_pitch_err_deg", "max_roll_err_deg", "max_yaw_err_deg"}``,
        each ``{label: list over pitch}``.
    """
    yaw = np.asarray(yaw_deg, dtype=float)
    roll = np.asarray(roll_deg, dtype=float)
    chunks = [(float(p), yaw, roll, int(n_shots), float(accel_sigma_mps2), float(gyro_sigma_rad_per_s),
               float(lat_rad)) for p in np.atleast_1d(pitch_deg)]
    results = map_chunks(_sweep_chunk, chunks, seed=seed, scheduler=scheduler, desc="alignment sweep")
    keys = ("max_pitch_err_deg", "max_roll_err_deg", "max_yaw_err_deg")
    return {k: {LABELS[m]: [res[m][i] for res in results] for m in results[0]} for i, k in enumerate(keys)}


def _grid(full):
    if full:
        pitch = np.concatenate([np.arange(0.0, 90.0, 1.0), [88.4, 89.0, 89.5, 89.9, 90.0]])
        return np.unique(pitch), np.arange(-180.0, 180.0, 5.0), np.arange(0.0, 360.0, 5.0)
    pitch = [0, 15, 30, 45, 60, 64.6, 70, 75, 80, 85, 88, 89, 89.5, 90]
    return np.array(pitch, dtype=float), np.arange(-180.0, 180.0, 15.0), np.arange(0.0, 360.0, 15.0)


#: Line style per method: alg1 and alg2 give the same pitch and roll, so alg1 is drawn thick underneath.
_STYLE = {"alg1": dict(color="C0", lw=3.0, alpha=0.5, marker="o", ms=7), "alg2": dict(color="C1", lw=1.2, marker="s"),
          "wahba": dict(color="C2", lw=1.2, ls="--", marker="^")}


def _settings_text(settings):
    return (f"{settings['n_shots']} shots per attitude, accel {settings['accel_sigma_mg']:g} mg, gyro "
            f"{settings['gyro_sigma_deg_per_h']:g} deg/h (1 sigma), lat {settings['lat_deg']:g} deg, "
            f"seed {settings['seed']}")


def _plot_fig2(path_pr, path_yaw, doc):
    """Pitch and roll errors (two panels) and yaw error against pitch, the paper's values marked."""
    plt = pyplot()
    p = doc["pitch_deg"]
    paper = doc["paper"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharey=True, constrained_layout=True)
    for ax, angle, limit in zip(axes, ("pitch", "roll"), (paper["pitch_err_below_0p6_deg_up_to_pitch_deg"],
                                                          paper["roll_err_below_0p6_deg_up_to_pitch_deg"])):
        for label, y in doc[f"max_{angle}_err_deg"].items():
            ax.semilogy(p, y, label=label, **_STYLE.get(label, {}))
        ax.plot([limit], [0.6], "k*", ms=11, label=f"[Qu 2024]: < 0.6 deg up to {limit:g} deg")
        ax.set(xlabel="pitch [deg]", title=f"{angle} error")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("largest error over the attitudes [deg]")
    fig.suptitle(f"[Qu 2024] Fig. 1, coarse alignment: {_settings_text(doc['settings'])}", fontsize=9)
    save_png(fig, path_pr)
    fig, ax = plt.subplots(figsize=(7, 4.4), constrained_layout=True)
    for label, y in doc["max_yaw_err_deg"].items():
        ax.semilogy(p, y, label=label, **_STYLE.get(label, {}))
    for label, y in paper["max_yaw_err_at_80_deg"].items():
        ax.plot([80], [y], "*", color=_STYLE[label]["color"], mec="k", ms=13,
                label=f"[Qu 2024] {label} at 80 deg: {y:g} deg")
    ax.set(xlabel="pitch [deg]", ylabel="largest yaw error over the attitudes [deg]")
    ax.set_title(f"[Qu 2024] Fig. 2, coarse alignment: yaw error\n{_settings_text(doc['settings'])}", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save_png(fig, path_yaw)


def fig2(*, seed=0, scheduler=None, full=False, out_dir=None):
    """[Qu 2024] Fig. 1-2: maximum alignment errors versus pitch (JSON document).

    ``out_dir``: ``align_fig2.csv`` (one row per pitch) and the two figures
    (the JSON document is written by :func:`leosop.apps.repro.run_target`).

    The default grid (14 pitches, yaw and roll every 15 deg, 100 shots) runs
    in seconds; ``full`` uses every degree of pitch and 5 deg yaw/roll steps.
    """
    pitch, yaw, roll = _grid(full)
    doc = {"pitch_deg": pitch.tolist()}
    doc.update(sweep(pitch, yaw, roll, seed=seed, scheduler=scheduler))
    doc["paper"] = PAPER_FIG2
    i80 = doc["pitch_deg"].index(80.0)
    doc["at_80_deg"] = {k: {m: v[i80] for m, v in doc[k].items()}
                        for k in ("max_pitch_err_deg", "max_roll_err_deg", "max_yaw_err_deg")}
    doc["settings"] = {"n_shots": 100, "accel_sigma_mg": 1.0, "gyro_sigma_deg_per_h": 0.1, "lat_deg": 30.0,
                       "yaw_step_deg": float(yaw[1] - yaw[0]), "roll_step_deg": float(roll[1] - roll[0]),
                       "seed": seed}
    if out_dir is not None:
        from pathlib import Path

        out = Path(out_dir)
        labels = list(doc["max_yaw_err_deg"])
        header = ["pitch_deg"] + [f"max_{a}_err_deg_{m}" for a in ("pitch", "roll", "yaw") for m in labels]
        rows = [[p] + [doc[f"max_{a}_err_deg"][m][i] for a in ("pitch", "roll", "yaw") for m in labels]
                for i, p in enumerate(doc["pitch_deg"])]
        write_csv(out / "align_fig2.csv", header, rows)
        _plot_fig2(out / "align_pitch_roll_error.png", out / "align_yaw_error.png", doc)
    return doc


def table1(*, seed=0, full=False, out_dir=None):
    """[Qu 2024] Table 1 (turntable, pitch 80 deg) by Monte Carlo (JSON document).

    ``n_shots`` trials (1000, or 10000 with ``full``) of the 12 attitudes
    with gyro 1 deg/h and accelerometer 0.1 mg errors (1 sigma per axis),
    each trial one IMU whose errors are fixed in the body frame while the
    turntable visits the 12 attitudes. ``out_dir``: ``align_table1.csv``, one
    row per attitude (the JSON document is written by :func:`leosop.apps.repro.run_target`).
    """
    n_shots = 10000 if full else 1000
    lat_rad = np.radians(31.5)
    designed = np.array([row[0] for row in PAPER_TABLE1], dtype=float)
    rng = np.random.default_rng(seed)
    errs = attitude_errors(designed[:, 1], designed[:, 2], designed[:, 0], n_shots,
                           accel_sigma_mps2=1e-4 * G0_MPS2, gyro_sigma_rad_per_s=DEG_PER_H,
                           lat_rad=lat_rad, rng=rng, same_errors_for_all_attitudes=True)
    rows = []
    for i, (des, a1, a2) in enumerate(PAPER_TABLE1):
        row = {"designed_deg": des, "yaw_err_rms_deg": {}, "yaw_err_max_deg": {}, "pitch_err_rms_deg": {},
               "roll_err_rms_deg": {}}
        for m, (pe, re, ye) in errs.items():
            row["yaw_err_rms_deg"][LABELS[m]] = float(np.sqrt(np.mean(ye[i] ** 2)))
            row["yaw_err_max_deg"][LABELS[m]] = float(np.abs(ye[i]).max())
            row["pitch_err_rms_deg"][LABELS[m]] = float(np.sqrt(np.mean(pe[i] ** 2)))
            row["roll_err_rms_deg"][LABELS[m]] = float(np.sqrt(np.mean(re[i] ** 2)))
        row["paper"] = {"alg1_deg": a1, "alg2_deg": a2,
                        "alg1_yaw_err_deg": float(_wrap_deg(a1[0] - des[0])),
                        "alg2_yaw_err_deg": float(_wrap_deg(a2[0] - des[0]))}
        rows.append(row)
    # The paper's maximum is over the 12 attitudes of one trial each.
    trial_max = {LABELS[m]: np.abs(ye).max(axis=0) for m, (_, _, ye) in errs.items()}
    doc = {
        "rows": rows,
        "max_over_attitudes_yaw_err_deg": {
            m: {"median": float(np.median(v)), "p10": float(np.percentile(v, 10)),
                "p90": float(np.percentile(v, 90))} for m, v in trial_max.items()},
        "paper": {"max_yaw_err_deg": PAPER_TABLE1_MAX_YAW_ERR_DEG,
                  "max_abs_yaw_err_from_rows_deg": {
                      "alg1": max(abs(r["paper"]["alg1_yaw_err_deg"]) for r in rows),
                      "alg2": max(abs(r["paper"]["alg2_yaw_err_deg"]) for r in rows)}},
        "settings": {"n_shots": n_shots, "accel_sigma_mg": 0.1, "gyro_sigma_deg_per_h": 1.0,
                     "lat_deg": 31.5, "seed": seed},
    }
    if out_dir is not None:
        from pathlib import Path

        out = Path(out_dir)
        labels = list(LABELS.values())
        header = (["yaw_deg", "pitch_deg", "roll_deg"] + [f"yaw_err_rms_deg_{m}" for m in labels]
                  + ["paper_yaw_err_deg_alg1", "paper_yaw_err_deg_alg2"])
        write_csv(out / "align_table1.csv", header,
                  [r["designed_deg"] + [r["yaw_err_rms_deg"][m] for m in labels]
                   + [r["paper"]["alg1_yaw_err_deg"], r["paper"]["alg2_yaw_err_deg"]] for r in rows])
    return doc
