"""[Chu 2009] reproduced: Table 3 of the short-time 9-state error model, and its check
against the full strapdown.

``table3``: 150 s of [Chu 2009]'s rolling flight as its Table 2 defines it
(body rate 180 deg/s about the forward axis, specific force of 1 g that
stays vertical, no Earth rotation), flown East so that the paper's
navigation X axis is the roll axis; gyro drift and accelerometer bias on the
roll axis, where rolling does not modulate them (the paper's rows show no
coupling between the gyro and the velocity error, which errors on the other
axes would cause; see ``all_axes`` in each row). Attitude, velocity and
position errors along X at 150 s from :func:`leosop.ins.error_model.model9`
propagated by :func:`leosop.ins.error_model.propagate`.

``validate``: the same model against the difference of two strapdown runs
(:mod:`leosop.ins.strapdown`) on the Earth-referenced rolling flight of
:func:`leosop.ins.trajectory.rolling_flight`, with the IMU errors of seed
001 Table 1; the relative error ``(model - strapdown) / strapdown`` per axis
at the end ([Chu 2009] eq. 22), next to the 15-state model's.
"""

import numpy as np

from ...constants import G0_MPS2
from ...earth import radii_m
from ...rotations import euler_to_dcm
from ...ins import error_model as em
from ...ins import strapdown, trajectory

__all__ = ["table3", "validate"]

DEG_PER_H = np.radians(1.0) / 3600.0
MG = 1e-3 * G0_MPS2

# [Chu 2009] Table 3: gyro [deg/h], accelerometer [mg] -> attitude [deg],
# velocity [m/s], position [m] errors after 150 s. The last row prints its
# position as 1032.481257; a digit is lost (a t^2 / 2 gives 11032.48).
PAPER_TABLE3 = [
    (1, 10, -0.041667, 14.709975, 1103.248125),
    (10, 10, -0.416670, 14.709975, 1103.248132),
    (100, 10, -4.166700, 14.709976, 1103.248198),
    (10, 1, -0.416670, 1.4709976, 110.324819),
    (10, 10, -0.416670, 14.7099751, 1103.248132),
    (10, 100, -0.416670, 147.09975011, 11032.481257),
]

# [Chu 2009] Table 1: IMU errors of the validation run, on the paper's body
# axes X forward, Y up, Z right -> ours (Right, Forward, Up).
GYRO_DRIFT_FUR_DEG_PER_H = np.array([2.5, 9.0, 6.6])
ACCEL_BIAS_FUR_MG = np.array([-10.0915, -4.9469, 0.78594])
_RFU_FROM_FUR = [2, 0, 1]

DURATION_S = 150.0
ROLL_RATE_RAD_PER_S = np.radians(180.0)


def _chu2009_rolling(rate_hz):
    """Attitude at step midpoints and ENU specific force of [Chu 2009] Table 2, flown East."""
    dt = 1.0 / rate_hz
    t_mid = (np.arange(int(round(DURATION_S * rate_hz))) + 0.5) * dt
    C_n_b = euler_to_dcm(0.0, ROLL_RATE_RAD_PER_S * t_mid, np.radians(-90.0))
    f_n = np.broadcast_to([0.0, 0.0, G0_MPS2], t_mid.shape + (3,))
    return C_n_b, f_n, dt


def _propagate9(C_n_b, f_n, dt, gyro_drift_b, accel_bias_b):
    F, G = em.model9(C_n_b, f_n)
    return em.propagate(F, G, np.concatenate([gyro_drift_b, accel_bias_b]), dt, np.zeros(9))


