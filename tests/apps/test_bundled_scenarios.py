"""Every bundled scenario finds its files after a plain install, from any directory.

A bundled scenario's files are either package data (the bundled skies) or
real data sets named ``$LEOSOP_DATA/...`` (:mod:`leosop.datadir`), found only
through ``--data DIR`` or the environment variable: never through a path
relative to the package, which under a wheel install points into the venv
(issue 20: ``simulate --scenario high-latitude`` looked for
``<venv>/lib/shared/...``).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from leosop.datadir import ENV_VAR, PREFIX, resolve_data_ref
from leosop.errors import InputError
from leosop.apps.repro import multi
from leosop.apps.scenarios import BUNDLED_DIR, bundled_names, load_scenario, scenario_tle

from tests.helpers import DATA_DIR, REPO_ROOT, data_path


HIGH_LATITUDE_TLE = ("tle", "active_3le_2021-08-06_atqlong.txt")


@pytest.fixture
def no_data_folder(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)


@pytest.mark.parametrize("name", bundled_names())
def test_every_bundled_scenario_names_only_package_data_or_the_data_folder(name):
    s = load_scenario(name)
    # None: the bundled sky, package data; otherwise a file of the data folder.
    assert s.tle is None or s.tle.startswith(PREFIX), s.tle
    if (BUNDLED_DIR / f"{name}.json").exists():
        text = (BUNDLED_DIR / f"{name}.json").read_text()
        assert ".." not in text and "shared" not in text


def test_without_the_data_folder_a_scenario_needing_it_stops_with_one_line(no_data_folder):
    s = load_scenario("high-latitude")
    with pytest.raises(InputError) as exc:
        scenario_tle(s)
    msg = str(exc.value)
    assert len(msg.splitlines()) == 1
    assert "high-latitude" in msg and "data_dir" in msg and ENV_VAR in msg and HIGH_LATITUDE_TLE[1] in msg
    assert multi.available("urban-canyon") is None and multi.available("high-latitude") == msg


def test_a_data_folder_without_the_file_is_named(tmp_path, no_data_folder):
    with pytest.raises(InputError, match=f"{tmp_path}.*not found.*from data_dir"):
        resolve_data_ref(PREFIX + "tle/x.tle", data_dir=tmp_path, needed_by="test")


def test_the_data_folder_comes_from_the_option_or_the_environment(monkeypatch):
    path = data_path(*HIGH_LATITUDE_TLE)
    s = load_scenario("high-latitude")
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert Path(scenario_tle(s, DATA_DIR)) == path
    monkeypatch.setenv(ENV_VAR, str(DATA_DIR))
    assert Path(scenario_tle(s)) == path
    assert multi.available("high-latitude") is None


def test_multi_warns_and_says_why_when_it_skips_a_row(monkeypatch, no_data_folder):
    monkeypatch.setattr(multi, "SCENARIOS", ("high-latitude",))
    with pytest.warns(UserWarning, match=f"row high-latitude skipped.*{ENV_VAR}"):
        doc = multi.multi(scheduler="serial")
    (row,) = doc["rows"]
    assert row["scenario"] == "high-latitude" and ENV_VAR in row["skipped"]


def _cli(args, env_extra=None, cwd=None):
    env = {k: v for k, v in os.environ.items() if k != ENV_VAR}
    env["PYTHONPATH"] = str(REPO_ROOT)
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-m", "leosop", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


def test_simulate_high_latitude_from_another_directory(tmp_path):
    out = _cli(["simulate", "--scenario", "high-latitude", "--level", "measurement"], cwd=tmp_path)
    assert out.returncode == 2 and out.stdout == ""
    (line,) = out.stderr.splitlines()
    assert "--data DIR" in line and ENV_VAR in line
    data_path(*HIGH_LATITUDE_TLE)
    out = _cli(["simulate", "--scenario", "high-latitude", "--level", "measurement", "--json", "--data",
                str(DATA_DIR)], cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    # README of the bundled scenarios: the 2021 sky at 68 N holds 7-10 OneWeb and 0-3 Iridium NEXT above
    # 25 deg, so a fix every second and a fused error of metres (20-seed mean 8.45 m); 30 m would
    # mean the wrong sky or no fixes, and the INS alone drifts about 1 km.
    assert doc["leo_fix"]["n_fixes"] == 900 and doc["visible"]["min"] >= 7
    assert doc["fused"]["pos_err_mean_m"] < 30.0 < 500.0 < doc["ins_only"]["pos_err_mean_m"]


@pytest.mark.parametrize("coupling", ["loose", "tight"])
def test_urban_canyon_says_how_much_was_aided(capsys, coupling):
    # The 60 deg canyon holds 0-3 Starlink satellites (scenario README): never the 7 of a snapshot
    # fix, so the loose filter has nothing to take and is the INS alone (availability 1.0 all the
    # same), while the tight filter takes the Doppler of most epochs.
    from leosop.cli import main
    from leosop.cli.simulate import summary

    assert main(["simulate", "--scenario", "urban-canyon", "--level", "measurement", "--coupling", coupling,
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    fused = doc["fused"]
    assert doc["leo_fix"]["n_fixes"] == 0 and fused["availability"] == 1.0
    if coupling == "loose":
        assert fused["aided_fraction"] == 0.0 and fused["n_updates"] == 0
        assert fused["pos_err_mean_m"] == pytest.approx(doc["ins_only"]["pos_err_mean_m"], rel=1e-9)
        assert "the INS alone" in summary(doc)
    else:
        # Epochs with at least one satellite above 60 deg: most of the flight, not all of it.
        assert 0.5 < fused["aided_fraction"] < 1.0 and fused["n_updates"] > 400
        assert "the INS alone" not in summary(doc)
