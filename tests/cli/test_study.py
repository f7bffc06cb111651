"""`leosop study gdop-map`: NetCDF contract, figures, bad input with no partial output."""

import json

import numpy as np
import pytest
import xarray as xr

from leosop.cli import main


def test_gdop_map_netcdf_and_figures(tmp_path, capsys):
    code = main(["study", "gdop-map", "--start", "2025-01-01T00:00:00Z", "--duration-s", "240", "--step-s", "120",
                 "--grid-deg", "10", "--mask-deg", "40", "--scheduler", "serial", "--json", "--out", str(tmp_path)])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc["n_epochs"] == 3 and doc["n_satellites"] == 4408
    with xr.open_dataset(tmp_path / "gdop_map.nc", engine="scipy") as ds:
        assert ds["n_visible"].dims == ("time", "lat", "lon") and ds["gdop"].shape == (3, 19, 36)
        np.testing.assert_array_equal(ds["lat"].values, np.arange(-90, 91, 10))
        np.testing.assert_array_equal(ds["lon"].values, np.arange(-180, 180, 10))
        assert str(ds["time"].values[-1]) == "2025-01-01T00:04:00.000000000"
        n, g = ds["n_visible"].values, ds["gdop"].values
        np.testing.assert_array_equal(np.isfinite(g), n >= 7)  # no singular geometry in this window
        assert ds["gdop"].attrs["units"] == "m Hz-1" and ds["lat"].attrs["units"] == "degrees_north"
        assert ds["gdop"].attrs["long_name"].startswith("Doppler GDOP")
        assert doc["n_visible_max"] == n.max()
        # One name, one quantity: the cell at 30 N 110 E is `leosop visibility`'s `gdop` at that site.
        cell_n, cell_gdop = n[:, 12, 29], g[:, 12, 29]
    assert main(["visibility", "--site", "30,110,0", "--start", "2025-01-01T00:00:00Z", "--duration-s", "240",
                 "--step-s", "120", "--mask-deg", "40", "--json"]) == 0
    vis = json.loads(capsys.readouterr().out)
    np.testing.assert_array_equal(vis["n_visible"], cell_n)
    assert np.isfinite(cell_gdop).any()
    # The map stores float32: 6e-8 relative rounding, within 1e-6.
    np.testing.assert_allclose(np.array(vis["gdop"], dtype=float), cell_gdop, rtol=1e-6)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["fix_fraction.png", "gdop_map.nc", "gdop_maps.png", "n_visible_maps.png"]


@pytest.mark.parametrize("args, code, message", [
    (["--grid-deg", "7"], 2, "--grid-deg 7: must divide 180 and 360 into whole steps; nearest valid: 6 or 7.2"),
    (["--constellation", "oneweb"], 2, "--constellation: no oneweb satellites"),
    (["--mask-deg", "95"], 2, "--mask-deg 95: elevation mask must be in [0, 90)"),
    (["--workers", "0"], 2, "--workers 0: expected an integer >= 1"),
    (["--scheduler", "tcp://127.0.0.1:9"], 1, "--scheduler tcp://127.0.0.1:9: cannot connect to a Dask scheduler"),
])
def test_bad_input_one_line_and_nothing_written(tmp_path, capsys, monkeypatch, args, code, message):
    monkeypatch.setattr("leosop.parallel.CONNECT_TIMEOUT", "1s")
    out = tmp_path / "maps"
    assert main(["study", "gdop-map", "--grid-deg", "30", "--duration-s", "60", *args, "--out", str(out)]) == code
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists() or not any(out.iterdir())


TINY_SPEC = {"scenario": {"duration_s": 10}, "fixed": {"level": "measurement"},
             "parameters": {"correction_period_s": [1, 5], "coupling": ["loose", "tight"]}, "n_seeds": 3,
             "runs_per_chunk": 4}


def _spec_file(tmp_path, **changes):
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps({**TINY_SPEC, **changes}))
    return path


