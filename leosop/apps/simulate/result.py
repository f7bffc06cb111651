"""What a simulated flight produced, and its summaries: the ``simulate`` JSON document and solution CSV."""

import dataclasses

import numpy as np

from ... import frames
from ...fusion import common, kalman
from ...timebase import format_utc

__all__ = ["SimulationResult", "aided", "fusion_label", "metrics", "solution_table"]


@dataclasses.dataclass(frozen=True)
class SimulationResult:
    """Everything a run produced, at the fix epochs ``t_s`` (n,), 1 Hz by default.

    Attributes
    ----------
    scenario : leosop.apps.scenarios.Scenario
    level, coupling : str
    correction_period_s, orbit_error_m : float
    seed : int
    times_utc : ndarray of datetime64[ns], (n,)
    t_s : ndarray, (n,)
    truth_pos_ecef_m, truth_vel_enu_mps : ndarray, (n, 3)
    truth_lat_rad, truth_lon_rad : ndarray, (n,)
    ins_pos_ecef_m, ins_vel_enu_mps : ndarray, (n, 3)
        INS alone, from the same erroneous start and IMU.
    fix_pos_ecef_m, fix_vel_enu_mps : ndarray, (n, 3)
        LEO snapshot fixes; NaN where none.
    fix_cov : ndarray, (n, 7, 7)
    fused : leosop.fusion.common.FusionResult
    n_visible : ndarray of int, (n,)
    gdop : ndarray, (n,)
        Eq. 10 along the true flight (one receiver clock per constellation
        seen); NaN below 6 + k satellites of k constellations.
    tle_age_days : float
    runtime_s : float
    n_visible_by_family : ndarray of int, (n, k)
        Tracked satellites of each of the scenario's ``leo.constellations``.
    """

    scenario: object
    level: str
    coupling: str
    correction_period_s: float
    orbit_error_m: float
    seed: int
    times_utc: np.ndarray
    t_s: np.ndarray
    truth_pos_ecef_m: np.ndarray
    truth_vel_enu_mps: np.ndarray
    truth_lat_rad: np.ndarray
    truth_lon_rad: np.ndarray
    ins_pos_ecef_m: np.ndarray
    ins_vel_enu_mps: np.ndarray
    fix_pos_ecef_m: np.ndarray
    fix_vel_enu_mps: np.ndarray
    fix_cov: np.ndarray
    fused: common.FusionResult
    n_visible: np.ndarray
    gdop: np.ndarray
    tle_age_days: float
    runtime_s: float
    n_visible_by_family: np.ndarray = None

    @property
    def fused_label(self):
        """``Starlink/INS`` for a Starlink-only scenario, ``LEO/INS`` for a mix: the fused solution's name."""
        return fusion_label(self.scenario.leo.constellations)

    def errors(self):
        """3D position [m] and velocity [m/s] errors, dict of (n,) arrays per solution."""
        out = {}
        for key, pos, vel in (("ins_only", self.ins_pos_ecef_m, self.ins_vel_enu_mps),
                              ("leo_fix", self.fix_pos_ecef_m, self.fix_vel_enu_mps),
                              ("fused", self.fused.pos_ecef_m, self.fused.vel_enu_mps)):
            out[key] = (np.linalg.norm(pos - self.truth_pos_ecef_m, axis=-1),
                        np.linalg.norm(vel - self.truth_vel_enu_mps, axis=-1))
        return out

    def error_enu(self):
        """Fused errors ``[dv_enu, dpos_enu]`` (n, 6), m/s and m, in the filter's state order."""
        dpos = frames.ecef_to_enu(self.fused.pos_ecef_m - self.truth_pos_ecef_m, self.truth_lat_rad,
                                  self.truth_lon_rad)
        return np.concatenate([self.fused.vel_enu_mps - self.truth_vel_enu_mps, dpos], axis=-1)

    def nees(self):
        """NEES of the fused position and velocity (6 dof), (n,)."""
        return kalman.nees(self.error_enu(), self.fused.pos_vel_cov_enu())

    def nis(self):
        """NIS of the updates and their degrees of freedom, two (n_updates,) arrays."""
        u = self.fused.updated
        return self.fused.nis[u], self.fused.nis_dof[u]


def aided(result):
    """Which output epochs the LEO measurements aided, (n,) bool.

    An epoch is aided when the filter's last update (a fix taken, loose; at
    least one Doppler taken, tight) is less than a correction period old
    (at least one output step): with corrections every 30 s the 29 epochs
    after an update are aided too. The start is never aided.
    """
    t = result.t_s
    step_s = float(t[1] - t[0]) if t.size > 1 else 1.0
    last_s = np.maximum.accumulate(np.where(result.fused.updated, t, -np.inf))
    return t - last_s < max(result.correction_period_s, step_s) - 1e-9


