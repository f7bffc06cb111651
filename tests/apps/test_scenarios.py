"""Scenario files: defaults, round trip, and the bad inputs of issue 6."""

import json

import numpy as np
import pytest

from leosop.errors import InputError
from leosop.apps.scenarios import XIAN_BAOJI, load_scenario, scenario_from_dict, to_dict


def test_xian_baoji_carries_shen2024_table1_and_section_4_1():
    s = load_scenario("xian-baoji")
    assert s.waypoints == ((34.342, 108.940, 3000.0), (34.363, 107.239, 3000.0))
    assert (s.speed_mps, s.mask_deg, s.duration_s) == (200.0, 40.0, 782.0)
    assert (s.imu.gyro_bias_deg_per_h, s.imu.gyro_arw_deg_per_rt_h) == (0.03, 0.01)
    assert (s.imu.accel_bias_g, s.imu.accel_vrw_g_per_rt_hz, s.imu.rate_hz) == (1e-4, 1e-5, 100.0)
    assert (s.leo.sat_doppler_offset_max_hz, s.leo.rx_freq_offset_hz, s.leo.orbit_error_m) == (5.0, 5.0, 1.0)
    assert s.init_error.pos_m == (100.0, 100.0, 100.0) and s.init_error.vel_mps == (1.0, 1.0, 1.0)


def test_dict_round_trip_and_json_file(tmp_path):
    doc = to_dict(XIAN_BAOJI)
    assert scenario_from_dict(json.loads(json.dumps(doc))) == XIAN_BAOJI
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"start_utc": "2025-01-01T10:00:00Z", "leo": {"orbit_error_m": 30}}))
    s = load_scenario(path)
    assert s.name == "mine"  # file stem when the file has no name
    assert s.start_utc == np.datetime64("2025-01-01T10:00:00", "ns")
    assert s.leo.orbit_error_m == 30.0
    assert s.leo.rx_freq_offset_hz == XIAN_BAOJI.leo.rx_freq_offset_hz  # missing keys: xian-baoji values
    assert s.waypoints == XIAN_BAOJI.waypoints and s.duration_s == 782.0
    assert s.leo.orbit_error_model == "independent"  # optional key, default


def test_orbit_error_model_is_an_optional_leo_key():
    s = scenario_from_dict({"leo": {"orbit_error_m": 60, "orbit_error_model": "common"}})
    assert (s.leo.orbit_error_m, s.leo.orbit_error_model) == (60.0, "common")
    assert scenario_from_dict(to_dict(s)) == s


def test_new_waypoints_drop_the_default_duration():
    s = scenario_from_dict({"waypoints": [[10, 20, 100], [10.1, 20, 100]]})
    assert s.duration_s is None


@pytest.mark.parametrize(
    "doc, words",
    [
        ({"colour": "red"}, ["'colour'"]),
        ({"imu": {"gyro_bias": 1}}, ["imu", "'gyro_bias'"]),
        ({"leo": {"orbit_error_m": -1}}, ["leo.orbit_error_m"]),
        ({"waypoints": [[34, 108, 3000], [95, 108, 3000]]}, ["waypoints[1] latitude"]),
        ({"waypoints": [[34, 108, 3000], [34, 200, 3000]]}, ["waypoints[1] longitude"]),
        ({"waypoints": [[34, 108, 3000]]}, ["waypoints", "at least 2"]),
        ({"waypoints": [[34, 108], [34, 107, 0]]}, ["waypoints[0]"]),
        ({"speed_mps": 0}, ["speed_mps"]),
        ({"start_utc": "yesterday"}, ["start_utc"]),
        ({"init_error": {"pos_m": [1, 2]}}, ["init_error.pos_m"]),
        ({"leo": {"fix_rate_hz": 0}}, ["fix_rate_hz"]),
        ({"mask_deg": "40"}, ["mask_deg", "number"]),
        ({"leo": {"orbit_error_model": "shared"}}, ["leo.orbit_error_model", "independent, common", "'shared'"]),
    ],
)
def test_bad_scenarios_are_refused_naming_the_field(doc, words):
    with pytest.raises(InputError) as info:
        scenario_from_dict(doc, source="my.json")
    message = str(info.value)
    assert message.startswith("my.json")
    for word in words:
        assert word in message


def test_unknown_name_and_bad_json(tmp_path):
    with pytest.raises(InputError, match="neither a built-in"):
        load_scenario("paris-lyon")
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    with pytest.raises(InputError, match="not valid JSON"):
        load_scenario(bad)