def test_montecarlo_netcdf_table_and_figures(tmp_path, capsys):
    out = tmp_path / "mc"
    code = main(["study", "montecarlo", str(_spec_file(tmp_path)), "--scheduler", "serial", "--json",
                 "--out", str(out)])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc["n_runs"] == 12 and doc["n_chunks"] == 3 and doc["n_chunks_resumed"] == 0
    with xr.open_dataset(out / "montecarlo.nc", engine="scipy") as ds:
        assert ds["fused_pos_err_mean_m"].dims == ("correction_period_s", "coupling", "seed")
        assert ds["fused_pos_err_mean_m"].attrs["units"] == "m" and ds["correction_period_s"].attrs["units"] == "s"
        assert list(ds["coupling"].values) == ["loose", "tight"] and ds.attrs["Conventions"] == "CF-1.8"
        assert json.loads(ds.attrs["spec"])["n_seeds"] == 3 and ds["run_seed"].shape == (3,)
        cell = ds["fused_pos_err_mean_m"].sel(correction_period_s=5.0, coupling="tight").values
        assert doc["cells"][3]["parameters"] == {"correction_period_s": 5.0, "coupling": "tight"}
        assert doc["cells"][3]["fused_pos_err_mean_m"]["mean"] == pytest.approx(cell.mean(), rel=1e-12)
    assert sorted(p.name for p in out.iterdir()) == ["error_vs_correction_period_s.png", "error_vs_coupling.png",
                                                      "montecarlo.nc"]  # the chunk directory is gone
    assert main(["study", "montecarlo", str(_spec_file(tmp_path)), "--scheduler", "serial", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "correction_period_s  coupling" in text and text.count("\n") == 2 + 1 + 4


def test_montecarlo_interrupted_then_resumed(tmp_path, capsys, monkeypatch):
    from leosop.apps.montecarlo import execute

    real, calls = execute.run_chunk, []

    def interrupt_third(runs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(runs)

    monkeypatch.setattr(execute, "run_chunk", interrupt_third)
    out, spec = tmp_path / "mc", _spec_file(tmp_path)
    assert main(["study", "montecarlo", str(spec), "--scheduler", "serial", "--json", "--out", str(out)]) == 1
    assert "interrupted" in capsys.readouterr().err
    (work,) = out.iterdir()  # no montecarlo.nc, only the finished chunks
    assert work.name.startswith("montecarlo-chunks-") and len(list(work.iterdir())) == 2
    monkeypatch.setattr(execute, "run_chunk", real)
    assert main(["study", "montecarlo", str(spec), "--scheduler", "serial", "--json", "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["n_chunks_resumed"] == 2 and not work.exists()


@pytest.mark.parametrize("changes, args, code, message", [
    ({"parameters": {"cn0": [40]}}, [], 2, "tiny.json: parameters: unknown parameter 'cn0'"),
    ({"parameters": {"cn0_dbhz": []}}, [], 2, "tiny.json: parameters.cn0_dbhz: expected a non-empty list"),
    ({}, ["--workers", "0"], 2, "--workers 0: expected an integer >= 1"),
    ({}, ["--scheduler", "tcp://127.0.0.1:9"], 1, "--scheduler tcp://127.0.0.1:9: cannot connect to a Dask scheduler"),
])
def test_montecarlo_bad_input(tmp_path, capsys, monkeypatch, changes, args, code, message):
    monkeypatch.setattr("leosop.parallel.CONNECT_TIMEOUT", "1s")
    out = tmp_path / "mc"
    assert main(["study", "montecarlo", str(_spec_file(tmp_path, **changes)), *args, "--out", str(out)]) == code
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (out / "montecarlo.nc").exists()


def test_gdop_map_interrupted_then_resumed(tmp_path, capsys, monkeypatch):
    from leosop.orbits import gridmap

    args = ["study", "gdop-map", "--start", "2025-01-01T00:00:00Z", "--duration-s", "240", "--step-s", "60",
            "--grid-deg", "15", "--scheduler", "serial", "--json"]
    assert main(args + ["--out", str(tmp_path / "whole")]) == 0
    real, calls = gridmap.maps_for_times, []

    def interrupt_second(const, times, *rest):
        calls.append(len(times))
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(const, times, *rest)

    monkeypatch.setattr(gridmap, "maps_for_times", interrupt_second)
    out = tmp_path / "resumed"
    assert main(args + ["--out", str(out)]) == 1
    (work,) = out.iterdir()  # no gdop_map.nc, the first task's epochs only
    assert work.name.startswith("gdop-map-chunks-") and calls == [2, 2] and len(list(work.iterdir())) == 1
    calls.clear()
    monkeypatch.setattr(gridmap, "maps_for_times", lambda const, times, *rest: calls.append(len(times)) or real(
        const, times, *rest))
    assert main(args + ["--out", str(out)]) == 0
    assert sum(calls) == 3 and not work.exists()  # 5 epochs, 2 taken from the work directory
    capsys.readouterr()
    with xr.open_dataset(tmp_path / "whole" / "gdop_map.nc", engine="scipy") as a, \
            xr.open_dataset(out / "gdop_map.nc", engine="scipy") as b:
        xr.testing.assert_identical(a, b)
