"""The scenario parameters a Monte Carlo study can sweep, and how each reaches a run.

A parameter is either an option of :func:`leosop.apps.simulate.run_scenario`
(``correction_period_s``, ``orbit_error_m``, ``orbit_error_model``,
``coupling``, ``level``), a field of the scenario (``mask_deg``,
``cn0_dbhz``, the IMU figures, ... named as in the scenario file without
their section, DESIGN.md 4.1) or ``imu_grade``, a named set of the four IMU
error figures (:data:`IMU_GRADES`). ``constellations`` is the LEO family mix
(``leo.constellations``): each value a list of family names, e.g.
``[["starlink"], ["starlink", "oneweb", "iridium", "orbcomm"]]``, labelled
``starlink+oneweb+...`` in results (:func:`label`). Scenario fields are
checked by :func:`leosop.apps.scenarios.scenario_from_dict`, so a study accepts
exactly the values a scenario file accepts.
"""

from dataclasses import dataclass

import numpy as np

from ...constellations import REGISTRY
from ...errors import InputError
from ...fusion.common import ORBIT_MODELS
from ..scenarios import scenario_from_dict
from ..simulate import COUPLINGS, LEVELS

__all__ = ["Parameter", "PARAMETERS", "IMU_GRADES", "check_value", "apply", "label"]

#: IMU error figures by grade (bias and random walk of gyro and accelerometer).
#: ``navigation``: [Shen 2024] Table 1 (the xian-baoji IMU). ``tactical``: the
#: biases of [Qu 2024]'s turntable IMU (1 deg/h, 0.1 mg). ``mems``: 10 deg/h
#: and 1 mg, an assumed consumer-MEMS order of magnitude (no seed paper gives
#: one). The random walks of the tactical and MEMS grades are Table 1's scaled
#: by the ratio of their biases to Table 1's (the papers give no random walks).
IMU_GRADES = {
    "navigation": {"gyro_bias_deg_per_h": 0.03, "gyro_arw_deg_per_rt_h": 0.01,
                   "accel_bias_g": 1e-4, "accel_vrw_g_per_rt_hz": 1e-5},
    "tactical": {"gyro_bias_deg_per_h": 1.0, "gyro_arw_deg_per_rt_h": 0.01 * 1.0 / 0.03,
                 "accel_bias_g": 1e-4, "accel_vrw_g_per_rt_hz": 1e-5},
    "mems": {"gyro_bias_deg_per_h": 10.0, "gyro_arw_deg_per_rt_h": 0.01 * 10.0 / 0.03,
             "accel_bias_g": 1e-3, "accel_vrw_g_per_rt_hz": 1e-5 * 1e-3 / 1e-4},
}


@dataclass(frozen=True)
class Parameter:
    """One sweepable parameter.

    Attributes
    ----------
    name : str
    target : {"run", "scenario", "leo", "imu", "imu_grade"}
        Where the value goes: a ``run_scenario`` option, a top-level scenario
        field, a field of the scenario's ``leo`` or ``imu`` section, or the
        IMU grade (all four IMU error figures).
    units : str
        CF-style units of the value ("1" dimensionless, "" for names).
    long_name : str
    choices : tuple of str, optional
        The allowed names of a categorical parameter; None for numbers.
    multiple : bool
        Each value is a list of distinct ``choices`` (a tuple once checked),
        not one of them.
    """

    name: str
    target: str
    units: str
    long_name: str
    choices: tuple | None = None
    multiple: bool = False


def _params():
    p = [
        Parameter("correction_period_s", "run", "s", "time between EKF corrections of the INS"),
        Parameter("orbit_error_m", "run", "m", "satellite orbit error per ECEF axis"),
        Parameter("orbit_error_model", "run", "", "how orbit errors are drawn", ORBIT_MODELS),
        Parameter("coupling", "run", "", "INS/LEO coupling of the EKF", COUPLINGS),
        Parameter("level", "run", "", "signal or measurement level simulation", LEVELS),
        Parameter("mask_deg", "scenario", "degree", "elevation mask"),
        Parameter("speed_mps", "scenario", "m s-1", "flight speed"),
        Parameter("duration_s", "scenario", "s", "flight duration"),
        Parameter("cn0_dbhz", "leo", "dB-Hz", "pilot carrier-to-noise density"),
        Parameter("sat_doppler_offset_max_hz", "leo", "Hz", "largest clock-induced Doppler offset of a satellite"),
        Parameter("rx_freq_offset_hz", "leo", "Hz", "receiver frequency offset"),
        Parameter("fix_rate_hz", "leo", "Hz", "LEO fix and fusion rate"),
        Parameter("constellations", "leo", "", "LEO constellation families received", tuple(REGISTRY),
                  multiple=True),
        Parameter("gyro_bias_deg_per_h", "imu", "degree h-1", "gyro constant bias"),
        Parameter("gyro_arw_deg_per_rt_h", "imu", "degree h-1/2", "gyro angle random walk"),
        Parameter("accel_bias_g", "imu", "g", "accelerometer constant bias"),
        Parameter("accel_vrw_g_per_rt_hz", "imu", "g Hz-1/2", "accelerometer velocity random walk"),
        Parameter("rate_hz", "imu", "Hz", "IMU sample rate"),
        Parameter("imu_grade", "imu_grade", "", "IMU grade (error figures of leosop.apps.montecarlo.IMU_GRADES)",
                  tuple(IMU_GRADES)),
    ]
    return {q.name: q for q in p}


#: Every parameter a study may fix or sweep, by name.
PARAMETERS = _params()


def check_value(name, value, where):
    """``value`` as the run will use it (float, str or tuple of str); InputError naming ``where`` if invalid.

    Run options and lists of names are checked here (lists as the scenario
    file checks them); other scenario fields by :func:`apply` (which builds
    the scenario).
    """
    param = PARAMETERS[name]
    if param.multiple:
        scenario = scenario_from_dict({param.target: {name: value}}, source=f"{where}: scenario")
        return getattr(getattr(scenario, param.target), name)
    if param.choices is not None:
        if value not in param.choices:
            raise InputError(f"{where}: expected one of {', '.join(param.choices)}, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    value = float(value)
    if name == "correction_period_s" and value <= 0:
        raise InputError(f"{where}: {value:g} must be > 0 s")
    if name == "orbit_error_m" and value < 0:
        raise InputError(f"{where}: {value:g} must be >= 0 m")
    return value


def label(value):
    """A checked value as text for coordinates and tables: names of a list joined by ``+``, numbers as ``%g``."""
    if isinstance(value, tuple):
        return "+".join(value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def apply(base, values, where):
    """The scenario and ``run_scenario`` options of one cell.

    Parameters
    ----------
    base : leosop.apps.scenarios.Scenario
    values : dict
        Parameter name -> checked value (:func:`check_value`).
    where : str
        Names the cell in error messages (file and parameters).

    Returns
    -------
    scenario : leosop.apps.scenarios.Scenario
    options : dict
        Keyword arguments of ``run_scenario`` (without ``seed``).
    """
    doc, options = {}, {}
    for name, value in values.items():
        target = PARAMETERS[name].target
        if target == "run":
            options[name] = value
        elif target == "scenario":
            doc[name] = value
        elif target == "imu_grade":
            doc.setdefault("imu", {}).update(IMU_GRADES[value])
        else:
            doc.setdefault(target, {})[name] = value
    scenario = scenario_from_dict(doc, source=where, base=base) if doc else base
    return scenario, options
