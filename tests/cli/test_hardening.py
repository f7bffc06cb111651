"""The command line as a hostile user meets it (issue 13): option errors,
output paths, signals, warnings and all-or-nothing outputs."""

import errno
import http.server
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest

from leosop import fileio
from leosop.cli import COMMANDS, build_parser, main, tle

from tests.helpers import REPO_ROOT


#: A small recording: 10 ms of one satellite at 1 MS/s.
SMALL = ["--duration-s", "0.01", "--truth-step-s", "0.01", "--sample-rate-hz", "1e6", "--sat", "70002"]


def _run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def _one_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def _leftovers(root):
    """Hidden staging files or directories anywhere below ``root``."""
    return [p for p in root.rglob(".*") if ".part" in p.name]


@pytest.mark.parametrize("argv", [["visibility", "--bogus"], ["generate"], ["align", "--imu"],
                                  ["doppler", "x.sigmf-meta", "--method", "nope"]])
def test_option_errors_are_one_line(capsys, argv):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    line = _one_line(capsys.readouterr().err)
    assert "error:" in line and "usage:" not in line


@pytest.mark.parametrize("argv, line", [
    (["position", "m.csv", "--statc"],
     "leosop position: error: unrecognized arguments: --statc (did you mean --static?) (see leosop position --help)"),
    (["tle", "info", "x.tle", "--skip-bda"], "leosop tle info: error: unrecognized arguments: --skip-bda "
                                             "(did you mean --skip-bad?) (see leosop tle info --help)"),
    (["study", "gdop-map", "--out", "d", "--grid-degs=5"], "leosop study gdop-map: error: unrecognized arguments: "
     "--grid-degs=5 (did you mean --grid-deg?) (see leosop study gdop-map --help)"),
    (["visibility", "--xyzzy"],
     "leosop visibility: error: unrecognized arguments: --xyzzy (see leosop visibility --help)"),
])
def test_unknown_options_name_the_subcommand_and_the_nearest_option(capsys, argv, line):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2 and _one_line(capsys.readouterr().err) == line


def test_action_groups_show_only_options_that_work(capsys):
    """`study --out` was listed and ignored; `tle/study --json ACTION` was overwritten by the action's default."""
    parser = build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["study", "--help"])
    assert "--out" not in capsys.readouterr().out
    assert parser.parse_args(["study", "--json", "gdop-map", "--out", "d"]).json is True
    assert parser.parse_args(["study", "gdop-map", "--out", "d"]).json is False
    assert parser.parse_args(["tle", "--json", "info", "f"]).json is True


