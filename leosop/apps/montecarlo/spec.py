"""Monte Carlo study specification: a JSON file, checked field by field.

A spec is a JSON object::

    {
      "name": "table5",                        optional, default the file name
      "description": "...",                    optional
      "scenario": "xian-baoji",                built-in name, scenario file (relative
                                               to the spec) or a scenario object
      "tle": "path/to.tle",                    optional, relative to the spec
      "fixed": {"level": "measurement"},       parameters held at one value
      "parameters": {                          the grid: one axis per parameter,
        "correction_period_s": [1, 30, 60],    in this order
        "coupling": ["loose", "tight"]
      },
      "n_seeds": 20,                           runs per grid cell
      "seed": 0,                               root of the SeedSequence (optional, 0)
      "runs_per_chunk": 10                     runs per Dask task and chunk file (optional, 10)
    }

Parameter names are those of :data:`leosop.apps.montecarlo.parameters.PARAMETERS`.
Every error is one line naming the file and the field.
"""

import hashlib
import itertools
import json
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

import numpy as np

from ...chunkstore import code_digest
from ...errors import InputError
from ..scenarios import load_scenario, scenario_from_dict, to_dict
from .parameters import PARAMETERS, apply, check_value, label

__all__ = ["StudySpec", "load_spec", "spec_from_dict", "bundled_specs", "run_seeds"]

_KEYS = ("name", "description", "scenario", "tle", "fixed", "parameters", "n_seeds", "seed", "runs_per_chunk")
DEFAULT_RUNS_PER_CHUNK = 10
#: Largest study accepted (runs): the client's results array stays near 120 MB.
MAX_RUNS = 1_000_000


@dataclass(frozen=True)
class StudySpec:
    """A checked study.

    Attributes
    ----------
    name, description : str
    scenario : leosop.apps.scenarios.Scenario
        The base scenario (before ``fixed`` and the grid).
    tle : str or None
        Element-set file (absolute), None for the bundled one.
    fixed : dict
        Parameter name -> value.
    axes : dict
        Parameter name -> tuple of values, in grid order.
    n_seeds, seed, runs_per_chunk : int
    source : str
        Where the spec came from (file path or "<dict>").
    """

    name: str
    description: str
    scenario: object
    tle: str | None
    fixed: dict
    axes: dict
    n_seeds: int
    seed: int
    runs_per_chunk: int
    source: str

    @property
    def shape(self):
        """Grid shape plus the seed axis: ``(n_1, ..., n_k, n_seeds)``."""
        return tuple(len(v) for v in self.axes.values()) + (self.n_seeds,)

    @property
    def n_runs(self):
        return int(np.prod(self.shape))

    def cells(self):
        """Every grid cell as a dict of parameter values (fixed ones included), C order."""
        names = list(self.axes)
        return [dict(self.fixed, **dict(zip(names, combo))) for combo in itertools.product(*self.axes.values())]

    def to_json(self):
        """The normalised spec (scenario expanded), as stored in the NetCDF attributes."""
        return json.dumps({
            "name": self.name, "description": self.description, "scenario": to_dict(self.scenario),
            "tle": self.tle, "fixed": self.fixed, "parameters": {k: list(v) for k, v in self.axes.items()},
            "n_seeds": self.n_seeds, "seed": self.seed, "runs_per_chunk": self.runs_per_chunk,
        }, sort_keys=True)

    def digest(self):
        """Hash of everything the results depend on: spec, element-set file, leosop version and source code."""
        h = hashlib.sha256(self.to_json().encode())
        h.update(code_digest().encode())
        if self.tle is not None:
            stat = Path(self.tle).stat()
            h.update(f"{stat.st_size}:{stat.st_mtime_ns}".encode())
        return h.hexdigest()


def run_seeds(spec):
    """The ``seed`` of each seed index: child k of ``SeedSequence(spec.seed)``, (n_seeds,) int64.

    Seed k is the same in every grid cell (common random numbers: cells differ
    only by their parameters), and a run is reproduced alone by
    ``run_scenario(..., seed=run_seeds(spec)[k])``. Values are 31-bit so that
    NetCDF 3 stores them exactly.
    """
    children = np.random.SeedSequence(spec.seed).spawn(spec.n_seeds)
    return np.array([c.generate_state(1, np.uint32)[0] >> 1 for c in children], dtype=np.int64)


def bundled_specs():
    """Names of the bundled spec files (``leosop/data/studies/NAME.json``) -> path."""
    folder = files("leosop") / "data" / "studies"
    return {Path(str(p)).stem: Path(str(p)) for p in folder.iterdir() if str(p).endswith(".json")}


