"""`leosop visibility` and `leosop tle`: the JSON contract, bad input, and fetching."""

import csv
import http.server
import json
import subprocess
import sys
import threading

import pytest

from leosop.cli import main
from leosop.orbits import DEFAULT_TLE
from tests.helpers import peak_rss_mb


def run_cli(*args):
    proc = subprocess.run([sys.executable, "-m", "leosop", *args], capture_output=True, text=True)
    return proc.returncode, proc.stdout, proc.stderr


def test_json_contract_and_outputs(tmp_path, capsys):
    code = main(["visibility", "--start", "2025-01-01T00:00:00Z", "--duration-s", "300", "--step-s", "5",
                 "--mask-deg", "40", "--json", "--out", str(tmp_path)])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    assert {"epochs_utc", "n_visible", "gdop", "visible_ids"} <= set(doc)
    assert doc["per_epoch"]["in_document"] and doc["n_epochs"] == 61
    assert doc["stats"]["n_visible_max"] == max(doc["n_visible"])
    assert len(doc["epochs_utc"]) == 61 and doc["epochs_utc"][1] == "2025-01-01T00:00:05.000000Z"
    for n, g, ids in zip(doc["n_visible"], doc["gdop"], doc["visible_ids"]):
        assert n == len(ids) and all(isinstance(s, str) and s.isdigit() for s in ids)
        assert (g is None) == (n < 7)
    for name in ("visibility.json", "visibility.csv", "passes.csv", "visibility.png", "skyplot.png"):
        assert (tmp_path / name).stat().st_size > 0
    text = (tmp_path / "visibility.json").read_text()
    assert json.loads(text) == doc
    assert text.count("\n") == 1 and ", " not in text  # compact: the per-epoch lists make it large
    # The CSV's Doppler GDOP column has the JSON's (and gdop_map.nc's) name and values (4 decimals written).
    with open(tmp_path / "visibility.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["time_utc"] for r in rows] == doc["epochs_utc"]
    for r, g in zip(rows, doc["gdop"]):
        assert (r["gdop"] == "") if g is None else float(r["gdop"]) == pytest.approx(g, abs=5e-5)
    # passes.csv is the visible sets' encoding the document points at beyond --json-max-epochs: a satellite is
    # visible at every epoch from rise to set inclusive.
    with open(tmp_path / "passes.csv") as fh:
        passes = list(csv.DictReader(fh))
    assert len(passes) == doc["n_passes"] > 0
    from_passes = [sorted(p["sat_id"] for p in passes if p["rise_utc"] <= e <= p["set_utc"]) for e in doc["epochs_utc"]]
    assert from_passes == [sorted(ids) for ids in doc["visible_ids"]]


def test_default_start_is_the_median_element_set_epoch_to_the_minute(capsys):
    # The bundled set (starlink_walker.tle) has every epoch at 2025-01-01T00:00Z (tle info says so); a median in the
    # wrong datetime unit once put the start in 2111.
    code = main(["visibility", "--duration-s", "60", "--step-s", "60", "--json"])
    assert code == 0
    assert json.loads(capsys.readouterr().out)["start_utc"] == "2025-01-01T00:00:00.000000Z"


def test_sub_second_steps_print_whole_instants(capsys):
    # 3 x 0.3 s in floating point is 0.8999999999 s: the epoch is 00.900000, neither 00.899999 nor 1 ns early.
    assert main(["visibility", "--start", "2025-01-01T00:00:00Z", "--duration-s", "1", "--step-s", "0.3",
                 "--json"]) == 0
    epochs = json.loads(capsys.readouterr().out)["epochs_utc"]
    assert epochs == [f"2025-01-01T00:00:00.{k * 300_000:06d}Z" for k in range(4)]


@pytest.mark.parametrize("args, message", [
    (["--site", "91,0,0"], "latitude 91 deg is outside"),
    (["--site", "10,20"], "expected LAT_DEG,LON_DEG,ALT_M"),
    (["--duration-s", "-60"], "--duration-s -60: must be a positive"),
    (["--mask-deg", "90"], "elevation mask must be in [0, 90)"),
    (["--mask-deg", "-1"], "elevation mask must be in [0, 90)"),
    (["--start", "not-a-time"], "--start: 'not-a-time' is not an ISO 8601"),
    (["--tle", "/nonexistent/x.tle"], "no such TLE file"),
])
def test_bad_input_is_one_line_exit_2_and_no_output(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    code = main(["visibility", "--duration-s", "10", *args, "--out", str(out), "--json"])
    stdout, stderr = capsys.readouterr()
    assert code == 2
    assert stdout == ""
    assert message in stderr and len(stderr.strip().splitlines()) == 1
    assert not out.exists() or not any(out.iterdir())


def test_malformed_tle_file_is_reported_with_line_and_no_traceback(tmp_path):
    lines = DEFAULT_TLE.read_text().splitlines()[:6]
    lines[4] = lines[4][:68] + str((int(lines[4][68]) + 1) % 10)
    bad = tmp_path / "bad.tle"
    bad.write_text("\n".join(lines) + "\n")
    code, _, stderr = run_cli("visibility", "--tle", str(bad), "--duration-s", "10")
    assert code == 2 and f"{bad}:5: bad TLE checksum on line 1" in stderr


class _Handler(http.server.BaseHTTPRequestHandler):
    body = b""

    def do_GET(self):  # noqa: N802 (http.server API)
        self.send_response(200 if self.body else 404)
        self.end_headers()
        self.wfile.write(self.body)

    def log_message(self, *args):
        pass


@pytest.fixture()
def server():
    httpd = http.server.HTTPServer(("127.0.0.1", 0), _Handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield httpd
    httpd.shutdown()


def test_tle_fetch_from_a_local_server(tmp_path, server, capsys):
    _Handler.body = "\n".join(DEFAULT_TLE.read_text().splitlines()[:30]).encode() + b"\n"
    url = f"http://127.0.0.1:{server.server_port}/gp.php"
    out = tmp_path / "starlink.tle"
    assert main(["tle", "fetch", "starlink", "-o", str(out), "--url", url, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n_sats"] == 10 and doc["by_family"] == {"starlink": 10}
    assert out.read_bytes() == _Handler.body


def test_tle_fetch_failures_leave_no_file(tmp_path, server):
    out = tmp_path / "x.tle"
    _Handler.body = b"<html>not element sets</html>\n"
    code, _, stderr = run_cli("tle", "fetch", "starlink", "-o", str(out), "--url",
                              f"http://127.0.0.1:{server.server_port}/gp.php")
    assert code == 1 and "do not parse" in stderr and not out.exists()
    _Handler.body = b""
    code, _, stderr = run_cli("tle", "fetch", "starlink", "-o", str(out), "--url",
                              f"http://127.0.0.1:{server.server_port}/gp.php")
    assert code == 1 and "HTTP 404" in stderr and not out.exists()
    # Nothing listens on port 9 of the loopback: a clear network error.
    code, _, stderr = run_cli("tle", "fetch", "starlink", "-o", str(out), "--url", "http://127.0.0.1:9/gp.php")
    assert code == 1 and "cannot download" in stderr and len(stderr.strip().splitlines()) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [["tle", "--json", "info", str(DEFAULT_TLE)],
                                  ["tle", "info", str(DEFAULT_TLE), "--json"]])
def test_tle_info_json_before_or_after_the_action(capsys, argv):
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)  # one JSON document, whichever side of `info` --json stands
    assert doc["n_sats"] == 4408 and doc["by_family"] == {"starlink": 4408}


def test_tle_info_out_writes_the_summary_and_one_row_per_satellite(tmp_path, capsys):
    out = tmp_path / "info"
    assert main(["tle", "info", str(DEFAULT_TLE), "--out", str(out)]) == 0
    assert "4408 satellites" in capsys.readouterr().out
    assert json.loads((out / "tle_info.json").read_text())["n_sats"] == 4408
    with open(out / "satellites.csv") as fh:
        rows = {r["sat_id"]: r for r in csv.DictReader(fh)}
    # Independent reference: the element-set text itself (TLE line 2, fixed columns).
    lines = [s for s in DEFAULT_TLE.read_text().splitlines() if s.startswith("2 ")]
    assert len(rows) == len(lines) == 4408
    for line in lines[::97]:
        r = rows[line[2:7].strip()]
        assert r["family"] == "starlink" and r["epoch_utc"].endswith("Z")
        assert float(r["inclination_deg"]) == pytest.approx(float(line[8:16]), abs=5e-5)
        assert float(r["eccentricity"]) == pytest.approx(float("0." + line[26:33]), abs=5e-8)
        assert float(r["mean_motion_rev_per_day"]) == pytest.approx(float(line[52:63]), abs=5e-9)


def test_tle_fetch_refuses_out(tmp_path, capsys):
    # Not an abbreviation of --output: the one file fetch writes is named by -o.
    with pytest.raises(SystemExit) as info:
        main(["tle", "fetch", "starlink", "-o", str(tmp_path / "s.tle"), "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err
    assert info.value.code == 2 and err.startswith("leosop tle fetch: error: --out") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_peak_memory_stays_flat_when_the_span_doubles(tmp_path):
    # 60 satellites, 0.5 s steps: 20,001 then 40,001 epochs, both past --json-max-epochs and the figure's
    # binning. The whole-span code (before chunking) kept ~1.2 kB per epoch (the grid's geometry, the padded
    # GDOP arrays, the JSON lists): measured +24 MB here. Streamed, a run keeps ~20 B per epoch: measured
    # +1.4 MB. 8 MB leaves room for the allocator's noise and still fails the old growth by 3x.
    tle = tmp_path / "small.tle"
    tle.write_text("\n".join(DEFAULT_TLE.read_text().splitlines()[:180]) + "\n")
    peaks = [peak_rss_mb("visibility", "--tle", str(tle), "--start", "2025-01-01T00:00:00Z", "--duration-s",
                          str(seconds), "--step-s", "0.5", "--mask-deg", "10", "--json-max-epochs", "1000",
                          "--out", str(tmp_path / str(seconds))) for seconds in (10_000, 20_000)]
    assert peaks[1] - peaks[0] < 8.0, peaks
    with open(tmp_path / "20000" / "visibility.csv") as fh:
        assert sum(1 for _ in fh) == 40_002
    doc = json.loads((tmp_path / "20000" / "visibility.json").read_text())
    assert doc["epochs_utc"] is None and doc["visible_ids"] is None and doc["n_epochs"] == 40_001
    assert not doc["per_epoch"]["in_document"] and doc["per_epoch"]["files"]["n_visible"].startswith("visibility.csv")
