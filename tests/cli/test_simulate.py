"""``leosop simulate``: the JSON contract (DESIGN.md 4.1), output files and bad inputs, on short flights."""

import csv
import json

import pytest

from leosop.cli import main

# DESIGN.md 4.1: every key present, nothing renamed.
CONTRACT = {
    "scenario": None, "duration_s": None,
    "ins_only": {"pos_err_mean_m", "vel_err_mean_mps"},
    "leo_fix": {"pos_err_mean_m", "vel_err_mean_mps", "n_fixes"},
    "fused": {"pos_err_mean_m", "vel_err_mean_mps", "pos_err_rms_m", "availability"},
    "visible": {"min", "max"}, "gdop": {"max"}, "runtime_s": None,
}


def _scenario(tmp_path, name="short", **changes):
    doc = {"name": name, "duration_s": 60.0}
    doc.update(changes)
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(doc))
    return str(path)


def _run(capsys, *argv):
    status = main(["simulate", *argv])
    out, err = capsys.readouterr()
    return status, out, err


def test_json_contract_files_and_figures(tmp_path, capsys):
    out_dir = tmp_path / "out"
    status, out, _ = _run(capsys, "--scenario", _scenario(tmp_path), "--level", "measurement", "--json",
                          "--out", str(out_dir))
    assert status == 0
    doc = json.loads(out)
    assert set(doc) == set(CONTRACT) | {"run"}  # "run": an extension naming what was run
    assert doc["run"] == {"coupling": "loose", "level": "measurement", "seed": 0, "correction_period_s": 1.0,
                          "constellations": ["starlink"]}
    for key, sub in CONTRACT.items():
        if sub is not None:
            assert sub <= set(doc[key])  # the contract's keys; extensions may be added
    assert set(doc["fused"]) - CONTRACT["fused"] == {"aided_fraction", "n_updates"}
    assert doc["scenario"] == "short" and doc["duration_s"] == 60.0
    assert doc["fused"]["availability"] == 1.0
    # A fix every second, each taken: every epoch after the start is aided.
    assert doc["fused"]["aided_fraction"] == 1.0 and doc["fused"]["n_updates"] == 60
    # The default start sees 7-11 satellites in the first minute (tools/search_start_time.py).
    assert doc["visible"]["min"] >= 7 and doc["leo_fix"]["n_fixes"] == 60
    # Fusion beats both of its inputs by a wide margin even in one minute.
    assert doc["fused"]["pos_err_mean_m"] < min(doc["ins_only"]["pos_err_mean_m"], doc["leo_fix"]["pos_err_mean_m"])
    assert json.loads((out_dir / "metrics.json").read_text()) == doc
    with open(out_dir / "solution.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 61 and float(rows[-1]["t_s"]) == 60.0
    assert {"truth_lat_deg", "ins_lat_deg", "fix_lat_deg", "fused_lat_deg", "sigma_e_m", "sigma_vu_mps"} <= set(rows[0])
    for fig in ("trajectory.png", "errors_3d.png", "visible.png", "gdop.png"):
        assert (out_dir / fig).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_signal_level_short_run_matches_measurement_level(tmp_path, capsys):
    # 20 s at signal level (about 180 pilot blocks) against the same seed at
    # measurement level: the IMU and satellite errors are the same streams, so
    # the fused errors must agree to within the estimator noise's effect
    # (a few metres after 20 s of 100 m initial error).
    path = _scenario(tmp_path, duration_s=20.0)
    docs = []
    for level in ("signal", "measurement"):
        status, out, _ = _run(capsys, "--scenario", path, "--level", level, "--json", "--seed", "3")
        assert status == 0
        docs.append(json.loads(out))
    assert docs[0]["leo_fix"]["n_fixes"] == docs[1]["leo_fix"]["n_fixes"] == 20
    assert docs[0]["ins_only"] == docs[1]["ins_only"]
    assert abs(docs[0]["fused"]["pos_err_mean_m"] - docs[1]["fused"]["pos_err_mean_m"]) < 5.0


def test_human_summary_prints_metrics_and_runtime(tmp_path, capsys):
    status, out, _ = _run(capsys, "--scenario", _scenario(tmp_path, duration_s=10.0), "--level", "measurement")
    assert status == 0
    assert "Starlink/INS" in out and "INS only" in out and "runtime" in out
    assert out.startswith("scenario short (loose coupling, measurement level, seed 0, correction every 1 s): 10 s")


@pytest.mark.parametrize(
    "changes, argv, words",
    [
        ({"colour": "blue"}, [], ["'colour'"]),
        ({"waypoints": [[34.3, 108.9, 3000], [34.3, 190.0, 3000]]}, [], ["waypoints[1] longitude"]),
        ({}, ["--correction-period-s", "0"], ["--correction-period-s"]),
        ({}, ["--correction-period-s", "-5"], ["--correction-period-s"]),
        ({}, ["--orbit-error-m", "-1"], ["--orbit-error-m"]),
        ({"leo": {"fix_rate_hz": 3}}, [], ["leo.fix_rate_hz=3", "even number"]),
    ],
)
def test_bad_input_exits_2_naming_the_problem(tmp_path, capsys, changes, argv, words):
    status, out, err = _run(capsys, "--scenario", _scenario(tmp_path, **changes), "--level", "measurement", *argv)
    assert status == 2 and out == ""
    for word in words:
        assert word in err


def test_no_satellite_visible_still_writes_the_ins_result(tmp_path, capsys):
    # An 88 deg mask: nobody is ever that high along this flight.
    out_dir = tmp_path / "out"
    status, out, err = _run(capsys, "--scenario", _scenario(tmp_path, duration_s=10.0, mask_deg=88.0),
                            "--level", "measurement", "--json", "--out", str(out_dir))
    assert status == 0
    assert "warning: short: no satellite rises above the 88 deg mask" in err
    doc = json.loads(out)
    assert doc["leo_fix"]["n_fixes"] == 0 and doc["visible"]["max"] == 0 and doc["gdop"]["max"] is None
    # Available (the INS always gives an output) but never aided, and the summary says so.
    assert doc["fused"]["availability"] == 1.0
    assert doc["fused"]["aided_fraction"] == 0.0 and doc["fused"]["n_updates"] == 0
    assert doc["fused"]["pos_err_mean_m"] == pytest.approx(doc["ins_only"]["pos_err_mean_m"], rel=1e-9)
    assert (out_dir / "solution.csv").exists()
    from leosop.cli.simulate import summary

    text = summary(doc)
    assert "LEO fixes     none" in text and "no LEO fix, no update: the INS alone" in text


def test_aided_fraction_with_a_correction_every_30_s(tmp_path, capsys):
    # 60 s with a fix every second and a correction due every 30 s: updates at 30 and 60 s;
    # epochs 30..60 are within 30 s of an update and 1..29 precede the first, so 31 of the
    # 60 epochs after the start are aided (closed form; exact).
    status, out, _ = _run(capsys, "--scenario", _scenario(tmp_path), "--level", "measurement", "--json",
                          "--correction-period-s", "30")
    assert status == 0
    fused = json.loads(out)["fused"]
    assert fused["n_updates"] == 2 and fused["aided_fraction"] == pytest.approx(31 / 60, abs=1e-12)
    assert fused["availability"] == 1.0


def test_start_far_from_the_element_sets_warns_with_the_age(tmp_path, capsys):
    # The bundled element sets have epoch 2025-01-01T00:00Z: 59 days before.
    status, _, err = _run(capsys, "--scenario", _scenario(tmp_path, duration_s=5.0, start_utc="2025-03-01T00:00:00Z"),
                          "--level", "measurement", "--json")
    assert status == 0
    assert "warning: scenario start 2025-03-01T00:00:00.000000Z is 59 days from the nearest element-set epoch" in err