def load_spec(name_or_path):
    """A spec from a JSON file, or a bundled spec by name (:func:`bundled_specs`)."""
    key = str(name_or_path)
    path = Path(key)
    bundled = bundled_specs()
    if not path.exists() and key in bundled:
        path = bundled[key]
    elif not path.exists():
        raise InputError(f"{key}: no such spec file (bundled specs: {', '.join(sorted(bundled))})")
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file") from None
    return spec_from_dict(doc, source=str(path), base_dir=path.parent)


def _int(doc, key, default, low, where):
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InputError(f"{where}: {key}: expected an integer >= {low}, got {value!r}")
    return value


def _scenario(value, base_dir, where):
    if isinstance(value, dict):
        return scenario_from_dict(value, source=f"{where}: scenario")
    if not isinstance(value, str):
        raise InputError(f"{where}: scenario: expected a scenario name, file or object, got {value!r}")
    candidate = base_dir / value
    return load_scenario(candidate if candidate.suffix == ".json" else value)


def _axis(name, values, where):
    if not isinstance(values, list) or not values:
        raise InputError(f"{where}: expected a non-empty list of values, got {values!r}")
    checked = [check_value(name, v, f"{where}[{i}]") for i, v in enumerate(values)]
    if len(set(checked)) != len(checked):
        raise InputError(f"{where}: values repeat ({values!r})")
    return tuple(checked)


def _names(doc, where):
    if not isinstance(doc, dict):
        raise InputError(f"{where}: expected a JSON object of parameter names, got {type(doc).__name__}")
    for name in doc:
        if name not in PARAMETERS:
            raise InputError(f"{where}: unknown parameter {name!r} (expected one of {', '.join(PARAMETERS)})")
    return doc


def spec_from_dict(doc, *, source="<dict>", base_dir=Path(".")):
    """A checked :class:`StudySpec` from a parsed JSON object (see the module docstring)."""
    where = source
    if not isinstance(doc, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    unknown = sorted(set(doc) - set(_KEYS))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r} (expected one of {', '.join(_KEYS)})")
    for key in ("parameters", "n_seeds"):
        if key not in doc:
            raise InputError(f"{where}: missing key {key!r}")
    name = doc.get("name", Path(source).stem)
    description = doc.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise InputError(f"{where}: {key}: expected a string, got {value!r}")
    scenario = _scenario(doc.get("scenario", "xian-baoji"), base_dir, where)
    tle = doc.get("tle")
    if tle is not None:
        if not isinstance(tle, str) or not (base_dir / tle).is_file():
            raise InputError(f"{where}: tle: {tle!r} is not a file (paths are relative to the spec)")
        tle = str((base_dir / tle).resolve())
    fixed = {k: check_value(k, v, f"{where}: fixed.{k}")
             for k, v in _names(doc.get("fixed", {}), f"{where}: fixed").items()}
    params = _names(doc["parameters"], f"{where}: parameters")
    if not params:
        raise InputError(f"{where}: parameters: expected at least one parameter with a list of values")
    axes = {k: _axis(k, v, f"{where}: parameters.{k}") for k, v in params.items()}
    both = sorted(set(fixed) & set(axes))
    if both:
        raise InputError(f"{where}: parameter {both[0]!r} is both fixed and swept")
    imu_fields = sorted(k for k in {**fixed, **axes} if PARAMETERS[k].target == "imu" and k != "rate_hz")
    if "imu_grade" in {**fixed, **axes} and imu_fields:
        raise InputError(f"{where}: imu_grade and {imu_fields[0]} both set the IMU errors; keep one")
    spec = StudySpec(name=name, description=description, scenario=scenario, tle=tle, fixed=fixed, axes=axes,
                     n_seeds=_int(doc, "n_seeds", None, 1, where), seed=_int(doc, "seed", 0, 0, where),
                     runs_per_chunk=_int(doc, "runs_per_chunk", DEFAULT_RUNS_PER_CHUNK, 1, where), source=source)
    if spec.n_runs > MAX_RUNS:
        raise InputError(f"{where}: {spec.n_runs:,} runs is too many (at most {MAX_RUNS:,})")
    for name, values in axes.items():  # each value alone first: the message names its place in the file
        for i, value in enumerate(values):
            apply(scenario, {**fixed, name: value}, f"{where}: parameters.{name}[{i}]: scenario")
    for cell in spec.cells():  # then every combination, before anything runs
        apply(scenario, cell, f"{where}: cell {_label(cell, axes)}: scenario")
    return spec


def _label(cell, axes):
    return ", ".join(f"{k}={label(cell[k])}" for k in axes)
