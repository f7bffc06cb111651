"""The global visibility and GDOP maps as a CF-style ``xarray.Dataset`` and its NetCDF file."""

import numpy as np

__all__ = ["map_dataset", "write_netcdf", "GDOP_UNITS"]

#: CF (UDUNITS) units of the Doppler GDOP: metres of position per hertz of
#: Doppler noise, its dominant part. Not CF's "1", which declares a
#: dimensionless quantity; the classic range DOPs are, this one is not.
GDOP_UNITS = "m Hz-1"


def map_dataset(times, grid, mask_deg, counts, gdops, const):
    """The maps with their coordinates and CF attributes.

    Parameters
    ----------
    times : ndarray of datetime64[ns], (n_epochs,)
    grid : ~leosop.orbits.gridcells.Grid
    mask_deg : float
    counts : ndarray of int16, (n_epochs, n_lat, n_lon)
    gdops : ndarray of float32, (n_epochs, n_lat, n_lon)
    const : Constellation

    Returns
    -------
    xarray.Dataset
    """
    import xarray as xr

    families = sorted({f or "other" for f in const.families})
    ds = xr.Dataset(
        {
            "n_visible": (("time", "lat", "lon"), counts, {
                "long_name": f"number of satellites above the {mask_deg:g} deg elevation mask",
                "units": "1",
            }),
            "gdop": (("time", "lat", "lon"), gdops, {
                "long_name": "Doppler GDOP: geometric dilution of precision of Doppler positioning "
                             "(7 states: position, velocity, frequency offset; static receiver on the ellipsoid)",
                "units": GDOP_UNITS,
                "comment": "sqrt(trace((H^T H)^-1)), Shen 2024 eq. 10, H in Hz per state unit: the root-sum-square "
                           "of the state standard deviations for 1 Hz of Doppler noise. Not dimensionless: the "
                           "position terms (m per Hz) dominate; the velocity (m/s per Hz) and frequency-offset "
                           "(Hz per Hz) terms are added as numbers. NaN where fewer than 7 satellites",
            }),
        },
        coords={
            "time": ("time", times, {"standard_name": "time", "long_name": "time (UTC)"}),
            "lat": ("lat", grid.lat_deg, {"standard_name": "latitude", "long_name": "geodetic latitude (WGS84)",
                                          "units": "degrees_north"}),
            "lon": ("lon", grid.lon_deg, {"standard_name": "longitude", "long_name": "longitude",
                                          "units": "degrees_east"}),
        },
        attrs={
            "Conventions": "CF-1.8",
            "title": "LEO visibility and Doppler-positioning GDOP map",
            "source": f"leosop gdop-map; SGP4 elements from {const.source or 'bundled Walker set'}",
            "elevation_mask_deg": float(mask_deg),
            "grid_step_deg": float(grid.step_deg),
            "n_satellites": int(len(const)),
            "families": ",".join(families),
            "carrier_note": "each satellite's family carrier; unknown families use the Starlink pilot 11.325 GHz",
        },
    )
    return ds


def write_netcdf(ds, path):
    """Write the map dataset as NetCDF 3 (64-bit offsets, scipy backend), complete or absent."""
    from ..fileio import atomic_path

    encoding = {
        "time": {"units": "seconds since 1970-01-01T00:00:00Z", "calendar": "proleptic_gregorian", "dtype": "f8",
                 "_FillValue": None},
        "lat": {"_FillValue": None},
        "lon": {"_FillValue": None},
        "gdop": {"_FillValue": np.float32(np.nan)},
        "n_visible": {"_FillValue": None},
    }
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT", encoding=encoding)
