"""``leosop replay A B ...``: a batch gives each recording's single-replay result, and resumes.

The reference of a batch is the single-recording command run on each
recording by itself: the batch's ``DIR/<name>/replay.json`` must be that
document, key for key. The ledger's resume rules are checked with a stand-in
replay that counts its calls (no signal processing: milliseconds).
"""

import json
import os

import pytest

from leosop.cli import main
from leosop.cli import replay as replay_cli
from leosop.errors import InputError
from leosop.replay.batch import LEDGER, batch_recordings, run_batch

INIT = "34.98,109.71,0"  # 100 km from the site, as the single-replay tests use


@pytest.fixture(scope="module")
def two_recordings(tmp_path_factory):
    """Two tiny recordings (3 snapshots of 10 ms at 1 MS/s, Xi'an) with different noise and clocks."""
    folder = tmp_path_factory.mktemp("recs")
    for seed in (1, 2):
        assert main(["generate", "-o", str(folder / f"rec{seed}.sigmf-meta"), "--site", "34.342,108.94,400",
                     "--start", "2025-01-01T19:40:00Z", "--sample-rate-hz", "1e6", "--seed", str(seed),
                     "--duration-s", "3", "--snapshot-s", "0.01", "--period-s", "1", "--mask-deg", "40"]) == 0
    return [folder / "rec1.sigmf-meta", folder / "rec2.sigmf-meta"]


def _json(capsys, argv):
    capsys.readouterr()
    code = main(argv)
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


def test_batch_gives_each_single_replay_and_resumes(two_recordings, capsys, tmp_path, monkeypatch):
    opts = ["--init", INIT, "--static", "--mask-deg", "40"]  # the generated satellites are all above 40 deg
    singles = [_json(capsys, ["replay", str(p), *opts, "--json"]) for p in two_recordings]
    out = tmp_path / "batch"
    doc = _json(capsys, ["replay", *map(str, two_recordings), *opts, "--scheduler", "serial", "--out", str(out),
                         "--json"])
    assert (doc["n_recordings"], doc["n_run"], doc["n_resumed"], doc["n_failed"]) == (2, 2, 0, 0)
    for single, entry, path in zip(singles, doc["recordings"], two_recordings):
        name = path.name.removesuffix(".sigmf-meta")
        assert entry["name"] == name and entry["status"] == "done"
        # The batch's document is the single run's, to the last bit (neither has a runtime in it).
        assert json.loads((out / name / "replay.json").read_text()) == single
        assert entry["n_identified"] == single["n_identified"] > 0
        assert entry["fix"]["lat_deg"] == single["solutions"][0]["lat_deg"]
        assert entry["fix"]["status"] == single["solutions"][0]["status"]
        assert {"tracks.csv", "measurements.csv", "spectrogram.png"} <= {f.name for f in (out / name).iterdir()}
    assert json.loads((out / LEDGER).read_text())["recordings"] == doc["recordings"]
    # The same command again replays nothing: every recording is done with the same options and code.
    monkeypatch.setattr(replay_cli, "_run_single", lambda args: pytest.fail("a finished recording was rerun"))
    again = _json(capsys, ["replay", *map(str, two_recordings), *opts, "--scheduler", "serial", "--out", str(out),
                           "--json"])
    assert (again["n_run"], again["n_resumed"]) == (0, 2)
    assert [e["runtime_s"] for e in again["recordings"]] == [e["runtime_s"] for e in doc["recordings"]]