def table3(*, rate_hz=100.0):
    """[Chu 2009] Table 3 (JSON document ``{"rows": [...]}``).

    ``rate_hz`` is the step rate of the propagation (the roll turns 0.18 deg
    per step at 100 Hz; the roll-axis rows are exact at any step).
    """
    C_n_b, f_n, dt = _chu2009_rolling(rate_hz)
    forward = np.array([0.0, 1.0, 0.0])
    rows = []
    for gyro, accel, att, vel, pos in PAPER_TABLE3:
        x = _propagate9(C_n_b, f_n, dt, gyro * DEG_PER_H * forward, accel * MG * forward)[-1]
        x_all = _propagate9(C_n_b, f_n, dt, gyro * DEG_PER_H * np.ones(3), accel * MG * np.ones(3))[-1]
        rows.append({
            "gyro_deg_per_h": gyro, "accel_mg": accel,
            "att_err_deg": float(np.degrees(x[0])), "vel_err_mps": float(x[3]), "pos_err_m": float(x[6]),
            "paper": {"att_err_deg": att, "vel_err_mps": vel, "pos_err_m": pos},
            "all_axes": {"att_err_deg": float(np.degrees(x_all[0])), "vel_err_mps": float(x_all[3]),
                         "pos_err_m": float(x_all[6])},
        })
    return {"rows": rows, "settings": {"duration_s": DURATION_S, "roll_rate_deg_s": 180.0, "step_hz": rate_hz,
                                       "errors_on": "roll (forward) axis; all_axes: every body axis"}}


def _nav_errors_enu(nav, truth):
    """Attitude (rad), velocity (m/s) and position (m, ENU) errors, computed minus true."""
    D = nav.C_n_b @ np.swapaxes(truth.C_n_b, -1, -2)  # = I - [phi x]
    phi = 0.5 * np.stack([D[..., 1, 2] - D[..., 2, 1], D[..., 2, 0] - D[..., 0, 2], D[..., 0, 1] - D[..., 1, 0]],
                         axis=-1)
    R_M, R_N = radii_m(truth.lat_rad)
    dpos = np.stack([(nav.lon_rad - truth.lon_rad) * (R_N + truth.alt_m) * np.cos(truth.lat_rad),
                     (nav.lat_rad - truth.lat_rad) * (R_M + truth.alt_m), nav.alt_m - truth.alt_m], axis=-1)
    return phi, nav.vel_enu_mps - truth.vel_enu_mps, dpos


def validate(*, rate_hz=100.0, out_dir=None):
    """Error models against the strapdown over 150 s of the rolling flight.

    Parameters
    ----------
    rate_hz : float
        IMU rate of the flight.
    out_dir : pathlib.Path, optional
        Where to write ``errmodel_validate.csv`` (one row per quantity and
        ENU axis: strapdown, 9- and 15-state model at the end, relative
        errors) and ``errmodel_validate.png`` (velocity and position errors
        against time, as [Chu 2009]'s figures compare them).

    Returns
    -------
    dict
        Strapdown and model errors at 150 s per ENU axis and the relative
        errors ``(model - strapdown) / strapdown`` for velocity and position.
    """
    traj = trajectory.rolling_flight(duration_s=DURATION_S, rate_hz=rate_hz)
    dt = traj.dt_s
    eps_b = GYRO_DRIFT_FUR_DEG_PER_H[_RFU_FROM_FUR] * DEG_PER_H
    nabla_b = ACCEL_BIAS_FUR_MG[_RFU_FROM_FUR] * MG
    state0 = strapdown.NavState.from_dcm(traj.lat_rad[0], traj.lon_rad[0], traj.alt_m[0], traj.vel_enu_mps[0],
                                         traj.C_n_b[0])
    ideal = strapdown.integrate(state0, traj.dtheta_b_rad, traj.dvel_b_mps, dt)
    bad = strapdown.integrate(state0, traj.dtheta_b_rad + eps_b * dt, traj.dvel_b_mps + nabla_b * dt, dt)
    # Compare the two runs (not the truth) so that the algorithm's own small
    # errors cancel; both are sampled every update (2 dt).
    phi_s, dv_s, dpos_s = _nav_errors_enu(bad, ideal)

    # Models along the ideal solution, one step per IMU sample.
    idx = np.arange(traj.dvel_b_mps.shape[0])
    C_mid = 0.5 * (traj.C_n_b[idx] + traj.C_n_b[idx + 1])
    f_n = np.einsum("kij,kj->ki", C_mid, traj.dvel_b_mps / dt)
    x9_t = _propagate9(C_mid, f_n, dt, eps_b, nabla_b)
    x9 = x9_t[-1]
    lat = 0.5 * (traj.lat_rad[idx] + traj.lat_rad[idx + 1])
    alt = 0.5 * (traj.alt_m[idx] + traj.alt_m[idx + 1])
    vel = 0.5 * (traj.vel_enu_mps[idx] + traj.vel_enu_mps[idx + 1])
    F15, G15 = em.model15(C_mid, f_n, vel, lat, alt)
    # The sensor errors enter the navigation states as G's noise does.
    x15_t = em.propagate(F15[:, :9, :9], G15[:, :9, :], np.concatenate([eps_b, nabla_b]), dt, np.zeros(9))
    R_M, R_N = radii_m(traj.lat_rad)
    h = traj.alt_m
    # 15-state position errors (dlat, dlon, dalt) as ENU metres at every sample.
    dpos15_t = np.stack([x15_t[:, 7] * (R_N + h) * np.cos(traj.lat_rad), x15_t[:, 6] * (R_M + h), x15_t[:, 8]], -1)
    x15, dpos15 = x15_t[-1], dpos15_t[-1]

    def rel(model, ref):
        return ((model - ref) / ref).tolist()

    doc = {
        "duration_s": float(bad.t_s[-1]),
        "strapdown": {"att_err_deg": np.degrees(phi_s[-1]).tolist(), "vel_err_mps": dv_s[-1].tolist(),
                      "pos_err_m": dpos_s[-1].tolist()},
        "model9": {"att_err_deg": np.degrees(x9[0:3]).tolist(), "vel_err_mps": x9[3:6].tolist(),
                   "pos_err_m": x9[6:9].tolist()},
        "model15": {"att_err_deg": np.degrees(x15[0:3]).tolist(), "vel_err_mps": x15[3:6].tolist(),
                    "pos_err_m": dpos15.tolist()},
        "relative_error": {
            "model9": {"vel": rel(x9[3:6], dv_s[-1]), "pos": rel(x9[6:9], dpos_s[-1])},
            "model15": {"vel": rel(x15[3:6], dv_s[-1]), "pos": rel(dpos15, dpos_s[-1])},
        },
        "paper_relative_error_max": {"x": 0.20, "y": 0.04, "z": 0.04},
    }
    if out_dir is not None:
        _write_validation(out_dir, doc, bad.t_s, np.concatenate([dv_s, dpos_s], -1), np.arange(idx.size + 1) * dt,
                          x9_t[:, 3:9], np.concatenate([x15_t[:, 3:6], dpos15_t], -1))
    return doc