def metrics(result):
    """The ``simulate`` JSON document (DESIGN.md 4.1), every key present.

    Means are over the output epochs (1 Hz by default) after the start;
    ``availability`` is the fraction of those epochs with a fused output
    (the INS alone counts: the filter always has one). Beyond the contract,
    ``fused`` also says how much of it rests on LEO: ``aided_fraction``, the
    fraction of those epochs the LEO measurements aided (:func:`aided`), and
    ``n_updates``, the filter's updates (loose: the fixes it took; tight:
    the epochs whose Doppler it took).
    """
    err = result.errors()
    out = slice(1, None)

    def mean(a):
        a = a[out]
        a = a[np.isfinite(a)]
        return float(a.mean()) if a.size else None

    fused_pos = err["fused"][0][out]
    fix_ok = np.isfinite(err["leo_fix"][0][out])
    gdop = result.gdop[np.isfinite(result.gdop)]
    return {
        "scenario": result.scenario.name,
        "duration_s": float(result.t_s[-1]),
        "ins_only": {"pos_err_mean_m": mean(err["ins_only"][0]), "vel_err_mean_mps": mean(err["ins_only"][1])},
        "leo_fix": {"pos_err_mean_m": mean(err["leo_fix"][0]), "vel_err_mean_mps": mean(err["leo_fix"][1]),
                    "n_fixes": int(fix_ok.sum())},
        "fused": {"pos_err_mean_m": mean(err["fused"][0]), "vel_err_mean_mps": mean(err["fused"][1]),
                  "pos_err_rms_m": float(np.sqrt(np.nanmean(fused_pos**2))) if np.isfinite(fused_pos).any() else None,
                  "availability": float(np.isfinite(fused_pos).mean()),
                  "aided_fraction": float(aided(result)[out].mean()), "n_updates": int(result.fused.updated.sum())},
        "visible": {"min": int(result.n_visible.min()), "max": int(result.n_visible.max())},
        "gdop": {"max": float(gdop.max()) if gdop.size else None},
        "runtime_s": float(result.runtime_s),
    }


def fusion_label(constellations):
    """The fused solution's name from the scenario's constellations: ``Starlink/INS`` or ``LEO/INS``."""
    return "Starlink/INS" if tuple(constellations) == ("starlink",) else "LEO/INS"


def solution_table(result):
    """The solution CSV: header and rows, one per output epoch.

    Columns: time; truth, INS-only, LEO fix and fused position (deg, deg, m)
    and ENU velocity (m/s); the fused 1-sigma position (ENU m) and velocity
    (m/s); visible satellites, GDOP and whether the filter updated.
    """
    header = ["t_s", "time_utc"]
    cols = [result.t_s, format_utc(result.times_utc)]
    for name, pos, vel in (("truth", result.truth_pos_ecef_m, result.truth_vel_enu_mps),
                           ("ins", result.ins_pos_ecef_m, result.ins_vel_enu_mps),
                           ("fix", result.fix_pos_ecef_m, result.fix_vel_enu_mps),
                           ("fused", result.fused.pos_ecef_m, result.fused.vel_enu_mps)):
        lat, lon, alt = frames.ecef_to_geodetic(pos)
        header += [f"{name}_lat_deg", f"{name}_lon_deg", f"{name}_alt_m",
                   f"{name}_ve_mps", f"{name}_vn_mps", f"{name}_vu_mps"]
        cols += [np.degrees(lat), np.degrees(lon), alt, vel[:, 0], vel[:, 1], vel[:, 2]]
    sigma = np.sqrt(np.diagonal(result.fused.pos_vel_cov_enu(), axis1=-2, axis2=-1))
    header += ["sigma_e_m", "sigma_n_m", "sigma_u_m", "sigma_ve_mps", "sigma_vn_mps", "sigma_vu_mps",
               "n_visible", "gdop", "updated"]
    cols += [sigma[:, 3], sigma[:, 4], sigma[:, 5], sigma[:, 0], sigma[:, 1], sigma[:, 2], result.n_visible,
             result.gdop, result.fused.updated.astype(int)]

    def cell(v):
        if isinstance(v, str):
            return v
        v = float(v)
        return "" if not np.isfinite(v) else f"{v:.10g}"

    rows = [[cell(c[k]) for c in cols] for k in range(result.t_s.size)]
    return header, rows

