"""[Liu 2016]'s vehicle test, simulated: float vs ambiguity-fixed tight PPP/INS, first fix, an outage.

The paper's car test (section 4): GPS only, a single dual-frequency receiver
and an IMU, about 9 min of static alignment then driving; statistics of the
last 30 min: 3-D RMS 0.1514 m float, 0.0392 m fixed, first fix after about
10 min. Its IMU is not stated; ours is a fibre-optic unit (:data:`GRADES`
"fog": gyro 0.1 deg/h, 0.01 deg/sqrt(h); accelerometer 100 ug, 20 ug/sqrt(Hz);
true biases drawn per run from the filter's prior), and the alignment is
replaced by initial errors drawn from the filter's prior (0.02 deg level,
0.3 deg heading, 0.05 m/s, 1 m). GNSS: the real GRG orbits and clocks of
2020-06-25 from 06:00 GPST around Esbjerg (:mod:`leosop.gnss.simulate`),
1 Hz, 10 deg mask; vehicle: 15 m/s with a 46.5 deg turn (turn rate ramped
to 3 deg/s over 30 s, back to 0 in 1 s) every 4.5 min; a 60 s
GNSS outage starts 20 min into the run (before the last 30 min of the
statistics, as the paper's run had none).
"""

import dataclasses
from pathlib import Path

import numpy as np

from ...constants import G0_MPS2
from ...datadir import ENV_VAR, data_folder
from ...errors import InputError
from ...fusion.common import FilterSettings, pos_jacobian
from ...gnss import ppp_ins
from ...gnss.products import read_clk, read_sp3
from ...gnss.simulate import SimSettings, simulate
from ...ins import error_model, strapdown
from ...ins.imu import ImuErrors, corrupt
from ...ins.trajectory import Segment, from_segments

__all__ = ["PAPER", "GRADES", "BUDGET_GROUPS", "filter_settings", "scenario", "outage_budget", "statistics",
           "ppp_ins_table", "format_table"]

#: [Liu 2016] table 2 and section 4.2.
PAPER = {"float_rms_3d_m": 0.1514, "fixed_rms_3d_m": 0.0392, "first_fix_s": 600.0}
#: IMU grades (quoted values): the paper does not state its IMU. "fog": a fibre-optic unit at the
#: navigation / tactical boundary (the default); "navigation": a ring-laser unit; "mems-tactical": the
#: class of [Petovello 2004].
GRADES = {"fog": dict(gyro_bias_deg_per_h=0.1, gyro_arw_deg_per_rt_h=0.01, accel_bias_g=1e-4,
                      accel_vrw_g_per_rt_hz=2e-5),
          "navigation": dict(gyro_bias_deg_per_h=0.01, gyro_arw_deg_per_rt_h=0.002, accel_bias_g=2.5e-5,
                             accel_vrw_g_per_rt_hz=5e-6),
          "mems-tactical": dict(gyro_bias_deg_per_h=1.0, gyro_arw_deg_per_rt_h=0.07, accel_bias_g=3e-4,
                                accel_vrw_g_per_rt_hz=5e-5)}


def filter_settings(grade):
    """Filter priors and Q from an IMU grade of :data:`GRADES` (the filter knows the IMU it has)."""
    q = GRADES[grade]
    return FilterSettings(pos_sigma_m=(1.0, 1.0, 1.0), vel_sigma_mps=(0.05, 0.05, 0.05),
                          att_sigma_rad=tuple(np.radians([0.02, 0.02, 0.3])),
                          gyro_bias_sigma_rad_per_s=np.radians(q["gyro_bias_deg_per_h"]) / 3600.0,
                          accel_bias_sigma_mps2=q["accel_bias_g"] * G0_MPS2,
                          gyro_arw_rad_per_rt_s=np.radians(q["gyro_arw_deg_per_rt_h"]) / 60.0,
                          accel_vrw_mps2_per_rt_hz=q["accel_vrw_g_per_rt_hz"] * G0_MPS2, step_s=1.0)


START_GPS_S = 6 * 3600.0
ESBJERG_DEG = (55.4936, 8.4568, 60.0)
OUTAGE_AT_S = 1200.0


#: The real products the simulation is built on, and where they sit under a data folder.
SP3_NAME, CLK_NAME = "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz", "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz"
DAY_SUBDIR = Path("rinex") / "esbc_2020-177"


def _products(data_dir=None):
    """GRG orbits and clocks of 2020-06-25 (GPS) from ``data_dir``, else from ``$LEOSOP_DATA``.

    The folder is either the one holding the two files or a data root with
    them under ``rinex/esbc_2020-177/`` (the project's public data folder).
    They are not shipped with the package (public IGS/CNES products, 4 MB).

    Raises
    ------
    InputError
        Neither names a folder with the two files (both named in the message).
    """
    root = data_folder(data_dir)
    found = None
    if root:
        for d in (Path(root), Path(root) / DAY_SUBDIR):
            if (d / SP3_NAME).is_file() and (d / CLK_NAME).is_file():
                found = d
                break
    if found is None:
        where = f"not in {root} nor {Path(root) / DAY_SUBDIR}" if root else "no folder given"
        raise InputError(f"data_dir / {ENV_VAR}: the GRG products of 2020-06-25 ({SP3_NAME}, {CLK_NAME}) are "
                         f"needed for this simulation; {where}", param="data_dir")
    day = np.datetime64("2020-06-25", "ns")
    return (read_sp3(found / SP3_NAME, systems="G", ref_gps=day),
            read_clk(found / CLK_NAME, systems="G", ref_gps=day))