@pytest.mark.parametrize("argv, message", [
    (["--scheduler", "serial"], "--scheduler and --workers run a batch"),
    (["SECOND", "--scheduler", "serial"], "a batch (several recordings, or a folder) needs --out DIR"),
    (["SECOND", "--out", "OUT", "--workers", "0"], "--workers 0: expected an integer >= 1"),
    (["SECOND", "--out", "OUT", "--base", "x.sigmf-meta", "--base-site", "0,0,0"], "take one rover recording"),
])
def test_batch_options_refused_before_any_work(two_recordings, capsys, tmp_path, argv, message):
    argv = [str(two_recordings[1]) if a == "SECOND" else str(tmp_path / "o") if a == "OUT" else a for a in argv]
    capsys.readouterr()
    assert main(["replay", str(two_recordings[0]), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_folders_expand_and_names_must_differ(tmp_path):
    for name in ("b", "a"):
        (tmp_path / f"{name}.sigmf-meta").write_text("{}")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "a.sigmf-meta").write_text("{}")
    assert [n for _, n in batch_recordings([tmp_path])] == ["a", "b"]  # sorted, sub-folders not searched
    with pytest.raises(InputError, match="same name as"):
        batch_recordings([tmp_path, tmp_path / "other" / "a.sigmf-meta"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no \\*.sigmf-meta"):
        batch_recordings([tmp_path / "empty"])


CALLS = []


def _stand_in(meta):
    """A replay stand-in: fails on a file saying 'bad', else one track and a static fix."""
    CALLS.append(meta.name)
    if meta.read_text() == "bad":
        raise InputError(f"{meta}: bad recording")
    sol = {"lat_deg": 1.0, "lon_deg": 2.0, "alt_m": 3.0, "status": "ok", "sigma_enu_m": [1, 1, 1], "n_sats": 8}
    doc = {"tracks": [{"sat_id": "1"}], "solutions": [sol], "n_identified": 1, "n_blocks": 3, "mode": "static"}
    return doc, {"replay.json": json.dumps(doc).encode(), "tracks.csv": meta.read_bytes()}


def _recordings(tmp_path, texts):
    for name, text in texts.items():
        (tmp_path / f"{name}.sigmf-meta").write_text(text)
    return batch_recordings([tmp_path / f"{n}.sigmf-meta" for n in texts])


def test_ledger_resumes_only_what_is_not_done_with_the_same_key(tmp_path):
    recs = _recordings(tmp_path, {"a": "one", "b": "bad", "c": "three"})
    out = tmp_path / "out"
    CALLS.clear()
    doc = run_batch(_stand_in, recs, out, options={"mask": 10}, scheduler="serial")
    assert [e["status"] for e in doc["recordings"]] == ["done", "failed", "done"] and doc["n_failed"] == 1
    assert doc["recordings"][1]["error_kind"] == "input" and "bad recording" in doc["recordings"][1]["error"]
    assert (out / "c" / "tracks.csv").read_text() == "three" and not (out / "b").exists()
    (tmp_path / "b.sigmf-meta").write_text("two")
    CALLS.clear()
    doc = run_batch(_stand_in, recs, out, options={"mask": 10}, scheduler="serial")
    assert CALLS == ["b.sigmf-meta"] and doc["n_resumed"] == 2 and doc["n_failed"] == 0  # only the failed one
    st = (tmp_path / "c.sigmf-meta").stat()
    os.utime(tmp_path / "c.sigmf-meta", ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    CALLS.clear()
    run_batch(_stand_in, recs, out, options={"mask": 10}, scheduler="serial")
    assert CALLS == ["c.sigmf-meta"]  # a recording changed on disk is replayed again
    (out / "a" / "replay.json").unlink()
    CALLS.clear()
    run_batch(_stand_in, recs, out, options={"mask": 10}, scheduler="serial")
    assert CALLS == ["a.sigmf-meta"]  # its result is gone
    CALLS.clear()
    run_batch(_stand_in, recs, out, options={"mask": 11}, scheduler="serial")
    assert CALLS == ["a.sigmf-meta", "b.sigmf-meta", "c.sigmf-meta"]  # other options: everything again


def test_dask_path_writes_what_the_serial_path_writes(tmp_path):
    distributed = pytest.importorskip("distributed")
    recs = _recordings(tmp_path, {"a": "one", "b": "bad", "c": "three"})
    serial = run_batch(_stand_in, recs, tmp_path / "serial", options={}, scheduler="serial")
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=":0") as client:
        dask = run_batch(_stand_in, recs, tmp_path / "dask", options={}, scheduler=client)
    strip = lambda doc: [{k: v for k, v in e.items() if k != "runtime_s"} for e in doc["recordings"]]  # noqa: E731
    assert strip(dask) == strip(serial) and dask["n_workers"] == 1
    for name in ("a", "c"):
        for f in ("replay.json", "tracks.csv"):
            assert (tmp_path / "dask" / name / f).read_bytes() == (tmp_path / "serial" / name / f).read_bytes()


def test_failed_recordings_are_reported_and_the_exit_says_why(two_recordings, capsys, tmp_path):
    # Recordings without core:datetime pass the up-front check (they are SigMF) and fail when replayed.
    copies = []
    for path in two_recordings:
        meta = json.loads(path.read_text())
        for cap in meta["captures"]:
            cap.pop("core:datetime", None)
        copy = tmp_path / path.name
        copy.write_text(json.dumps(meta))
        copy.with_suffix(".sigmf-data").symlink_to(path.with_suffix(".sigmf-data"))
        copies.append(copy)
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["replay", *map(str, copies), "--scheduler", "serial", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "2 of 2 recording(s) failed" in err and "core:datetime" in err and len(err.strip().splitlines()) == 1
    ledger = json.loads((out / LEDGER).read_text())
    assert [e["status"] for e in ledger["recordings"]] == ["failed", "failed"] and ledger["n_failed"] == 2
