"""Output sets are all or nothing, and ``reproduce --out`` writes every target's table.

When one file of a command's set cannot be written (a directory in its way),
nothing of the set is left behind and files it would have replaced are as
they were (issue 20: ``visibility --out`` left passes.csv). ``reproduce
TARGET --out DIR`` writes the document as JSON, its rows as CSV and the
target's figure (issue 20: table2, table3, table4 and errmodel-validate wrote
nothing).
"""

import csv
import dataclasses
import json
import os

import pytest

from leosop import fileio
from leosop.cli import main
from leosop.apps.repro import doppler_tables, fusion_tables, run_target
from leosop.apps.scenarios import XIAN_BAOJI

PNG = b"\x89PNG\r\n\x1a\n"


def _cli(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def _listing(d):
    return sorted(p.name for p in d.iterdir())


def _blocked(tmp_path, name):
    """An output directory holding an old file and a directory where ``name`` goes."""
    out = tmp_path / "out"
    (out / name).mkdir(parents=True)
    (out / "old.txt").write_text("kept")
    return out


def test_commit_puts_replaced_files_back_when_a_move_fails(tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.csv").write_text("old a")
    real_replace = os.replace

    def failing(src, dst):
        if str(dst).endswith("b.csv"):
            raise PermissionError(13, "Permission denied", str(dst))
        real_replace(src, dst)

    monkeypatch.setattr(fileio.os, "replace", failing)
    with pytest.raises(PermissionError), fileio.atomic_outputs(out) as stage:
        (stage / "a.csv").write_text("new a")
        (stage / "b.csv").write_text("new b")
    assert _listing(out) == ["a.csv"] and (out / "a.csv").read_text() == "old a"


def test_visibility(tmp_path, capsys):
    out = _blocked(tmp_path, "visibility.json")
    status, _, err = _cli(capsys, "visibility", "--site", "34.342,108.940,400", "--start", "2025-01-01T19:40:00Z",
                          "--duration-s", "60", "--step-s", "30", "--mask-deg", "40", "--out", str(out))
    assert status == 2 and "visibility.json" in err and len(err.splitlines()) == 1
    assert _listing(out) == ["old.txt", "visibility.json"] and not any((out / "visibility.json").iterdir())


def test_simulate(tmp_path, capsys):
    scenario = tmp_path / "short.json"
    scenario.write_text(json.dumps({"name": "short", "duration_s": 5.0}))
    out = _blocked(tmp_path, "visible.png")  # the last file of the set in name order
    status, _, err = _cli(capsys, "simulate", "--scenario", str(scenario), "--level", "measurement", "--out", str(out))
    assert status == 2 and "visible.png" in err
    assert _listing(out) == ["old.txt", "visible.png"]


def test_generate(tmp_path, capsys):
    (tmp_path / "rec.sigmf-data").mkdir()
    status, _, err = _cli(capsys, "generate", "-o", str(tmp_path / "rec.sigmf-meta"), "--duration-s", "0.1",
                          "--sample-rate-hz", "500e3")
    assert status == 2 and "rec.sigmf-data" in err
    assert _listing(tmp_path) == ["rec.sigmf-data"]


def test_reproduce(tmp_path, capsys):
    out = _blocked(tmp_path, "errmodel_validate.png")
    status, _, err = _cli(capsys, "reproduce", "errmodel-validate", "--out", str(out))
    assert status == 2 and "errmodel_validate.png" in err
    assert _listing(out) == ["errmodel_validate.png", "old.txt"]


def _csv_rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture
def small_tables(monkeypatch):
    """Tables 2-4 cut to one row / a 20 s flight and one seed, so that they run in seconds."""
    monkeypatch.setattr(doppler_tables, "PAPER_TABLE2", {1.0: doppler_tables.PAPER_TABLE2[1.0]})
    monkeypatch.setattr(doppler_tables, "PAPER_TABLE3", {100_000: doppler_tables.PAPER_TABLE3[100_000]})
    monkeypatch.setattr(fusion_tables, "XIAN_BAOJI", dataclasses.replace(XIAN_BAOJI, duration_s=20.0))
    monkeypatch.setattr(fusion_tables, "_seeds", lambda seed, full: [seed])


@pytest.mark.parametrize("target, figure", [("table2", None), ("table3", None), ("table4", "table4.png"),
                                            ("errmodel-validate", "errmodel_validate.png"),
                                            ("errmodel-table3", None)])
def test_reproduce_out_writes_the_table(tmp_path, small_tables, target, figure):
    doc = run_target(target, out_dir=tmp_path, seed=0, scheduler="serial", full=False)
    stem = target.replace("-", "_")
    assert json.loads((tmp_path / f"{stem}.json").read_text()) == json.loads(json.dumps(doc))
    rows = _csv_rows(tmp_path / f"{stem}.csv")
    if "rows" in doc:
        # One CSV row per document row, the numbers as the document holds them (nested keys joined by '.').
        assert len(rows) == len(doc["rows"])
        first = doc["rows"][0]
        key = next(k for k, v in first.items() if isinstance(v, float))
        assert float(rows[0][key]) == first[key]
    else:
        # errmodel-validate: attitude, velocity and position on E, N, U; the end values of the document.
        assert [(r["quantity"], r["axis"]) for r in rows][3:6] == [("velocity_mps", a) for a in "ENU"]
        for r, v in zip(rows[6:9], doc["strapdown"]["pos_err_m"]):
            assert float(r["strapdown"]) == pytest.approx(v, rel=1e-8)  # written to 9 digits
    expected = {f"{stem}.json", f"{stem}.csv"} | ({figure} if figure else set())
    assert set(_listing(tmp_path)) == expected
    if figure:
        assert (tmp_path / figure).read_bytes()[:8] == PNG
