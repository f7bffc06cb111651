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
        assert ds["gdop"].attrs["units"] == "1" and ds["lat"].attrs["units"] == "degrees_north"
        assert doc["n_visible_max"] == n.max()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["fix_fraction.png", "gdop_map.nc", "gdop_maps.png", "n_visible_maps.png"]


@pytest.mark.parametrize("args, code, message", [
    (["--grid-deg", "7"], 2, "--grid-deg 7: must divide 180 and 360 into whole steps; nearest valid: 6.92308 or 7.2"),
    (["--constellation", "oneweb"], 2, "--constellation: no oneweb satellites"),
    (["--mask-deg", "95"], 2, "--mask-deg 95: elevation mask must be in [0, 90)"),
    (["--scheduler", "tcp://127.0.0.1:9"], 1, "--scheduler tcp://127.0.0.1:9: cannot connect to a Dask scheduler"),
])
def test_bad_input_one_line_and_nothing_written(tmp_path, capsys, monkeypatch, args, code, message):
    monkeypatch.setattr("leosop.orbits.gridmap._CONNECT_TIMEOUT", "1s")
    out = tmp_path / "maps"
    assert main(["study", "gdop-map", "--grid-deg", "30", "--duration-s", "60", *args, "--out", str(out)]) == code
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists() or not any(out.iterdir())
