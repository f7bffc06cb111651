"""A study's results as an ``xarray.Dataset`` (parameter axes x seed) and its NetCDF file.

Every metric of :data:`leosop.apps.montecarlo.runs.METRICS` is a variable over
``(axis_1, ..., axis_k, seed)`` with CF-style ``units`` and ``long_name``;
each parameter axis is a coordinate (numbers with units, names, or lists of
names joined by ``+``: :func:`leosop.apps.montecarlo.parameters.label`), ``seed``
counts 0..n-1 and ``run_seed(seed)`` is the integer each run was given. The
normalised spec and the fixed parameters are global attributes, so a file
says how to reproduce itself.
"""

import json

import numpy as np

from ... import __version__
from ...fileio import atomic_path
from .parameters import PARAMETERS, label
from .runs import METRICS
from .spec import run_seeds

__all__ = ["to_dataset", "write_netcdf", "cell_table"]


def to_dataset(spec, rows):
    """The Dataset of a study.

    Parameters
    ----------
    spec : leosop.apps.montecarlo.spec.StudySpec
    rows : ndarray, (n_runs, n_metrics)
        :attr:`leosop.apps.montecarlo.execute.StudyRun.rows`.

    Returns
    -------
    xarray.Dataset
    """
    import xarray as xr

    dims = tuple(spec.axes) + ("seed",)
    data = rows.reshape(spec.shape + (len(METRICS),))
    variables = {name: (dims, data[..., j], {"units": units, "long_name": long_name})
                 for j, (name, (units, long_name)) in enumerate(METRICS.items())}
    variables["run_seed"] = (("seed",), run_seeds(spec), {
        "long_name": "seed given to leosop.apps.simulate.run_scenario (child k of numpy SeedSequence(seed_root))",
        "units": "1"})
    coords = {"seed": ("seed", np.arange(spec.n_seeds), {"long_name": "seed index", "units": "1"})}
    for name, values in spec.axes.items():
        p = PARAMETERS[name]
        attrs = {"long_name": p.long_name} | ({"units": p.units} if p.units else {})
        coords[name] = (name, np.array(values, dtype=float) if p.choices is None
                        else np.array([label(v) for v in values], dtype=str), attrs)
    return xr.Dataset(variables, coords=coords, attrs={
        "Conventions": "CF-1.8",
        "title": f"leosop Monte Carlo study {spec.name}",
        "comment": spec.description,
        "source": f"leosop {__version__} study montecarlo; simulation of [Shen 2024]'s Starlink/INS flight",
        "seed_root": spec.seed,
        "fixed_parameters": json.dumps(spec.fixed, sort_keys=True),
        "spec": spec.to_json(),
    })


def write_netcdf(ds, path):
    """Write ``ds`` as NetCDF 3 (64-bit offsets, scipy backend), complete or absent."""
    encoding = {name: {"_FillValue": np.nan} for name in METRICS}
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT", encoding=encoding)


def cell_table(ds, metrics=("fused_pos_err_mean_m", "fused_vel_err_mean_mps")):
    """Per grid cell: parameter values and, per metric, mean, std, 10th and 90th percentile over seeds.

    Returns
    -------
    list of dict
        ``{"parameters": {name: value}, metric: {"mean", "std", "p10", "p90", "n"}, ...}``,
        NaN runs (no fused output) left out of the statistics and counted out of ``n``.
    """
    axes = [d for d in ds[metrics[0]].dims if d != "seed"]
    stacked = {m: ds[m].transpose(*axes, "seed").values.reshape(-1, ds.sizes["seed"]) for m in metrics}
    grid = np.meshgrid(*[ds[a].values for a in axes], indexing="ij")
    table = []
    for c in range(stacked[metrics[0]].shape[0]):
        row = {"parameters": {a: g.ravel()[c].item() for a, g in zip(axes, grid)}}
        for m in metrics:
            v = stacked[m][c]
            v = v[np.isfinite(v)]
            stats = (v.mean(), v.std(ddof=1) if v.size > 1 else np.nan, *np.percentile(v, [10, 90])) if v.size \
                else (np.nan,) * 4
            row[m] = dict(zip(("mean", "std", "p10", "p90"), map(float, stats)), n=int(v.size))
        table.append(row)
    return table
