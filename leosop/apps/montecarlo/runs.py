"""One study run: a ``simulate`` run reduced to a row of numbers (:data:`METRICS`).

Worker tasks call :func:`run_chunk` on a list of runs; everything in a run is
plain data (a frozen :class:`leosop.apps.scenarios.Scenario`, keyword options, an
element-set path, an integer seed), so chunks pickle to any worker.
"""

import warnings

import numpy as np

from ...orbits.gridmap import GDOP_UNITS
from ..simulate import metrics, run_scenario

__all__ = ["METRICS", "REPRODUCIBLE", "run_one", "run_chunk"]

#: Recorded per run: name -> (units, long name). Errors are the 3D means of
#: :func:`leosop.apps.simulate.metrics` over the 1 Hz epochs.
METRICS = {
    "fused_pos_err_mean_m": ("m", "mean 3D position error of the fused (LEO/INS) solution"),
    "fused_vel_err_mean_mps": ("m s-1", "mean 3D velocity error of the fused solution"),
    "fused_pos_err_rms_m": ("m", "RMS 3D position error of the fused solution"),
    "fused_availability": ("1", "fraction of 1 Hz epochs with a fused output"),
    "ins_pos_err_mean_m": ("m", "mean 3D position error of the INS alone"),
    "ins_vel_err_mean_mps": ("m s-1", "mean 3D velocity error of the INS alone"),
    "fix_pos_err_mean_m": ("m", "mean 3D position error of the LEO snapshot fixes"),
    "fix_vel_err_mean_mps": ("m s-1", "mean 3D velocity error of the LEO snapshot fixes"),
    "n_fixes": ("1", "number of LEO snapshot fixes"),
    "n_visible_min": ("1", "fewest satellites visible along the flight"),
    "n_visible_max": ("1", "most satellites visible along the flight"),
    "gdop_max": (GDOP_UNITS, "largest Doppler GDOP along the flight ([Shen 2024] eq. 10)"),
    "nees_per_dim": ("1", "mean NEES of fused position and velocity per dimension (1 when consistent)"),
    "nis_per_dof": ("1", "NIS of the filter updates per degree of freedom (1 when consistent)"),
    "runtime_s": ("s", "wall time of the run (not reproducible)"),
}
#: Metrics that depend only on the spec and the seed (all but the wall time).
REPRODUCIBLE = tuple(k for k in METRICS if k != "runtime_s")


def run_one(scenario, options, tle, seed):
    """One ``run_scenario`` call as a row of :data:`METRICS` (NaN where undefined), (n_metrics,)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. "no satellite above the mask": the numbers say it
        result = run_scenario(scenario, seed=int(seed), tle=tle, **options)
    doc = metrics(result)
    nis, dof = result.nis()
    values = {
        "fused_pos_err_mean_m": doc["fused"]["pos_err_mean_m"],
        "fused_vel_err_mean_mps": doc["fused"]["vel_err_mean_mps"],
        "fused_pos_err_rms_m": doc["fused"]["pos_err_rms_m"], "fused_availability": doc["fused"]["availability"],
        "ins_pos_err_mean_m": doc["ins_only"]["pos_err_mean_m"],
        "ins_vel_err_mean_mps": doc["ins_only"]["vel_err_mean_mps"],
        "fix_pos_err_mean_m": doc["leo_fix"]["pos_err_mean_m"],
        "fix_vel_err_mean_mps": doc["leo_fix"]["vel_err_mean_mps"],
        "n_fixes": doc["leo_fix"]["n_fixes"], "n_visible_min": doc["visible"]["min"],
        "n_visible_max": doc["visible"]["max"], "gdop_max": doc["gdop"]["max"],
        "nees_per_dim": float(np.nanmean(result.nees()[1:])) / 6.0 if result.fused.updated.any() else None,
        "nis_per_dof": float(np.nansum(nis) / dof.sum()) if dof.sum() else None,
        "runtime_s": doc["runtime_s"],
    }
    return np.array([np.nan if values[k] is None else float(values[k]) for k in METRICS])


def run_chunk(runs):
    """Rows of :func:`run_one` for a list of ``(scenario, options, tle, seed)``, (n_runs, n_metrics)."""
    return np.stack([run_one(*run) for run in runs])
