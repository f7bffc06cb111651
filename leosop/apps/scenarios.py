"""Simulation scenarios: the bundled ``xian-baoji`` flight and JSON files.

A scenario says where and when the receiver flies, how bad its IMU is and
how the LEO measurements are corrupted (DESIGN.md 4.1, [Shen 2024] section 4.1
and Table 1). Scenario files are JSON objects with the keys of
:data:`XIAN_BAOJI` (as :func:`to_dict` writes them); every key is optional
and missing keys take the xian-baoji values. Unknown keys are refused.
"""

import json
from importlib.resources import files
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ..constants import DAY_S
from ..datadir import is_data_ref, resolve_data_ref
from ..constellations import REGISTRY, family
from ..errors import InputError
from ..timebase import format_utc, parse_utc

__all__ = ["ImuSpec", "LeoSpec", "InitError", "Scenario", "XIAN_BAOJI", "BUILTIN", "load_scenario",
           "scenario_from_dict", "to_dict", "bundled_names", "BUNDLED_DIR", "family_masks_deg", "mask_label",
           "scenario_tle"]


@dataclass(frozen=True)
class ImuSpec:
    """IMU error figures, in the units their names carry ([Shen 2024] Table 1)."""

    gyro_bias_deg_per_h: float = 0.03
    gyro_arw_deg_per_rt_h: float = 0.01
    accel_bias_g: float = 1e-4
    accel_vrw_g_per_rt_hz: float = 1e-5
    rate_hz: float = 100.0


@dataclass(frozen=True)
class LeoSpec:
    """LEO measurement errors ([Shen 2024] Table 1) and fix settings.

    ``sat_doppler_offset_max_hz``: every satellite carries a constant clock-
    induced Doppler offset drawn uniformly in [0, max]. ``rx_freq_offset_hz``:
    the receiver's fixed frequency offset (estimated by every fix).
    ``orbit_error_m``: size per ECEF axis of the satellite position error,
    constant over a run; ``orbit_error_model`` says how it is drawn:
    ``"independent"`` (each satellite its own error, standard deviation
    ``orbit_error_m`` per axis) or ``"common"`` (every satellite shifted by
    the same ``[E, E, E]``, E = ``orbit_error_m``: [Shen 2024] Table 6's "orbit
    error [E, E, E] m", whose position errors are close to sqrt(3) E). Optional
    in scenario files, a compatible extension of DESIGN.md 4.1. ``cn0_dbhz``: pilot
    carrier-to-noise density (not given by the paper; 45 dB-Hz is a
    conservative figure for the Starlink pilot tone seen by a small dish).

    Several constellations (DESIGN.md 4.1 ``leo.constellations``, keys of
    :data:`leosop.constellations.REGISTRY`): each family transmits on its own carrier
    and is measured by its own receiver chain. ``rx_freq_offsets_hz`` gives
    a family's receiver offset [Hz] (missing families: ``rx_freq_offset_hz``
    scaled by the carrier ratio to Starlink's, one oscillator);
    ``cn0_dbhz_by_family`` a family's C/N0 (missing:
    :data:`leosop.constellations.REGISTRY`; Starlink's is
    ``cn0_dbhz``). The satellites' offsets scale with the carrier the same way
    (the same fractional oscillator error as Starlink's 0-5 Hz at 11.325 GHz).
    ``mask_deg_by_family``: a family's elevation mask [deg] (its own antenna:
    the omnidirectional L-band and VHF antennas of Iridium NEXT and Orbcomm
    track far lower than a Ku-band dish); missing families use the registry's
    ``mask_deg`` of the family, else the scenario's ``mask_deg``
    (:func:`family_masks_deg`). ``outage_s``: ``[start, end]``
    seconds of the flight during which only the ``outage_max_sats`` highest
    satellites are tracked (a degraded sky: foliage, banking, jamming of the
    other bands); None: no outage.
    """

    sat_doppler_offset_max_hz: float = 5.0
    rx_freq_offset_hz: float = 5.0
    orbit_error_m: float = 1.0
    fix_rate_hz: float = 1.0
    cn0_dbhz: float = 45.0
    orbit_error_model: str = "independent"
    constellations: tuple = ("starlink",)
    rx_freq_offsets_hz: dict = field(default_factory=dict)
    cn0_dbhz_by_family: dict = field(default_factory=dict)
    mask_deg_by_family: dict = field(default_factory=dict)
    outage_s: tuple | None = None
    outage_max_sats: int = 3


