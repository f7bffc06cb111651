"""Monte Carlo study specs: one-line errors naming the field, the bundled specs, the seeds."""

import json

import numpy as np
import pytest

from leosop.chunkstore import PACKAGE_DIR, code_digest
from leosop.errors import InputError
from leosop.apps.montecarlo import IMU_GRADES, METRICS, bundled_specs, load_spec, run_seeds, spec_from_dict, to_dataset
from leosop.apps.montecarlo import spec as spec_module
from leosop.apps.montecarlo.parameters import apply
from leosop.constellations import REGISTRY
from leosop.apps.scenarios import XIAN_BAOJI, load_scenario
from leosop.apps.repro.fusion_tables import PAPER_TABLE5, PAPER_TABLE6

GOOD = {"fixed": {"level": "measurement"}, "parameters": {"correction_period_s": [1, 30]}, "n_seeds": 2}


def _with(**changes):
    doc = json.loads(json.dumps(GOOD))
    doc.update(changes)
    return doc


@pytest.mark.parametrize("doc, message", [
    (_with(parameters={"foo_s": [1]}), "s.json: parameters: unknown parameter 'foo_s'"),
    (_with(fixed={"cn0": 40}), "s.json: fixed: unknown parameter 'cn0'"),
    (_with(parameters={"correction_period_s": []}), "parameters.correction_period_s: expected a non-empty list"),
    (_with(parameters={}), "parameters: expected at least one parameter"),
    (_with(parameters={"coupling": ["loose", "medium"]}), "parameters.coupling[1]: expected one of loose, tight"),
    (_with(parameters={"correction_period_s": [1, 0]}), "parameters.correction_period_s[1]: 0 must be > 0 s"),
    (_with(parameters={"cn0_dbhz": [45, 150]}), "parameters.cn0_dbhz[1]: scenario.leo.cn0_dbhz: 150.0 is outside"),
    (_with(parameters={"mask_deg": [10, 10.0]}), "parameters.mask_deg: values repeat"),
    (_with(fixed={"coupling": "loose"}, parameters={"coupling": ["tight"]}), "'coupling' is both fixed and swept"),
    (_with(fixed={"gyro_bias_deg_per_h": 1.0}, parameters={"imu_grade": ["mems"]}),
     "imu_grade and gyro_bias_deg_per_h both set the IMU errors"),
    (_with(n_seeds=0), "n_seeds: expected an integer >= 1, got 0"),
    (_with(runs_per_chunk=2.5), "runs_per_chunk: expected an integer >= 1"),
    (_with(seeds=3), "s.json: unknown key 'seeds'"),
    ({"parameters": {"coupling": ["loose"]}}, "s.json: missing key 'n_seeds'"),
    (_with(scenario={"speed": 100}), "s.json: scenario: unknown key 'speed'"),
    (_with(tle="missing.tle"), "s.json: tle: 'missing.tle' is not a file"),
    (_with(parameters={"constellations": [["starlink"], ["starlink", "galileo"]]}),
     "parameters.constellations[1]: scenario.leo.constellations: unknown constellation 'galileo'; "
     "expected one of starlink, oneweb, iridium, orbcomm"),
    (_with(parameters={"constellations": [[]]}), "parameters.constellations[0]: scenario.leo.constellations: "
                                                 "expected a non-empty list of constellation names"),
    (_with(parameters={"constellations": ["starlink"]}), "parameters.constellations[0]: scenario.leo.constellations: "
                                                         "expected a non-empty list"),
    (_with(parameters={"constellations": [["oneweb"], ["oneweb"]]}), "parameters.constellations: values repeat"),
    (_with(fixed={"constellations": ["iridium", "iridium"]}), "fixed.constellations: scenario.leo.constellations: "
                                                              "a constellation is listed twice"),
])
def test_bad_specs_one_line_naming_the_field(doc, message, tmp_path):
    with pytest.raises(InputError) as err:
        spec_from_dict(doc, source="s.json", base_dir=tmp_path)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_spec_file_errors(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{\"n_seeds\": 2,")
    with pytest.raises(InputError, match=r"bad.json: not valid JSON"):
        load_spec(bad)
    with pytest.raises(InputError,
                       match=r"nope.json: no such spec file \(bundled specs: cn0_imu, families, table5, table6\)"):
        load_spec(tmp_path / "nope.json")


def test_grid_cells_and_scenarios():
    spec = spec_from_dict(_with(parameters={"cn0_dbhz": [35, 55], "imu_grade": ["navigation", "mems"]}))
    assert spec.shape == (2, 2, 2) and spec.n_runs == 8 and spec.name == "<dict>"
    cells = spec.cells()
    assert cells[1] == {"level": "measurement", "cn0_dbhz": 35.0, "imu_grade": "mems"}  # C order, fixed included
    scenario, options = apply(XIAN_BAOJI, cells[1], "test")
    assert options == {"level": "measurement"}
    assert scenario.leo.cn0_dbhz == 35.0
    assert scenario.imu.gyro_bias_deg_per_h == IMU_GRADES["mems"]["gyro_bias_deg_per_h"]
    assert scenario.imu.rate_hz == XIAN_BAOJI.imu.rate_hz and scenario.waypoints == XIAN_BAOJI.waypoints


def test_constellation_mix_is_a_parameter():
    mixes = [["starlink"], ["starlink", "oneweb", "iridium", "orbcomm"]]
    spec = spec_from_dict(_with(parameters={"constellations": mixes, "coupling": ["loose", "tight"]}))
    assert spec.axes["constellations"] == (("starlink",), ("starlink", "oneweb", "iridium", "orbcomm"))
    scenario, options = apply(XIAN_BAOJI, spec.cells()[3], "test")
    assert scenario.leo.constellations == ("starlink", "oneweb", "iridium", "orbcomm")
    assert options["coupling"] == "tight"
    ds = to_dataset(spec, np.zeros((spec.n_runs, len(METRICS))))
    assert list(ds["constellations"].values) == ["starlink", "starlink+oneweb+iridium+orbcomm"]
    assert json.loads(ds.attrs["spec"])["parameters"]["constellations"] == mixes


def test_navigation_grade_is_the_papers_table1():
    nav = IMU_GRADES["navigation"]
    assert all(getattr(XIAN_BAOJI.imu, k) == v for k, v in nav.items())


def test_bundled_specs_are_the_papers_grids():
    specs = {name: load_spec(name) for name in bundled_specs()}
    t5, t6, cn0, fam = specs["table5"], specs["table6"], specs["cn0_imu"], specs["families"]
    assert list(t5.axes["correction_period_s"]) == sorted(PAPER_TABLE5) and t5.axes["coupling"] == ("loose", "tight")
    assert t5.fixed == {"level": "measurement", "orbit_error_m": 1.0}
    assert list(t6.axes["orbit_error_m"]) == sorted(PAPER_TABLE6) and t6.fixed["correction_period_s"] == 1.0
    assert set(t6.axes["orbit_error_model"]) == {"independent", "common"}
    assert cn0.axes["imu_grade"] == tuple(IMU_GRADES) and len(cn0.axes["cn0_dbhz"]) == 5
    assert fam.axes["constellations"] == (("starlink",), tuple(REGISTRY)) and fam.axes["coupling"] == ("loose", "tight")
    assert fam.scenario == load_scenario("xian-baoji-multi")  # each family its own receiver clock
    assert {s.n_seeds for s in specs.values()} == {20} and all(s.scenario == XIAN_BAOJI for s in (t5, t6, cn0))


def test_run_seeds_from_one_seed_sequence():
    small, large = (spec_from_dict(_with(n_seeds=n, seed=7)) for n in (3, 5))
    np.testing.assert_array_equal(run_seeds(small), run_seeds(large)[:3])  # adding seeds extends a study
    assert len(set(run_seeds(large))) == 5 and run_seeds(large).max() < 2**31  # NetCDF 3 int32
    assert not np.array_equal(run_seeds(small), run_seeds(spec_from_dict(_with(n_seeds=3, seed=8))))


def test_digest_follows_what_the_results_depend_on():
    a = spec_from_dict(GOOD)
    assert a.digest() == spec_from_dict(GOOD).digest()
    assert a.digest() != spec_from_dict(_with(n_seeds=3)).digest()
    assert a.digest() != spec_from_dict(_with(scenario={"mask_deg": 30})).digest()


def test_digest_follows_the_source_code(monkeypatch):
    before = spec_from_dict(GOOD).digest()
    monkeypatch.setattr(spec_module, "code_digest", lambda: "0" * 64)  # as if a module had changed
    assert spec_from_dict(GOOD).digest() != before


def test_code_digest_sees_every_source_change(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "notes.txt").write_text("not code")
    digests = [code_digest(tmp_path)]
    code_digest.cache_clear()
    (tmp_path / "notes.txt").write_text("still not code")
    assert code_digest(tmp_path) == digests[0]  # only Python source counts
    for change in (lambda: (tmp_path / "sub" / "b.py").write_text("y = 3\n"),
                   lambda: (tmp_path / "c.py").write_text(""),
                   lambda: (tmp_path / "c.py").rename(tmp_path / "sub" / "c.py")):
        change()
        code_digest.cache_clear()
        digests.append(code_digest(tmp_path))
    assert len(set(digests)) == 4
    code_digest.cache_clear()
    assert code_digest() == code_digest(PACKAGE_DIR) and len(code_digest()) == 64
