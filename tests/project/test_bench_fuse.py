"""tools/bench_fuse.py: its one table builder on hand-made scores (the real runs take minutes and real data)."""

import importlib.util
import json

import pytest

from tests.helpers import REPO_ROOT

_spec = importlib.util.spec_from_file_location("bench_fuse", REPO_ROOT / "tools" / "bench_fuse.py")
bench_fuse = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench_fuse)

#: Per-outage maxima [m] of two runs: means 2 and 4 m, worsts 3 and 6 m, so each table's ratio is 0.5.
BETTER = {"max_horiz_err_m": [1.0, 3.0], "inside_3sigma": 0.95, "runtime_s": 2.0, "log_s": 100.0}
WORSE = {"max_horiz_err_m": [2.0, 6.0], "inside_3sigma": 0.5, "runtime_s": 10.0, "log_s": 100.0}


@pytest.fixture
def fake_runs(monkeypatch):
    """One outage length; ``ours`` scores BETTER with LEO, ``score["gnss_only"]`` without; the peer WORSE."""
    monkeypatch.setattr(bench_fuse, "OUTAGE_LENGTHS_S", (15.0,))
    score = {"gnss_only": BETTER}
    monkeypatch.setattr(bench_fuse, "ours", lambda data, name, length_s, leo_sim=False, leo_exact=False,
                        leo_window_s=None: (BETTER if leo_sim else score["gnss_only"], ((0.0, length_s),)))
    monkeypatch.setattr(bench_fuse, "peer", lambda data, anchor, name, length_s, outages: WORSE)
    return score


def test_peer_table(fake_runs, capsys):
    bench_fuse.main(["--logs", "drive", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert list(row) == ["log", "outage_s", "n_outages", "ours_mean_m", "ours_worst_m", "peer_mean_m", "peer_worst_m",
                         "inside_3sigma", "ours_runtime_s", "peer_runtime_s", "log_s", "ours_max_m", "peer_max_m",
                         "mean_ratio"]
    assert (row["ours_mean_m"], row["ours_worst_m"], row["peer_mean_m"], row["peer_worst_m"]) == (2.0, 3.0, 4.0, 6.0)
    assert row["mean_ratio"] == 0.5 and row["n_outages"] == 2 and row["peer_max_m"] == [2.0, 6.0]
    bench_fuse.main(["--logs", "drive"])
    assert capsys.readouterr().out == (
        "drive   15 s x 2: ours mean   2.00 m worst   3.00 m | peer mean   4.00 m worst   6.00 m | ratio 0.50 | "
        "inside 3 sigma 95 % | run 2.0 s (0.020 x log), peer 10.0 s\n")


def test_leo_table(fake_runs, capsys):
    fake_runs["gnss_only"] = WORSE
    bench_fuse.main(["--logs", "walk", "--leo-sim", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert list(row) == ["log", "outage_s", "n_outages", "gnss_mean_m", "gnss_worst_m", "leo_mean_m", "leo_worst_m",
                         "gnss_inside_3sigma", "leo_inside_3sigma", "leo_runtime_s", "log_s", "leo_max_m", "mean_ratio"]
    assert (row["gnss_mean_m"], row["gnss_worst_m"], row["leo_mean_m"], row["leo_worst_m"]) == (4.0, 6.0, 2.0, 3.0)
    assert row["mean_ratio"] == 0.5 and row["leo_max_m"] == [1.0, 3.0]
    bench_fuse.main(["--logs", "walk", "--leo-sim"])
    assert capsys.readouterr().out == (
        "walk    15 s x 2: GNSS-only mean   4.00 m worst   6.00 m | +LEO sim mean   2.00 m worst   3.00 m | "
        "ratio 0.500 | inside 3 sigma 50 % / 95 % | LEO run 2.0 s (0.020 x log)\n")