@dataclass(frozen=True)
class InitError:
    """Initial INS errors: ENU position [m] and velocity [m/s] ([Shen 2024] Table 1)."""

    pos_m: tuple = (100.0, 100.0, 100.0)
    vel_mps: tuple = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Scenario:
    """One flight with its sensors.

    Attributes
    ----------
    name : str
    start_utc : numpy.datetime64
        Take-off time (UTC).
    waypoints : tuple of (lat_deg, lon_deg, alt_m)
        Great-circle legs flown at constant speed and altitude profile.
    speed_mps, mask_deg : float
    duration_s : float or None
        None: the time to fly the waypoints.
    imu : ImuSpec
    leo : LeoSpec
    init_error : InitError
    tle : str or None
        Element-set file of the scenario: an absolute path (a relative one
        in a file is resolved against the file's folder), or a file of the
        data folder, ``$LEOSOP_DATA/<path>`` (:mod:`leosop.datadir`, resolved
        when the run needs it by :func:`scenario_tle`); None: the bundled
        sky. The ``--tle`` option overrides it.
    """

    name: str
    start_utc: np.datetime64
    waypoints: tuple
    speed_mps: float
    mask_deg: float
    duration_s: float | None
    imu: ImuSpec
    leo: LeoSpec
    init_error: InitError
    tle: str | None = None


#: [Shen 2024] section 4.1: Xi'an (34.342 N, 108.940 E) to Baoji (34.363 N,
#: 107.239 E) at 3 km and 200 m/s, 782 s, 40 deg mask.
#: Start time: tools/search_start_time.py scanned starts every 60 s over
#: 2025-01-01 (the bundled TLE epoch), counting satellites above 40 deg at
#: 1 Hz along the flight. 19:40:00Z is the best match to the paper's Fig. 9:
#: 6-11 visible (mean 8.5), 7 or more everywhere except 411-437 s, where 6
#: remain (paper: a thin stretch at about 402-431 s).
XIAN_BAOJI = Scenario(
    name="xian-baoji",
    start_utc=np.datetime64("2025-01-01T19:40:00", "ns"),
    waypoints=((34.342, 108.940, 3000.0), (34.363, 107.239, 3000.0)),
    speed_mps=200.0,
    mask_deg=40.0,
    duration_s=782.0,
    imu=ImuSpec(),
    leo=LeoSpec(),
    init_error=InitError(),
)

#: Scenarios known by name.
BUILTIN = {XIAN_BAOJI.name: XIAN_BAOJI}
#: Bundled scenario files, known by their stem (the degraded-sky flights of
#: the multi-constellation work; see their README.md).
BUNDLED_DIR = Path(str(files("leosop") / "data" / "scenarios"))


def to_dict(scenario):
    """The scenario as a JSON-ready dict with the file keys (DESIGN.md 4.1)."""
    doc = asdict(scenario)
    doc["start_utc"] = format_utc(scenario.start_utc)
    doc["waypoints"] = [list(w) for w in scenario.waypoints]
    doc["init_error"] = {k: list(v) for k, v in doc["init_error"].items()}
    doc["leo"]["constellations"] = list(scenario.leo.constellations)
    doc["leo"]["outage_s"] = None if scenario.leo.outage_s is None else list(scenario.leo.outage_s)
    return doc


def _number(value, where, *, low=-np.inf, high=np.inf, low_open=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where}: expected a number, got {value!r}")
    value = float(value)
    bad_low = value <= low if low_open else value < low
    if not np.isfinite(value) or bad_low or value > high:
        bracket = "(" if low_open else "["
        raise InputError(f"{where}: {value!r} is outside {bracket}{low}, {high}]")
    return value


def _vector3(value, where, low=-np.inf, high=np.inf):
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise InputError(f"{where}: expected a list of 3 numbers, got {value!r}")
    return tuple(_number(v, f"{where}[{i}]", low=low, high=high) for i, v in enumerate(value))