def _trajectory(duration_s):
    legs = [Segment(30.0, speed_mps=15.0)]
    while sum(s.duration_s for s in legs) < duration_s:
        legs += [Segment(240.0), Segment(30.0, turn_rate_deg_s=3.0), Segment(1.0, turn_rate_deg_s=0.0)]
    return from_segments(*ESBJERG_DEG, 0.0, legs, rate_hz=100.0)


def scenario(seed, *, duration_s=3600.0, outage_at_s=OUTAGE_AT_S, products=None, ar=True, sim=SimSettings(),
             grade="fog", options=ppp_ins.PppInsOptions()):
    """Simulate one run and filter it with :func:`leosop.gnss.ppp_ins.run` (``options`` with ``ar`` replaced).

    Returns
    -------
    truth_ecef_m : ndarray, shape (n, 3)
    result : leosop.gnss.ppp_ins.PppInsResult
    """
    rng = np.random.default_rng(seed)
    settings = filter_settings(grade)
    # The true IMU: biases drawn from the filter's prior (one draw per run), noise as quoted.
    q = GRADES[grade]
    imu = ImuErrors.from_quoted(gyro_bias_deg_per_h=rng.normal(size=3) * q["gyro_bias_deg_per_h"],
                                gyro_arw_deg_per_rt_h=q["gyro_arw_deg_per_rt_h"],
                                accel_bias_g=rng.normal(size=3) * q["accel_bias_g"],
                                accel_vrw_g_per_rt_hz=q["accel_vrw_g_per_rt_hz"])
    orbits, clocks = products or _products()
    traj = _trajectory(duration_s)
    n_imu = int(round(duration_s / traj.dt_s))
    gnss = simulate(traj, START_GPS_S, orbits, clocks, rng, dataclasses.replace(sim, outage_start_s=outage_at_s),
                    step_s=settings.step_s)
    n = int(duration_s / settings.step_s) + 1
    dth, dvl = corrupt(traj.dtheta_b_rad[:n_imu], traj.dvel_b_mps[:n_imu], traj.dt_s, imu, rng)
    # Initial errors drawn from the filter's prior.
    att = rng.normal(size=3) * np.array(settings.att_sigma_rad)
    dv = rng.normal(size=3) * np.array(settings.vel_sigma_mps)
    dpos_enu = rng.normal(size=3) * np.array(settings.pos_sigma_m)
    dpos = np.linalg.solve(pos_jacobian(traj.lat_rad[0], traj.alt_m[0]), dpos_enu)
    true0 = strapdown.NavState.from_dcm(traj.lat_rad[0], traj.lon_rad[0], traj.alt_m[0], traj.vel_enu_mps[0],
                                        traj.C_n_b[0])
    state0 = true0.corrected(-att, -dv, -dpos)
    res = ppp_ins.run(gnss, orbits, clocks, state0, dth, dvl, traj.dt_s, settings, dataclasses.replace(options, ar=ar))
    return gnss.pos_ecef_m[:n], res


#: Groups of the 15 INS error states in :func:`outage_budget` (the car is level: body x, y horizontal).
#: Tilt and horizontal accelerometer bias are anti-correlated after the GNSS aiding (the position sees
#: their sum), so they come together and alone.
BUDGET_GROUPS = {"tilt + accel bias x, y": [0, 1, 12, 13], "  tilt alone": [0, 1], "  accel bias x, y alone": [12, 13],
                 "heading": [2], "velocity": [3, 4, 5], "position": [6, 7, 8], "gyro bias x, y": [9, 10],
                 "gyro bias z": [11], "accel bias z": [14]}


def outage_budget(res, grade, duration_s, k0, k1):
    """Error budget of a GNSS gap of a :func:`scenario` run: what each source adds to the drift.

    The filter's INS-error covariance at epoch ``k0`` (``res.cov_ins``)
    propagated to epoch ``k1`` along the true trajectory in steps of the
    filter's (:func:`leosop.ins.error_model.position_budget`, groups
    :data:`BUDGET_GROUPS`).

    Parameters
    ----------
    res : leosop.gnss.ppp_ins.PppInsResult
    grade : str
        Key of :data:`GRADES` the run used.
    duration_s : float
        The run's duration (its trajectory).
    k0, k1 : int
        First and last epoch of the gap.

    Returns
    -------
    dict of str to ndarray, shape (3,)
        1-sigma ENU position drift [m] at ``k1`` per group, ``"gyro noise"``,
        ``"accel noise"``, ``"total"`` (correlations included) and
        ``"filter sigma"`` (the filter's own, ``res.cov_pos_enu_m2[k1]``).
    """
    settings = filter_settings(grade)
    traj = _trajectory(duration_s)
    per = int(round(settings.step_s / traj.dt_s))
    i0 = np.arange(k0, k1) * per
    # Mean specific force of each step in ENU from the ideal increments.
    f_n = np.stack([np.einsum("kij,kj->i", traj.C_n_b[i:i + per], traj.dvel_b_mps[i:i + per]) for i in i0])
    F, G = error_model.model15(traj.C_n_b[i0], f_n / settings.step_s, traj.vel_enu_mps[i0], traj.lat_rad[i0],
                               traj.alt_m[i0])
    out = error_model.position_budget(F, G, settings.noise_psd, settings.step_s, res.cov_ins[k0], BUDGET_GROUPS)
    J = pos_jacobian(traj.lat_rad[k1 * per], traj.alt_m[k1 * per])
    doc = {k: np.sqrt(np.diag(J @ c @ J.T)) for k, c in out.items()}
    doc["filter sigma"] = np.sqrt(np.diag(res.cov_pos_enu_m2[k1]))
    return doc