def test_an_interrupt_while_the_command_loads_is_one_line(capsys, monkeypatch):
    """Ctrl-C before the command runs (its modules loading, its options parsing) printed a traceback."""
    import leosop.cli as cli

    def interrupted(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    monkeypatch.setattr(sys, "argv", ["leosop", "visibility"])
    with pytest.raises(SystemExit) as info:
        cli.main_exit()
    assert info.value.code == 1 and capsys.readouterr().err == "leosop: interrupted\n"


def test_every_option_says_what_it_does():
    """`generate --agc-period-s` was listed with an empty help line: every option of every command has a help."""
    bare, seen, parsers = [], [], [("leosop", build_parser())]
    while parsers:
        name, parser = parsers.pop()
        seen.append(name)
        for action in parser._actions:  # argparse keeps no public list of a parser's actions
            if action.option_strings and not (action.help or "").strip():
                bare.append(f"{name} {action.option_strings[-1]}")
            if isinstance(action.choices, dict):
                parsers.extend((f"{name} {sub}", p) for sub, p in action.choices.items())
    assert {"leosop generate", "leosop study gdop-map", "leosop imu allan"} <= set(seen)  # the walk reaches them
    assert bare == []


@pytest.mark.parametrize("command", COMMANDS)
def test_a_command_alone_parses_as_in_the_full_parser(capsys, command):
    """`leosop CMD` registers only CMD's module (issue 24): its --help must be the full parser's, byte for byte."""
    helps = []
    for parser in (build_parser(), build_parser(command)):
        with pytest.raises(SystemExit):
            parser.parse_args([command, "--help"])
        helps.append(capsys.readouterr().out)
    assert helps[0] == helps[1] and f"usage: leosop {command}" in helps[0]


def test_visibility_loads_none_of_the_other_commands_dependencies():
    """The other commands' scipy.stats, pyfftw and dask cost ~1.2 s of CPU at every start (issue 24)."""
    code = ("import sys; from leosop.cli import main\n"
            "try: main(['visibility', '--help'])\nexcept SystemExit: pass\n"
            "print(sorted({'scipy.stats', 'pyfftw', 'dask', 'leosop.cli.position'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.splitlines()[-1] == "[]"


def test_negative_numbers_are_option_values(capsys):
    status, out, err = _run(capsys, "visibility", "--site", "-33.9,18.4,0", "--start", "2025-01-01T00:00:00Z",
                            "--duration-s", "10", "--step-s", "5", "--json")
    assert status == 0, err
    assert len(json.loads(out)["epochs_utc"]) == 3


def test_negative_sample_rate_is_refused_by_the_value_check(tmp_path, capsys):
    status, _, err = _run(capsys, "generate", "-o", str(tmp_path / "r.sigmf-meta"), "--sample-rate-hz", "-1e6")
    assert status == 2
    assert "--sample-rate-hz -1e+06: must be a positive number" in _one_line(err)


@pytest.mark.parametrize("argv, option", [
    (["generate", "-o", "r.sigmf-meta", "--rx-offset-hz", "nan"], "--rx-offset-hz"),
    (["visibility", "--duration-s", "inf"], "--duration-s"),
    (["visibility", "--mask-deg", "-inf"], "--mask-deg"),
    (["position", "m.csv", "--static", "--alt-m", "nan"], "--alt-m"),
    (["doppler", "x.iq", "--dtype", "cf32", "--sample-rate-hz", "1e999"], "--sample-rate-hz"),
])
def test_non_finite_option_values_are_refused(capsys, argv, option):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    line = _one_line(capsys.readouterr().err)
    assert option in line and "is not a finite number" in line


def test_negative_seed_is_bad_input(tmp_path, capsys):
    status, _, err = _run(capsys, "generate", "-o", str(tmp_path / "r.sigmf-meta"), "--seed", "-1")
    assert status == 2 and "--seed -1: must be an integer >= 0" in _one_line(err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("target, message", [
    ("file", "exists and is not a directory"),
    ("file/below", "is not a directory"),
    ("/dev/null", "exists and is not a directory"),
    ("", "empty path"),
])
def test_out_that_cannot_be_a_directory(tmp_path, capsys, target, message):
    (tmp_path / "file").write_text("keep")
    out = target if target.startswith("/") or not target else str(tmp_path / target)
    status, stdout, err = _run(capsys, "visibility", "--duration-s", "10", "--out", out)
    assert status == 2 and stdout == ""
    assert f"--out {out}".strip() in err or "--out ''" in err
    assert message in _one_line(err)
    assert (tmp_path / "file").read_text() == "keep"


@pytest.mark.parametrize("target, message", [
    ("dir", "exists and is not a regular file"),
    ("file/below.sigmf-meta", "is not a directory"),
    ("/dev/null", "exists and is not a regular file"),
    ("", "empty path"),
])
def test_output_file_that_cannot_be_written(tmp_path, capsys, target, message):
    (tmp_path / "file").write_text("keep")
    (tmp_path / "dir").mkdir()
    out = target if target.startswith("/") or not target else str(tmp_path / target)
    status, _, err = _run(capsys, "generate", "-o", out, "--duration-s", "0.01")
    assert status == 2 and message in _one_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir", "file"]


def test_errors_in_the_summary_are_caught(capsys, monkeypatch):
    def broken(doc):
        raise KeyError("epoch_min_utc")

    monkeypatch.setattr(tle, "summary", broken)
    status, out, err = _run(capsys, "tle", "info", str(fileio.Path(tle.__file__).parents[1] / "data" /
                                                        "starlink_walker.tle"))
    assert status == 1 and out == ""
    assert "internal error: KeyError" in _one_line(err)


def test_warnings_are_one_line_and_internals_hidden(capsys, monkeypatch):
    real_run = tle.run

    def noisy(args):
        np.log(np.zeros(2))  # numpy RuntimeWarning: not for the user
        warnings.warn("element sets are old\n  and this is the second line", UserWarning)
        return real_run(args)

    monkeypatch.delenv("LEOSOP_DEBUG", raising=False)
    monkeypatch.setattr(tle, "run", noisy)
    status, _, err = _run(capsys, "tle", "info", str(fileio.Path(tle.__file__).parents[1] / "data" /
                                                      "starlink_walker.tle"))
    assert status == 0
    assert _one_line(err) == "leosop tle: warning: element sets are old and this is the second line"


def test_atomic_write_errors_name_the_users_path(tmp_path):
    target = tmp_path / "out.csv"
    with pytest.raises(OSError) as info:
        with fileio.atomic_path(target) as tmp:
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp))
    assert info.value.filename == str(target) and info.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


def _strict(text):
    """Parse JSON as a strict (RFC 8259) reader does: NaN and Infinity are errors."""
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")
    return json.loads(text, parse_constant=refuse)


def test_json_files_are_strict(tmp_path):
    # Python's json writes NaN/Infinity as bare tokens that other parsers
    # refuse; the toolkit's JSON writer turns them (and numpy's) into null.
    doc = {"a": float("nan"), "b": [1.0, float("inf"), np.float64("-inf")], "c": np.array([np.nan, 2.5]),
           "d": np.int64(3)}
    fileio.write_json(tmp_path / "x.json", doc)
    fileio.write_json(tmp_path / "y.json", doc, compact=True)
    expected = {"a": None, "b": [1.0, None, None], "c": [None, 2.5], "d": 3}
    for name in ("x.json", "y.json"):
        assert _strict((tmp_path / name).read_text()) == expected


def _ready_reference(obj):
    """`fileio.json_ready` element by element, without its fast paths for flat lists."""
    if isinstance(obj, dict):
        return {str(k): _ready_reference(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_ready_reference(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _ready_reference(obj.tolist())
    return None if isinstance(obj, float) and not math.isfinite(obj) else obj


def test_json_ready_fast_paths_give_the_element_by_element_bytes():
    """Flat lists skip the per-element walk (issue 24); every mix of types must still come out the same."""
    doc = {"ids": ["44713", "STARLINK-1007"], "tuple": ("a", 1, True, None), "floats": [0.1, float("nan"), -0.0],
           "mixed": [1, 2.5, float("inf")], "numpy": [np.float64(np.nan), np.int64(7), "x"], "empty": [],
           "nested": [[float("-inf"), 1e300], ["a"], (np.array([1.5, np.nan]),)], 3: [False, 10 ** 400]}
    assert json.dumps(fileio.json_ready(doc), allow_nan=False) == json.dumps(_ready_reference(doc), allow_nan=False)


def test_staged_output_errors_name_the_file_in_out_dir(tmp_path):
    out = tmp_path / "new" / "out"
    with pytest.raises(OSError) as info:
        with fileio.atomic_outputs(out) as stage:
            raise OSError(errno.EIO, "I/O error", str(stage / "fig.png"))
    assert info.value.filename == str(out / "fig.png")
    assert list(tmp_path.iterdir()) == []  # the directories made for it are gone too


def test_atomic_files_all_or_nothing(tmp_path, monkeypatch):
    a, b = tmp_path / "d" / "a.bin", tmp_path / "b.json"
    real_replace = os.replace
    calls = []

    def second_fails(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(errno.EXDEV, "Invalid cross-device link", str(dst))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", second_fails)
    with pytest.raises(OSError):
        with fileio.atomic_files([a, b]) as (ta, tb):
            ta.write_bytes(b"data")
            tb.write_text("{}")
    assert calls == [a, b]  # in the order given: data first
    assert list(tmp_path.iterdir()) == []


def test_generate_leaves_nothing_when_a_later_step_fails(tmp_path, capsys, monkeypatch):
    from leosop.cli import generate

    def chunks(*args):
        yield np.zeros(1000, complex)
        raise RuntimeError("disk went away")

    monkeypatch.setattr(generate, "sample_chunks", chunks)
    status, _, err = _run(capsys, "generate", "-o", str(tmp_path / "rec" / "r.sigmf-meta"), *SMALL,
                          "--out", str(tmp_path / "out"))
    assert status == 1 and "disk went away" in _one_line(err)
    assert list(tmp_path.iterdir()) == []


def test_generate_outputs_together(tmp_path, capsys):
    meta = tmp_path / "r.sigmf-meta"
    status, _, err = _run(capsys, "generate", "-o", str(meta), *SMALL, "--out", str(tmp_path / "out"),
                          "--json")
    assert status == 0, err
    assert meta.with_suffix(".sigmf-data").stat().st_size == 8 * 10_000
    assert json.loads((tmp_path / "out" / "generate.json").read_text())["n_samples"] == 10_000
    assert _leftovers(tmp_path) == []


def test_generate_warns_about_old_element_sets(tmp_path, capsys):
    status, _, err = _run(capsys, "generate", "-o", str(tmp_path / "r.sigmf-meta"), *SMALL[:6], "--mask-deg", "10",
                          "--start", "2025-03-01T00:00:00Z")
    assert status == 0
    assert "warning: start 2025-03-01T00:00:00.000000Z is 59 days from the nearest element-set epoch" in err


def test_visibility_out_is_all_or_nothing(tmp_path, capsys, monkeypatch):
    from leosop.plots import sky

    def broken(*args, **kwargs):
        raise RuntimeError("no fonts")

    monkeypatch.setattr(sky, "plot_skyplot", broken)
    status, _, err = _run(capsys, "visibility", "--duration-s", "10", "--out", str(tmp_path / "vis"))
    assert status == 1 and "no fonts" in err
    assert list(tmp_path.iterdir()) == []


def test_align_refuses_a_log_without_gravity(tmp_path, capsys):
    path = tmp_path / "zero.imu"
    rows = ["0 0 0 0 0 0", "34.0 108.0 400 0 10 9.79", "0.1 0.1 0.1 100 100 100"] + ["0 0 0 0 0 0"] * 300
    path.write_text("\n".join(rows) + "\n")
    status, _, err = _run(capsys, "align", "--imu", str(path))
    assert status == 2 and "mean specific force 0 m/s^2 is not gravity" in _one_line(err)


def test_doppler_center_hz_zero_is_refused(tmp_path, capsys):
    raw = tmp_path / "x.iq"
    raw.write_bytes(bytes(8 * 10_000))
    status, _, err = _run(capsys, "doppler", str(raw), "--dtype", "cf32", "--sample-rate-hz", "1e6",
                          "--center-hz", "0")
    assert status == 2 and "--center-hz 0: must be a positive number" in _one_line(err)


class _Garbage(http.server.BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 (http.server's name)
        body = b"this is not an element set\n"
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


def test_failed_tle_fetch_leaves_no_directory(tmp_path, capsys):
    server = http.server.HTTPServer(("127.0.0.1", 0), _Garbage)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        status, _, err = _run(capsys, "tle", "fetch", "starlink", "-o", str(tmp_path / "new" / "dir" / "s.tle"),
                              "--url", f"http://127.0.0.1:{server.server_port}/gp.php")
    finally:
        server.shutdown()
    assert status == 1 and "do not parse" in _one_line(err)
    assert list(tmp_path.iterdir()) == []


def test_sigterm_is_cleaned_up_like_sigint(tmp_path):
    meta = tmp_path / "long.sigmf-meta"
    proc = subprocess.Popen([sys.executable, "-m", "leosop", "generate", "-o", str(meta), "--duration-s", "60",
                             "--sample-rate-hz", "1e6", "--sat", "70002"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not _leftovers(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert _leftovers(tmp_path), "the staged data file never appeared"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1 and err.strip().splitlines()[-1] == "leosop generate: interrupted"
    assert list(tmp_path.iterdir()) == []


def test_no_command_is_one_line(capsys):
    status, _, err = _run(capsys)
    assert status == 2 and "give a command: visibility, tle" in _one_line(err)


REC = "signals/starlink_xian_snapshots.sigmf-meta"


@pytest.mark.parametrize("argv, message", [
    (["visibility", "--start", "9999-01-01T00:00:00Z"], "outside the years 1678..2261"),
    (["visibility", "--duration-s", "1e300"], "1e+300 epochs is too many"),
    (["generate", "-o", "r.sigmf-meta", "--sample-rate-hz", "1e300"], "--sample-rate-hz 1e+300: at most 1e+10"),
    (["generate", "-o", "r.sigmf-meta", "--duration-s", "1e300"], "2.5e+306 samples; at most 1e+11"),
    (["generate", "-o", "r.sigmf-meta", "--cn0-dbhz", "1e300"], "--cn0-dbhz 1e+300: must be in [-20, 100] dB-Hz"),
    (["generate", "-o", "r.sigmf-meta", "--rx-offset-hz", "1e300"], "must be within +-1.25e+06 Hz"),
    (["generate", "-o", "r.sigmf-meta", "--orbit-error-along-m", "1e300"], "in [0, 100000] m"),
    (["doppler", REC, "--max-doppler-hz", "1e300"], "--max-doppler-hz 1e+300: must be in (0, 1e+07] Hz"),
    (["doppler", REC, "--max-rate-hz-per-s", "1e300"], "--max-rate-hz-per-s 1e+300: must be in [0, 1e+06]"),
    (["doppler", REC, "--resolution-hz", "1e-300"], "--resolution-hz 1e-300: must be in [1e-09, 1000] Hz"),
    (["doppler", REC, "--block-s", "1e300"],
     "--block-s 1e+300 is longer than the recording signals/starlink_xian_snapshots.sigmf-data (600000 samples"),
])
def test_absurd_option_values_are_refused(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(REPO_ROOT)
    argv = [str(tmp_path / a) if a.endswith(".sigmf-meta") and a != REC else a for a in argv]
    status, _, err = _run(capsys, *argv)
    assert status == 2 and message in _one_line(err)
    assert list(tmp_path.iterdir()) == []


def test_generate_with_satellites_below_the_horizon(tmp_path, capsys):
    status, _, err = _run(capsys, "generate", "-o", str(tmp_path / "r.sigmf-meta"), *SMALL,
                          "--start", "2025-01-01T00:00:00Z")
    assert status == 2 and "--sat 70002: no satellite is above the horizon" in _one_line(err)


def _absurd_doppler_csv(path):
    """Eight satellites of one epoch around the Earth, states given, every Doppler 1e300 Hz."""
    az = 2 * np.pi * np.arange(8) / 8
    pos = np.stack([7.0e6 * np.cos(az), 7.0e6 * np.sin(az), 1.0e6 * (np.arange(8) - 4)], axis=1)
    vel = np.stack([-7.5e3 * np.sin(az), 7.5e3 * np.cos(az), np.zeros(8)], axis=1)
    rows = [f"0,{70000 + k},1e300," + ",".join(f"{v:.3f}" for v in (*pos[k], *vel[k])) for k in range(8)]
    path.write_text("t_s,sat_id,doppler_hz,x_sv_m,y_sv_m,z_sv_m,vx_sv_mps,vy_sv_mps,vz_sv_mps\n" + "\n".join(rows))
    return str(path)


@pytest.mark.parametrize("mode", [[], ["--static"]])
def test_position_refuses_to_report_nan_fixes(tmp_path, capsys, mode):
    # Before: "1 fix(es)" of NaN coordinates, exit 0.
    meas = _absurd_doppler_csv(tmp_path / "absurd.csv")
    status, out, err = _run(capsys, "position", meas, *mode, "--out", str(tmp_path / "out"))
    assert status == 2 and out == ""
    assert "absurd.csv: no finite fix from 1 solve(s) (not_converged); check the doppler_hz values" in _one_line(err)
    assert not (tmp_path / "out").exists() and _leftovers(tmp_path) == []


@pytest.mark.parametrize("init, message", [
    ("34,108,1e12", "--init: altitude 1e+12 m is outside [-12000, 1e8]"),
    ("34,108", "--init '34,108': expected LAT_DEG,LON_DEG,ALT_M (three numbers)"),
    ("95,108,0", "--init: latitude 95 deg is outside [-90, 90]"),
])
def test_position_init_is_checked_as_a_site(tmp_path, capsys, init, message):
    meas = _absurd_doppler_csv(tmp_path / "m.csv")
    status, _, err = _run(capsys, "position", meas, "--init", init, "--out", str(tmp_path / "out"))
    assert status == 2 and message in _one_line(err)
    assert not (tmp_path / "out").exists()


def test_scenario_file_not_utf8_is_bad_input(tmp_path, capsys):
    path = tmp_path / "latin1.json"
    path.write_bytes('{"name": "caf\u00e9"}'.encode("latin-1"))
    status, _, err = _run(capsys, "simulate", "--scenario", str(path), "--out", str(tmp_path / "out"))
    assert status == 2
    assert f"{path}: not UTF-8 text (byte 0xe9 at offset 13)" in _one_line(err)
    assert not (tmp_path / "out").exists()


def test_simulate_out_is_all_or_nothing(tmp_path, capsys, monkeypatch):
    from leosop.plots import simulation

    def broken(*args, **kwargs):
        raise RuntimeError("no fonts")

    # The last figure fails after the CSV, the JSON and three figures are made: none of them may stay.
    monkeypatch.setattr(simulation, "gdop_figure", broken)
    scenario = tmp_path / "short.json"
    scenario.write_text(json.dumps({"name": "short", "duration_s": 5.0}))
    status, _, err = _run(capsys, "simulate", "--scenario", str(scenario), "--level", "measurement",
                          "--out", str(tmp_path / "out"))
    assert status == 1 and "no fonts" in err
    assert not (tmp_path / "out").exists() and _leftovers(tmp_path) == []


def test_export_of_a_file_not_utf8_names_it(tmp_path, capsys):
    path = tmp_path / "latin1.csv"
    path.write_bytes("sat_id,rise_utc\ncaf\u00e9,x\n".encode("latin-1"))
    status, _, err = _run(capsys, "export", str(path), "--out", str(tmp_path / "out"))
    assert status == 2 and f"{path}: not UTF-8 text (a byte 0xe9)" in _one_line(err)
    assert not (tmp_path / "out").exists()


def test_gdop_map_without_any_fix_reports_n_a(tmp_path, capsys):
    # An 89 deg mask: no cell ever sees 7 satellites. The summary crashed on the null median (exit 1).
    status, out, err = _run(capsys, "study", "gdop-map", "--duration-s", "600", "--step-s", "600", "--grid-deg", "90",
                            "--mask-deg", "89", "--scheduler", "serial", "--out", str(tmp_path / "map"))
    assert status == 0, err
    assert "cell-epochs with a Doppler fix (>= 7): 0.0%; median Doppler GDOP n/a" in out
    assert (tmp_path / "map" / "gdop_maps.png").is_file()
