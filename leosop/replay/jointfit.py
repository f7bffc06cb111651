"""Stage 2 of the identification: joint least squares on one tentative assignment.

Position, receiver offset and drift, a frequency offset and a time offset
per satellite (with priors; the time offset is one of the satellite's
inertial orbit, its element set's along-track error, see
:mod:`~leosop.replay.ephemeris`), and optionally a constant receiver velocity;
tracks that do not fit are dropped one by one.
"""

import numpy as np

from ..frames import C_e_n, ecef_to_geodetic
from .ephemeris import SPEED_SV_MPS, doppler_model

__all__ = ["solve"]


def _stack(search, track_ids):
    rows = [(k, search.tracks[k].sample) for k in track_ids]
    t = np.concatenate([search.tracks[k].t_s[i] for k, i in rows])
    f = np.concatenate([search.tracks[k].doppler_hz[i] for k, i in rows])
    sig = np.concatenate([search.tracks[k].sigma_hz[i] for k, i in rows])
    which = np.concatenate([np.full(len(i), j) for j, (_, i) in enumerate(rows)])
    return t, f, np.sqrt(sig**2 + search.o["model_sigma_hz"] ** 2), which

def solve(search, pos0, assign, clock0, prior_sigma_m):
    """Position, clock and per-satellite offsets on one assignment.

    Returns
    -------
    dict with pos, cov (3, 3), clock, drift (the receiver's common offset [Hz] at the search's
    centre time and its drift [Hz/s]) and their sigmas clock_sigma, drift_sigma, vel,
    nrms_used per used track, used tracks, chi2.
    """
    used = [k for k in range(len(search.tracks)) if assign[k] >= 0]
    lat0, lon0, _ = ecef_to_geodetic(pos0)
    C = C_e_n(lat0, lon0)
    up = C[:, 2]
    while len(used) >= 1:
        sol = _gauss_newton(search, pos0, assign, used, clock0, prior_sigma_m, C, up)
        if sol is None:
            return None
        worst = int(np.argmax(sol["nrms_used"]))
        if sol["nrms_used"][worst] <= search.o["track_gate"] or len(used) <= 2:
            return sol
        used = used[:worst] + used[worst + 1:]
    return None

def _gauss_newton(search, pos0, assign, used, clock0, prior_sigma_m, C, up):
    o = search.o
    t, f, sig, which = _stack(search, used)
    sats = np.array([assign[k] for k in used])
    m = len(used)
    sat = sats[which]
    sig_c = o["sat_offset_sigma_hz"]
    sig_tau = o["along_track_sigma_m"] / SPEED_SV_MPS
    n_vel = 3 if search.moving else 0
    x = np.zeros(5 + 2 * m + n_vel)  # dpos(3), clock, drift, c_j, tau_j[, vel(3)]
    x[3] = clock0
    dt = t - search.t_c
    for _ in range(10):
        vel_rx = x[5 + 2 * m:] if n_vel else np.zeros(3)
        pos = pos0 + x[:3] + dt[:, None] * vel_rx
        tau = x[5 + m:5 + 2 * m][which]
        p, v = search.eph.state_received(sat, t, pos, tau)
        dop, grad, u = doppler_model(p, v - vel_rx, pos, search.k, los=True)
        rate = search.eph.doppler_shift_rate(sat, t, tau, pos, search.k)
        model = dop + x[3] + x[4] * dt + x[5:5 + m][which]
        res = (f - model) / sig
        J = np.zeros((len(t), len(x)))
        J[:, :3] = grad
        J[:, 3] = 1
        J[:, 4] = dt
        J[np.arange(len(t)), 5 + which] = 1
        J[np.arange(len(t)), 5 + m + which] = rate
        if n_vel:
            J[:, 5 + 2 * m:] = search.k * u + grad * dt[:, None]
        J /= sig[:, None]
        # Priors: satellite offsets and time offsets, horizontal position, height[, velocity].
        axes = [(0, C[:, 0], prior_sigma_m), (0, C[:, 1], prior_sigma_m), (0, up, o["alt_sigma_m"])]
        if n_vel:
            axes += [(5 + 2 * m, C[:, 0], o["rx_speed_sigma_mps"]), (5 + 2 * m, C[:, 1], o["rx_speed_sigma_mps"]),
                     (5 + 2 * m, up, o["rx_climb_sigma_mps"])]
        P = np.zeros((2 * m + len(axes), len(x)))
        pr = np.zeros(len(P))
        P[np.arange(m), 5 + np.arange(m)] = 1 / sig_c
        pr[:m] = -x[5:5 + m] / sig_c
        P[m + np.arange(m), 5 + m + np.arange(m)] = 1 / sig_tau
        pr[m:2 * m] = -x[5 + m:5 + 2 * m] / sig_tau
        for r, (i0, axis, s) in enumerate(axes):
            P[2 * m + r, i0:i0 + 3] = axis / s
            pr[2 * m + r] = -(axis @ x[i0:i0 + 3]) / s
        A = np.vstack([J, P])
        y = np.concatenate([res, pr])
        dx = np.linalg.solve(A.T @ A, A.T @ y)
        x += dx
        if np.linalg.norm(dx[:3]) < 0.05 and abs(dx[3]) < 0.01:
            break
    if not np.all(np.isfinite(x)):
        return None
    cov = np.linalg.inv(A.T @ A)
    nrms = np.sqrt(np.bincount(which, res**2, m) / np.bincount(which, minlength=m))
    return {"pos": pos0 + x[:3], "cov": cov[:3, :3], "clock": x[3], "drift": x[4], "used": used,
            "clock_sigma": float(np.sqrt(cov[3, 3])), "drift_sigma": float(np.sqrt(cov[4, 4])),
            "vel": x[5 + 2 * m:] if n_vel else np.zeros(3), "nrms_used": nrms, "chi2": float(res @ res)}

# Identification ------------------------------------------------------