def _write_validation(out_dir, doc, t_strapdown_s, err_strapdown, t_model_s, err9, err15):
    """``errmodel_validate.csv`` and ``.png``; errors ``[dv_enu, dpos_enu]`` (n, 6), m/s and m, per time (n,)."""
    from ...fileio import write_csv
    from ...plots import pyplot, save_png

    rows = []
    quantities = (("attitude_deg", "att_err_deg"), ("velocity_mps", "vel_err_mps"), ("position_m", "pos_err_m"))
    for quantity, key in quantities:
        rel = {"velocity_mps": "vel", "position_m": "pos"}.get(quantity)
        for i, axis in enumerate("ENU"):
            rows.append([quantity, axis] + [f"{doc[src][key][i]:.9g}" for src in ("strapdown", "model9", "model15")]
                        + ([f"{doc['relative_error'][m][rel][i]:.6g}" for m in ("model9", "model15")] if rel
                           else ["", ""]))
    write_csv(out_dir / "errmodel_validate.csv", ["quantity", "axis", "strapdown", "model9", "model15",
                                                  "relative_error_model9", "relative_error_model15"], rows)
    plt = pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(12, 6), sharex=True, constrained_layout=True)
    for row, (label, unit) in enumerate((("velocity error", "m/s"), ("position error", "m"))):
        for i, axis in enumerate("ENU"):
            ax = axes[row, i]
            j = 3 * row + i
            ax.plot(t_strapdown_s, err_strapdown[:, j], color="k", lw=2.5, alpha=0.5, label="strapdown difference")
            ax.plot(t_model_s, err9[:, j], color="C0", lw=1.2, ls="--", label="9-state model")
            ax.plot(t_model_s, err15[:, j], color="C1", lw=1.2, ls=":", label="15-state model")
            ax.set_title(f"{label}, {axis}", fontsize=9)
            ax.set_ylabel(f"[{unit}]")
            ax.grid(True, alpha=0.3)
            if row == 1:
                ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("[Chu 2009] sec. 3: short-time error models against two strapdown runs (rolling flight, "
                 "IMU errors of its Table 1)", fontsize=9)
    save_png(fig, out_dir / "errmodel_validate.png")