def _check_keys(doc, allowed, where):
    if not isinstance(doc, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    unknown = sorted(set(doc) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r} (expected one of {', '.join(sorted(allowed))})")


#: Values of the string fields.
_CHOICES = {"orbit_error_model": ("independent", "common")}
# Limits of each numeric field: (low, high, low_open).
_LIMITS = {
    "gyro_bias_deg_per_h": (0.0, 1e4, False),
    "gyro_arw_deg_per_rt_h": (0.0, 1e3, False),
    "accel_bias_g": (0.0, 1.0, False),
    "accel_vrw_g_per_rt_hz": (0.0, 1.0, False),
    "rate_hz": (1.0, 2000.0, False),
    "sat_doppler_offset_max_hz": (0.0, 1e4, False),
    "rx_freq_offset_hz": (-1e6, 1e6, False),
    "orbit_error_m": (0.0, 1e5, False),
    "fix_rate_hz": (0.0, 100.0, True),
    "cn0_dbhz": (0.0, 100.0, False),
}


def _families(value, where):
    if not isinstance(value, (list, tuple)) or not value or not all(isinstance(v, str) for v in value):
        raise InputError(f"{where}: expected a non-empty list of constellation names")
    for name in value:
        family(name, where)
    if len(set(value)) != len(value):
        raise InputError(f"{where}: a constellation is listed twice")
    return tuple(value)


def _per_family(value, where, low, high):
    _check_keys(value, REGISTRY, where)
    return {k: _number(v, f"{where}.{k}", low=low, high=high) for k, v in value.items()}


def _outage(value, where):
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise InputError(f"{where}: expected [start_s, end_s] or null, got {value!r}")
    start = _number(value[0], f"{where}[0]", low=0.0, high=DAY_S)
    end = _number(value[1], f"{where}[1]", low=start, high=DAY_S, low_open=True)
    return (start, end)


def _leo_value(key, value, where):
    """A validated value of one of the multi-constellation keys of ``leo``."""
    if key == "constellations":
        return _families(value, where)
    if key == "rx_freq_offsets_hz":
        return _per_family(value, where, -1e6, 1e6)
    if key == "cn0_dbhz_by_family":
        return _per_family(value, where, 0.0, 100.0)
    if key == "mask_deg_by_family":
        return _per_family(value, where, 0.0, 89.0)
    if key == "outage_s":
        return _outage(value, where)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 1000:
        raise InputError(f"{where}: expected a whole number of satellites in [0, 1000], got {value!r}")
    return value


_LEO_KEYS = ("constellations", "rx_freq_offsets_hz", "cn0_dbhz_by_family", "mask_deg_by_family", "outage_s",
             "outage_max_sats")


def _section(cls, doc, base, where):
    names = [f.name for f in fields(cls)]
    _check_keys(doc, names, where)
    values = {}
    for key, value in doc.items():
        if key in _LEO_KEYS:
            values[key] = _leo_value(key, value, f"{where}.{key}")
        elif cls is InitError:
            values[key] = _vector3(value, f"{where}.{key}", -1e6, 1e6)
        elif key in _CHOICES:
            if value not in _CHOICES[key]:
                raise InputError(f"{where}.{key}: expected one of {', '.join(_CHOICES[key])}, got {value!r}")
            values[key] = value
        else:
            low, high, low_open = _LIMITS[key]
            values[key] = _number(value, f"{where}.{key}", low=low, high=high, low_open=low_open)
    return replace(base, **values)


def _waypoints(value, where):
    if not isinstance(value, (list, tuple)) or len(value) < 2:
        raise InputError(f"{where}: expected a list of at least 2 [lat_deg, lon_deg, alt_m] points")
    points = []
    for i, point in enumerate(value):
        if not isinstance(point, (list, tuple)) or len(point) != 3:
            raise InputError(f"{where}[{i}]: expected [lat_deg, lon_deg, alt_m], got {point!r}")
        lat = _number(point[0], f"{where}[{i}] latitude", low=-89.0, high=89.0)
        lon = _number(point[1], f"{where}[{i}] longitude", low=-180.0, high=180.0)
        alt = _number(point[2], f"{where}[{i}] altitude", low=-400.0, high=50_000.0)
        points.append((lat, lon, alt))
    return tuple(points)


def scenario_from_dict(doc, *, source="scenario", base=XIAN_BAOJI):
    """A validated :class:`Scenario` from a dict of file keys; missing keys from ``base``.

    Raises
    ------
    InputError
        Naming ``source`` and the key for unknown keys and out-of-range values.
    """
    top = ("name", "start_utc", "waypoints", "speed_mps", "mask_deg", "duration_s", "imu", "leo", "init_error", "tle")
    _check_keys(doc, top, source)
    values = {}
    if "name" in doc:
        if not isinstance(doc["name"], str) or not doc["name"].strip():
            raise InputError(f"{source}.name: expected a non-empty string")
        values["name"] = doc["name"].strip()
    if "start_utc" in doc:
        try:
            values["start_utc"] = np.datetime64(parse_utc(str(doc["start_utc"]), name=f"{source}.start_utc"), "ns")
        except ValueError as exc:
            raise InputError(str(exc)) from None
    if "waypoints" in doc:
        values["waypoints"] = _waypoints(doc["waypoints"], f"{source}.waypoints")
    if "speed_mps" in doc:
        values["speed_mps"] = _number(doc["speed_mps"], f"{source}.speed_mps", low=0.0, high=8000.0, low_open=True)
    if "mask_deg" in doc:
        values["mask_deg"] = _number(doc["mask_deg"], f"{source}.mask_deg", low=0.0, high=89.0)
    if "duration_s" in doc:
        values["duration_s"] = None if doc["duration_s"] is None else _number(
            doc["duration_s"], f"{source}.duration_s", low=0.0, high=DAY_S, low_open=True)
    elif "waypoints" in doc or "speed_mps" in doc:
        values["duration_s"] = None  # the base flight's length no longer applies
    if "tle" in doc:
        if doc["tle"] is not None and (not isinstance(doc["tle"], str) or not doc["tle"].strip()):
            raise InputError(f"{source}.tle: expected a file name or null")
        values["tle"] = doc["tle"]
    for key, cls in (("imu", ImuSpec), ("leo", LeoSpec), ("init_error", InitError)):
        if key in doc:
            values[key] = _section(cls, doc[key], getattr(base, key), f"{source}.{key}")
    # A family's mask given here must be of a family received; masks inherited from ``base`` for
    # families this document drops (a study narrowing leo.constellations) are left unused.
    leo = values.get("leo", base.leo)
    unselected = sorted(set(doc.get("leo", {}).get("mask_deg_by_family", {})) - set(leo.constellations))
    if unselected:
        raise InputError(f"{source}.leo.mask_deg_by_family: {unselected[0]!r} is not in leo.constellations "
                         f"({', '.join(leo.constellations)})")
    return replace(base, **values)


def family_masks_deg(scenario):
    """The elevation mask of each of ``scenario.leo.constellations`` [deg], ndarray (k,).

    A family's ``leo.mask_deg_by_family`` entry, else its registry ``mask_deg``, else the scenario's ``mask_deg``.
    """
    own = {f: family(f).mask_deg for f in scenario.leo.constellations}
    return np.array([scenario.leo.mask_deg_by_family.get(f, scenario.mask_deg if own[f] is None else own[f])
                     for f in scenario.leo.constellations])


def mask_label(scenario):
    """The masks in words for titles and messages: ``"40 deg"``, or ``"40 deg (iridium 15, orbcomm 15)"``.

    Only the families of ``leo.constellations`` whose mask differs from ``mask_deg`` are named.
    """
    own = [f"{f} {m:g}" for f, m in zip(scenario.leo.constellations, family_masks_deg(scenario))
           if m != scenario.mask_deg]
    return f"{scenario.mask_deg:g} deg" + (f" ({', '.join(own)})" if own else "")


def bundled_names():
    """Names of every built-in scenario: ``xian-baoji`` and the files of :data:`BUNDLED_DIR`."""
    return list(BUILTIN) + sorted(p.stem for p in BUNDLED_DIR.glob("*.json"))


def load_scenario(name_or_path):
    """A built-in scenario by name, or a scenario JSON file.

    Parameters
    ----------
    name_or_path : str or path-like
        ``"xian-baoji"``, the name of a bundled scenario file
        (:data:`BUNDLED_DIR`, e.g. ``"urban-canyon"``) or the path of a JSON file.

    Returns
    -------
    Scenario
        Its ``tle``, when a relative path, resolved against the file's
        folder; a ``$LEOSOP_DATA/...`` reference is kept (:func:`scenario_tle`).
    """
    key = str(name_or_path)
    if key in BUILTIN:
        return BUILTIN[key]
    path = BUNDLED_DIR / f"{key}.json"
    if not path.exists():
        path = Path(key)
        if not path.suffix == ".json" and not path.exists():
            raise InputError(f"name_or_path: {key!r} is neither a built-in scenario ({', '.join(bundled_names())}) "
                             "nor a JSON file", param="name_or_path")
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"name_or_path: cannot read {path}: {exc.strerror}", param="name_or_path") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start}); "
                         "a scenario file is JSON") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    scenario = scenario_from_dict(doc, source=str(path))
    if "name" not in doc:
        scenario = replace(scenario, name=path.stem)
    if scenario.tle is not None and not is_data_ref(scenario.tle):
        scenario = replace(scenario, tle=str((path.parent / scenario.tle).resolve()))
    return scenario


def scenario_tle(scenario, data_dir=None):
    """The element-set file a run of ``scenario`` reads: a path, or None for the bundled sky.

    Parameters
    ----------
    scenario : Scenario
    data_dir : path-like, optional
        The data folder (``--data``) for a ``$LEOSOP_DATA/...`` ``tle``;
        default the environment variable.

    Raises
    ------
    InputError
        The scenario's file is in the data folder and the folder is not
        given or lacks it (:func:`leosop.datadir.resolve_data_ref`).
    """
    if not is_data_ref(scenario.tle):
        return scenario.tle
    return str(resolve_data_ref(scenario.tle, data_dir=data_dir, needed_by=f"scenario {scenario.name}"))
