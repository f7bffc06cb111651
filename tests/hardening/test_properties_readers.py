"""Structure-aware fuzzing of the JSON readers with hypothesis (issue 13).

Byte-level fuzzing (``tools/fuzz_readers.py``) mostly breaks the JSON syntax;
here every known field of an otherwise valid document is either kept or
replaced by an arbitrary JSON value (wrong type, NaN, huge, nested). The
reader must return or raise InputError, nothing else.
"""

import json
import math

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from leosop.errors import InputError
from leosop.orbits import read_omm
from leosop.apps.scenarios import load_scenario
from leosop.signal.iq import open_sigmf

MANY = settings(max_examples=100, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

scalar = (st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats(allow_nan=True, allow_infinity=True)
          | st.text(max_size=12) | st.sampled_from(["", "nan", "1e999", "-1", "2025-01-01T00:00:00Z", "9999-99-99"]))
json_value = st.recursive(scalar, lambda inner: st.lists(inner, max_size=3)
                          | st.dictionaries(st.text(max_size=6), inner, max_size=3), max_leaves=6)


def _maybe_broken(valid):
    """Strategy of ``valid`` (a dict) with each field kept or replaced by any JSON value, or dropped."""
    return st.fixed_dictionaries({k: st.one_of(st.just(v), json_value, st.just(_DROP)) for k, v in valid.items()}) \
        .map(lambda d: {k: v for k, v in d.items() if v is not _DROP})


_DROP = object()


def _read_or_refuse(call):
    try:
        call()
    except InputError as exc:
        assert str(exc).strip()


_OMM = {"OBJECT_NAME": "STARLINK-1007", "NORAD_CAT_ID": 44713, "EPOCH": "2025-01-01T00:00:00.000",
        "MEAN_MOTION": 15.06, "ECCENTRICITY": 0.0001, "INCLINATION": 53.05, "RA_OF_ASC_NODE": 10.0,
        "ARG_OF_PERICENTER": 90.0, "MEAN_ANOMALY": 270.0, "BSTAR": 0.0001, "MEAN_MOTION_DOT": 1e-5,
        "MEAN_MOTION_DDOT": 0, "CLASSIFICATION_TYPE": "U", "ELEMENT_SET_NO": 999, "REV_AT_EPOCH": 1}


@MANY
@given(st.lists(_maybe_broken(_OMM), min_size=1, max_size=2) | json_value)
@example([{**_OMM, "CLASSIFICATION_TYPE": []}])  # found by this test in CI: sgp4 raised TypeError on "[]"
@example([{**_OMM, "CLASSIFICATION_TYPE": "SECRET"}])
def test_omm_json_fields_of_any_type(tmp_path, doc):
    path = tmp_path / "set.json"
    path.write_text(json.dumps(doc))
    _read_or_refuse(lambda: read_omm(path))


_GLOBAL = {"core:datatype": "cf32_le", "core:sample_rate": 1000.0, "core:version": "1.2.0", "core:num_channels": 1,
           "leosop:n_tones": 9, "leosop:tone_spacing_hz": 43945.3125}
_CAPTURE = {"core:sample_start": 0, "core:frequency": 11.325e9, "core:datetime": "2025-01-01T00:00:00Z",
            "core:header_bytes": 0}
_ANNOTATION = {"core:sample_start": 0, "core:sample_count": 64, "leosop:sat_id": "1", "leosop:doppler_hz": 5.0,
               "leosop:t_s": 0.03, "leosop:cn0_dbhz": 45.0}


@MANY
@given(st.fixed_dictionaries({"global": _maybe_broken(_GLOBAL),
                              "captures": st.lists(_maybe_broken(_CAPTURE), max_size=2) | json_value,
                              "annotations": st.lists(_maybe_broken(_ANNOTATION), max_size=2) | json_value}))
# Found by this test in CI: an integer beyond int64 made np.isfinite raise TypeError.
@example({"global": {**_GLOBAL, "leosop:tone_spacing_hz": -9223372036854775809}, "captures": [], "annotations": []})
def test_sigmf_metadata_fields_of_any_type(tmp_path, meta):
    (tmp_path / "r.sigmf-data").write_bytes(bytes(8 * 256))
    path = tmp_path / "r.sigmf-meta"
    path.write_text(json.dumps(meta))

    def read():
        rec = open_sigmf(path)
        assert math.isfinite(rec.sample_rate_hz) and rec.sample_rate_hz > 0
        rec.read(0, rec.n_samples)

    _read_or_refuse(read)


_SCENARIO = {"name": "fuzz", "start_utc": "2025-01-01T00:00:00Z", "speed_mps": 100.0, "mask_deg": 20.0,
             "duration_s": 60.0, "waypoints": [[34.3, 108.9, 400.0], [34.4, 109.0, 500.0]],
             "imu": {"gyro_bias_deg_per_h": 0.1, "rate_hz": 100.0}, "leo": {"cn0_dbhz": 45.0, "fix_rate_hz": 1.0},
             "init_error": {"pos_m": [1.0, 1.0, 1.0], "vel_mps": [0.1, 0.1, 0.1]}}


@MANY
@given(_maybe_broken(_SCENARIO) | json_value)
def test_scenario_fields_of_any_type(tmp_path, doc):
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(doc))
    _read_or_refuse(lambda: load_scenario(path))


def test_omm_classification_must_be_one_character(tmp_path):
    path = tmp_path / "set.json"
    path.write_text(json.dumps([{**_OMM, "CLASSIFICATION_TYPE": []}]))
    with pytest.raises(InputError, match=r"record 1: OMM field CLASSIFICATION_TYPE: expected one character"):
        read_omm(path)
    path.write_text(json.dumps([{**_OMM, "CLASSIFICATION_TYPE": "C"}]))
    assert read_omm(path).names == ("STARLINK-1007",)