def test_multi_constellation_keys_validated_and_round_tripped():
    doc = {"leo": {"constellations": ["starlink", "iridium"], "rx_freq_offsets_hz": {"iridium": -3},
                   "cn0_dbhz_by_family": {"iridium": 52}, "outage_s": [10, 70], "outage_max_sats": 2}}
    s = scenario_from_dict(doc)
    assert s.leo.constellations == ("starlink", "iridium") and s.leo.outage_s == (10.0, 70.0)
    assert s.leo.rx_freq_offsets_hz == {"iridium": -3.0} and s.leo.outage_max_sats == 2
    assert scenario_from_dict(json.loads(json.dumps(to_dict(s)))) == s


@pytest.mark.parametrize("leo, words", [
    ({"constellations": ["starlink", "globalstar"]}, ["globalstar", "starlink, oneweb, iridium, orbcomm"]),
    ({"constellations": []}, ["constellations", "non-empty"]),
    ({"constellations": ["oneweb", "oneweb"]}, ["twice"]),
    ({"rx_freq_offsets_hz": {"gps": 1.0}}, ["rx_freq_offsets_hz", "gps"]),
    ({"mask_deg_by_family": {"galileo": 15}}, ["mask_deg_by_family", "galileo", "iridium, oneweb, orbcomm, starlink"]),
    ({"mask_deg_by_family": {"starlink": 90}}, ["mask_deg_by_family.starlink", "90.0", "89.0"]),
    ({"mask_deg_by_family": {"starlink": -1}}, ["mask_deg_by_family.starlink", "-1.0"]),
    ({"mask_deg_by_family": {"iridium": 15}}, ["mask_deg_by_family", "'iridium'", "leo.constellations (starlink)"]),
    ({"constellations": ["starlink", "oneweb"], "mask_deg_by_family": {"orbcomm": 15}},
     ["mask_deg_by_family", "'orbcomm'", "(starlink, oneweb)"]),
    ({"outage_s": [100, 50]}, ["outage_s[1]"]),
    ({"outage_max_sats": 2.5}, ["outage_max_sats", "whole number"]),
])
def test_bad_multi_constellation_keys_name_the_field(leo, words):
    with pytest.raises(InputError) as exc:
        scenario_from_dict({"leo": leo}, source="f.json")
    assert all(w in str(exc.value) for w in words), str(exc.value)
    assert len(str(exc.value).splitlines()) == 1


def test_family_masks_default_to_the_scenario_mask():
    from leosop.apps.scenarios import family_masks_deg, mask_label

    s = scenario_from_dict({"mask_deg": 35, "leo": {"constellations": ["starlink", "iridium", "orbcomm"],
                                                    "mask_deg_by_family": {"iridium": 15, "orbcomm": 10.5}}})
    assert s.leo.mask_deg_by_family == {"iridium": 15.0, "orbcomm": 10.5}
    np.testing.assert_array_equal(family_masks_deg(s), [35.0, 15.0, 10.5])
    assert mask_label(s) == "35 deg (iridium 15, orbcomm 10.5)"
    assert mask_label(XIAN_BAOJI) == "40 deg"
    assert scenario_from_dict(json.loads(json.dumps(to_dict(s)))) == s


def test_bundled_scenarios_load_by_name_and_resolve_their_tle():
    from leosop.apps.scenarios import bundled_names

    assert {"xian-baoji", "xian-baoji-multi", "high-latitude", "urban-canyon", "outage"} <= set(bundled_names())
    s = load_scenario("high-latitude")
    assert s.tle == "$LEOSOP_DATA/tle/active_3le_2021-08-06_atqlong.txt" and s.mask_deg == 25.0
    assert load_scenario("urban-canyon").mask_deg == 60.0
    assert load_scenario("outage").leo.outage_s == (300.0, 480.0)


def test_narrowing_the_families_of_a_base_with_family_masks_is_allowed():
    # A study's cell {"leo": {"constellations": ["starlink"]}} on xian-baoji-multi: the base's
    # Iridium and Orbcomm masks stay in the spec, unused, rather than refusing the cell.
    base = load_scenario("xian-baoji-multi")
    s = scenario_from_dict({"leo": {"constellations": ["starlink"]}}, base=base)
    assert s.leo.constellations == ("starlink",) and s.leo.mask_deg_by_family == {"iridium": 15.0, "orbcomm": 15.0}
