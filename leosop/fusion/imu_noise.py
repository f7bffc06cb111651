"""The IMU noise a fusion filter assumes: data-sheet figures, grades, a JSON file, Allan deviations.

:class:`ImuSpec` turns data-sheet units into the engine's
:class:`leosop.fusion.engine.EngineSettings`; :data:`GRADES` are typical
figures by grade; :func:`imu_spec` reads a grade name or the JSON file
``leosop imu allan --out`` writes.
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from .. import earth
from ..errors import InputError
from . import engine

__all__ = ["GRADES", "ImuSpec", "imu_spec"]


@dataclasses.dataclass(frozen=True)
class ImuSpec:
    """IMU noise for the filter, in data-sheet units.

    ``gyro_arw_deg_per_rt_h`` and ``accel_vrw_ug_per_rt_hz`` are white noise
    densities (vibration included), ``*_bias_sigma_*`` the initial bias
    uncertainty (turn-on bias), ``*_bias_rw_*`` the bias random walks.
    """

    gyro_arw_deg_per_rt_h: float
    accel_vrw_ug_per_rt_hz: float
    gyro_bias_sigma_deg_per_s: float
    accel_bias_sigma_mps2: float
    gyro_bias_rw_deg_per_s_per_rt_s: float
    accel_bias_rw_mps2_per_rt_s: float

    @classmethod
    def from_allan(cls, gyro, accel):
        """The spec read off Allan deviations (:func:`leosop.ins.allan.allan`) of a static log, worst axis.

        Gyro ``gyro`` in rad/s, accelerometer ``accel`` in m/s^2. White
        densities as they are; each bias instability ``B`` (least Allan
        deviation at ``tau_min``) becomes the initial bias sigma and a random
        walk reaching ``B`` over ``tau_min`` (``B / sqrt(tau_min)``). A static
        log cannot show the turn-on bias, so the initial sigma is a floor.
        """
        g = earth.normal_gravity_mps2(0.0, 0.0)
        return cls(gyro_arw_deg_per_rt_h=math.degrees(float(gyro.white_density.max())) * 60.0,
                   accel_vrw_ug_per_rt_hz=float(accel.white_density.max()) / g * 1e6,
                   gyro_bias_sigma_deg_per_s=math.degrees(float(gyro.bias_instability.max())),
                   accel_bias_sigma_mps2=float(accel.bias_instability.max()),
                   gyro_bias_rw_deg_per_s_per_rt_s=math.degrees(float(
                       np.max(gyro.bias_instability / np.sqrt(gyro.tau_min_s)))),
                   accel_bias_rw_mps2_per_rt_s=float(np.max(accel.bias_instability / np.sqrt(accel.tau_min_s))))

    def settings(self):
        """The :class:`leosop.fusion.engine.EngineSettings` of this IMU."""
        return engine.EngineSettings(
            gyro_arw_rad_per_rt_s=math.radians(self.gyro_arw_deg_per_rt_h) / 60.0,
            accel_vrw_mps_per_rt_s=self.accel_vrw_ug_per_rt_hz * 1e-6 * earth.normal_gravity_mps2(0.0, 0.0),
            gyro_bias_rw_rad_per_s_per_rt_s=math.radians(self.gyro_bias_rw_deg_per_s_per_rt_s),
            accel_bias_rw_mps2_per_rt_s=self.accel_bias_rw_mps2_per_rt_s)


#: Noise models by grade. ``consumer``: a MEMS IMU in a car or a hand (the rtklibexplorer logs), its white
#: noise raised far above the data sheet's (~0.2 deg/sqrt(h), ~100 ug/sqrt(Hz)) to cover engine vibration,
#: hand shake and the unmodelled scale factors and misalignments (chosen on the drive: with 1 deg/sqrt(h) and
#: 1000 ug/sqrt(Hz) only 48 % of the outage errors were inside 3 sigma; tools/bench_fuse.py); the others are
#: typical values of their grades (Groves 2013, section 4.4).
GRADES = {
    "consumer": ImuSpec(6.0, 3000.0, 0.5, 0.2, 1e-3, 1e-3),
    "industrial": ImuSpec(0.2, 100.0, 0.05, 0.05, 1e-4, 1e-4),
    "tactical": ImuSpec(0.05, 50.0, 10.0 / 3600, 0.01, 1e-5, 1e-5),
    "navigation": ImuSpec(0.002, 10.0, 0.01 / 3600, 0.001, 1e-7, 1e-6),
}


def imu_spec(spec):
    """An :class:`ImuSpec` from a grade name of :data:`GRADES` or a JSON file with its fields.

    Parameters
    ----------
    spec : str or path-like
        A key of :data:`GRADES` or the path of a JSON object with the fields of :class:`ImuSpec`.
    """
    if spec in GRADES:
        return GRADES[spec]
    path = Path(spec)
    if not path.is_file():
        raise InputError(f"spec {spec}: neither a grade ({', '.join(GRADES)}) nor a JSON file", param="spec")
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"spec {path}: not readable JSON ({exc})", param="spec") from None
    fields = [f.name for f in dataclasses.fields(ImuSpec)]
    if not isinstance(doc, dict) or set(doc) != set(fields):
        raise InputError(f"spec {path}: expected an object with exactly the keys {', '.join(fields)}", param="spec")
    bad = [k for k in fields if isinstance(doc[k], bool) or not isinstance(doc[k], (int, float))
           or not math.isfinite(doc[k]) or doc[k] <= 0]
    if bad:
        raise InputError(f"spec {path}: {bad[0]} must be a positive number, got {doc[bad[0]]!r}", param="spec")
    return ImuSpec(**{k: float(doc[k]) for k in fields})