def statistics(truth, res, *, last_s=1800.0, outage_at_s=OUTAGE_AT_S, outage_s=60.0):
    """The paper's figures and the outage figures of one run."""
    t = res.t_s - res.t_s[0]
    err_f = np.linalg.norm(res.pos_float_ecef_m - truth, axis=1)
    err_x = np.linalg.norm(res.pos_fixed_ecef_m - truth, axis=1)
    last = t >= t[-1] - last_s
    fixed = np.isfinite(err_x)
    # The fixed solution where available, else the float one (the paper outputs the float when not fixed).
    err_out = np.where(fixed, err_x, err_f)
    doc = {"float_rms_3d_m": float(np.sqrt(np.mean(err_f[last] ** 2))),
           "fixed_rms_3d_m": float(np.sqrt(np.mean(err_out[last] ** 2))),
           "fixed_fraction_last": float(np.mean(fixed[last])),
           "first_fix_s": float(t[np.argmax(fixed)]) if fixed.any() else None}
    if outage_at_s is not None and t[-1] > outage_at_s + outage_s:
        during = (t >= outage_at_s) & (t < outage_at_s + outage_s)
        after = np.flatnonzero((t >= outage_at_s + outage_s) & fixed)
        doc["outage_max_err_m"] = float(err_f[during].max())
        doc["refix_after_outage_s"] = float(t[after[0]] - (outage_at_s + outage_s)) if after.size else None
    return doc


def ppp_ins_table(*, seed=0, full=False, out_dir=None, data_dir=None):
    """``leosop reproduce ppp-ins``: one 60-min run (``full``: three seeds, their mean) beside the paper.

    With ``out_dir``, ``ppp_ins.png``: errors, sigma and fixed ambiguities of the first run. The real
    products come from ``data_dir`` or ``$LEOSOP_DATA`` (:func:`_products`).
    """
    products = _products(data_dir)
    seeds = [seed] if not full else [seed, seed + 1, seed + 2]
    runs = []
    for i, s in enumerate(seeds):
        truth, res = scenario(s, products=products)
        runs.append(statistics(truth, res))
        if i == 0 and out_dir is not None:
            _figure(truth, res, Path(out_dir) / "ppp_ins.png", s)
    ours = {k: (float(np.mean([r[k] for r in runs])) if all(r[k] is not None for r in runs) else None)
            for k in runs[0]}
    return {"paper": PAPER, "ours": ours, "runs": runs,
            "setting": "simulated car, GPS L1/L2 on GRG orbits/clocks 2020-06-25 06:00 GPST, 1 Hz, 60 min, "
                       "fog-grade IMU, 60 s outage at 20 min; statistics over the last 30 min",
            **{k: ours[k] for k in ("float_rms_3d_m", "fixed_rms_3d_m", "first_fix_s")}}


def _figure(truth, res, path, seed):
    from ...plots.ppp import ppp_ins_figure  # figures depend on gnss, not the reverse

    path.parent.mkdir(parents=True, exist_ok=True)
    t = res.t_s - res.t_s[0]
    ppp_ins_figure(t, np.linalg.norm(res.pos_float_ecef_m - truth, axis=1),
                   np.linalg.norm(res.pos_fixed_ecef_m - truth, axis=1),
                   np.sqrt(np.trace(res.cov_pos_enu_m2, axis1=1, axis2=2)), res.n_fixed, res.n_sats, path,
                   title=f"tight PPP/INS, simulated car (seed {seed}), 60 s outage at {OUTAGE_AT_S / 60:g} min")


def format_table(doc):
    rows = [f"{'':24s}{'paper':>10s}{'ours':>10s}"]
    for k in ("float_rms_3d_m", "fixed_rms_3d_m", "first_fix_s"):
        v = doc["ours"][k]
        rows.append(f"{k:24s}{doc['paper'][k]:10.4f}{'-' if v is None else f'{v:.4f}':>10s}")
    for k in ("fixed_fraction_last", "outage_max_err_m", "refix_after_outage_s"):
        v = doc["ours"].get(k)
        rows.append(f"{k:24s}{'':10s}{'-' if v is None else f'{v:.4f}':>10s}")
    return "\n".join(rows)
