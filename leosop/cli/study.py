"""``leosop study gdop-map|montecarlo``: studies at scale, results in NetCDF.

``gdop-map``: visible count and Doppler GDOP over a global grid and time,
``DIR/gdop_map.nc`` and map figures. ``montecarlo SPEC``: a grid of scenario
parameters x seeds of the ``simulate`` flight (:mod:`leosop.apps.montecarlo`),
``DIR/montecarlo.nc`` and error-vs-parameter figures. Finished chunks wait in
``DIR/montecarlo-chunks-<digest>/`` (``DIR/gdop-map-chunks-<digest>/``) until
the output is written, so the same command resumes an interrupted study.
NetCDF 3 through xarray's scipy backend; every output is complete or absent
(:func:`leosop.fileio.atomic_outputs`).
"""

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from ..apps.montecarlo import bundled_specs
from ..apps.montecarlo.parameters import PARAMETERS
from ..chunkstore import ChunkStore, code_digest
from ..constellations import REGISTRY
from ..errors import InputError
from ..orbits.gridmap import ConstellationSource, check_grid_deg, gdop_map, write_netcdf
from ..timebase import format_utc, utc_from_seconds
from . import add_action, add_command
from .options import mask_deg, parse_time, positive

# Output values (epochs x cells) above which a run would not fit in memory.
_MAX_VALUES = 400_000_000


def register(subparsers):
    p = add_command(subparsers, "study", sys.modules[__name__], help="studies at scale (gdop-map, montecarlo)",
                    out=False)
    sub = p.add_subparsers(dest="study", metavar="STUDY", required=True)
    g = add_action(sub, "gdop-map", help="visible satellites and Doppler GDOP over a lat/lon grid and time, "
                                         "to NetCDF and world maps")
    g.add_argument("--out", metavar="DIR", required=True, help="directory for gdop_map.nc and the figures")
    g.add_argument("--tle", metavar="FILE", help="TLE or OMM file (default: bundled Walker set)")
    g.add_argument("--start", metavar="ISO", help="UTC start (default: the median element-set epoch)")
    g.add_argument("--duration-s", type=float, default=3600.0, help="span in seconds (default 3600)")
    g.add_argument("--step-s", type=float, default=60.0, help="epoch step in seconds (default 60)")
    g.add_argument("--grid-deg", type=float, default=5.0, help="grid step, dividing 180 (default 5)")
    g.add_argument("--mask-deg", type=float, default=40.0, help="elevation mask (default 40)")
    g.add_argument("--constellation", nargs="+", choices=sorted(REGISTRY), metavar="NAME",
                   help=f"only these families of a mixed file ({', '.join(sorted(REGISTRY))})")
    g.add_argument("--skip-bad", action="store_true", help="skip malformed TLE records with a warning")
    g.add_argument("--workers", type=int, metavar="N", help="workers of the local Dask cluster (default: the cores)")
    g.add_argument("--scheduler", metavar="ADDR",
                   help="Dask scheduler address (default: a local cluster; 'serial' runs in this process)")
    g.set_defaults(_module=sys.modules[__name__])
    m = add_action(sub, "montecarlo", help="sweep scenario parameters x seeds of the simulate flight, to NetCDF and "
                                          "error-vs-parameter figures",
                       description="SPEC: a bundled spec name "
                                   f"({', '.join(sorted(bundled_specs()))}) or a JSON file: an object with "
                                   "'scenario' (built-in name, scenario file or object), 'parameters' (name -> "
                                   "list of values, one grid axis each, e.g. {\"correction_period_s\": [1, 10], "
                                   "\"coupling\": [\"loose\", \"tight\"]}), 'n_seeds' (runs per grid cell) "
                                   "and optional 'name', 'description', 'tle', 'fixed' (parameters held at one "
                                   "value, e.g. {\"level\": \"measurement\"}), 'seed' (default 0) and "
                                   f"'runs_per_chunk' (default 10). Parameters: {', '.join(PARAMETERS)}. Writes "
                                   "montecarlo.nc (the simulate metrics of every run: grid cell x seed) and "
                                   "error_vs_<parameter>.png.")
    m.add_argument("spec", metavar="SPEC", help="JSON spec file or bundled spec name")
    m.add_argument("--out", metavar="DIR", required=True,
                   help="directory for montecarlo.nc, the figures and the chunks of an unfinished study")
    m.add_argument("--workers", type=int, metavar="N", help="workers of the local Dask cluster (default: the cores)")
    m.add_argument("--scheduler", metavar="ADDR",
                   help="Dask scheduler address (default: a local cluster; 'serial' runs in this process)")
    m.set_defaults(_module=sys.modules[__name__])


def run(args):
    if args.study == "montecarlo":
        return _run_montecarlo(args)
    _check_workers(args.workers)
    duration = positive(args.duration_s, "--duration-s")
    step = positive(args.step_s, "--step-s")
    mask = mask_deg(args.mask_deg)
    grid_deg = check_grid_deg(args.grid_deg)
    n_epochs = int(np.floor(duration / step + 1e-9)) + 1
    n_cells = (round(180 / grid_deg) + 1) * round(360 / grid_deg)
    if n_epochs * n_cells > _MAX_VALUES:
        raise InputError(f"--duration-s/--step-s/--grid-deg: {n_epochs} epochs x {n_cells} cells is too many "
                         f"(at most {_MAX_VALUES:,} values)")
    source = ConstellationSource(args.tle, tuple(args.constellation or ()), args.skip_bad)
    const = source.load()
    if args.start:
        start = parse_time(args.start)
    else:
        start = np.median(const.epochs_utc.astype(np.int64)).astype("datetime64[ns]").astype("datetime64[m]")
    times = utc_from_seconds(np.arange(n_epochs) * step, start)
    out = _out_dir(args.out)
    work_dir = out / f"gdop-map-chunks-{_gdop_digest(args, grid_deg, mask)[:12]}"
    ds = gdop_map(source, times, grid_deg, mask, scheduler=args.scheduler, n_workers=args.workers, work_dir=work_dir)
    from ..fileio import atomic_outputs

    with atomic_outputs(out) as stage:
        write_netcdf(ds, stage / "gdop_map.nc")
        _figures(stage, ds, Path(const.source).name if const.source else "bundled Walker set")
    ChunkStore(work_dir).remove()
    fix = np.isfinite(ds["gdop"].values)
    n_vis = ds["n_visible"].values
    return {
        "study": "gdop-map",
        "netcdf": str(out / "gdop_map.nc"),
        "n_satellites": len(const),
        "n_epochs": n_epochs,
        "grid_deg": grid_deg,
        "mask_deg": mask,
        "start_utc": format_utc(times[0]),
        "end_utc": format_utc(times[-1]),
        "n_visible_mean": float(n_vis.mean()),
        "n_visible_max": int(n_vis.max()),
        "fix_fraction": float(fix.mean()),
        "gdop_median": float(np.median(ds["gdop"].values[fix])) if fix.any() else float("nan"),
    }


def _figures(stage, ds, label):
    from ..plots.maps import plot_fix_fraction, plot_small_multiples

    lat, lon = ds["lat"].values, ds["lon"].values
    gdop = ds["gdop"].values
    times = ds["time"].values
    minute = lambda t: format_utc(t)[:16].replace("T", " ") + " UTC"  # noqa: E731
    title = (f"{label}, {ds.attrs['n_satellites']} satellites, mask {ds.attrs['elevation_mask_deg']:g} deg, "
             f"{ds.attrs['grid_step_deg']:g} deg grid")
    plot_fix_fraction(stage / "fix_fraction.png", lat, lon, np.isfinite(gdop).mean(axis=0),
                      title=f"{title}\n{len(times)} epochs from {minute(times[0])} to {minute(times[-1])}")
    labels = [minute(t) for t in times]
    plot_small_multiples(stage / "n_visible_maps.png", lat, lon, ds["n_visible"].values.astype(float), labels,
                         cbar_label="visible satellites", vmin=0, title=title)
    finite = gdop[np.isfinite(gdop) & (gdop > 0)]
    # GDOP spans decades near the fix threshold: log colours between the 1st and 99th percentiles.
    vmin, vmax = np.percentile(finite, [1, 99]) if finite.size else (1.0, 10.0)
    plot_small_multiples(stage / "gdop_maps.png", lat, lon, gdop, labels,
                         cbar_label="Doppler GDOP [m per Hz] ([Shen 2024] eq. 10)", vmin=float(vmin),
                         vmax=float(max(vmax, vmin * 10)), cmap="magma_r", log_colors=True,
                         title=title + " (blank: < 7 satellites)")


def _out_dir(path):
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory")
    return out


def _gdop_digest(args, grid_deg, mask_deg):
    """Hash of what a map's epochs depend on besides their times: satellites, grid, mask, leosop version and code."""
    key = {"tle": str(Path(args.tle).resolve()) if args.tle else None, "families": sorted(args.constellation or ()),
           "skip_bad": args.skip_bad, "grid_deg": grid_deg, "mask_deg": mask_deg, "code": code_digest()}
    if args.tle:
        stat = Path(args.tle).stat()
        key["tle_file"] = [stat.st_size, stat.st_mtime_ns]
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


def _check_workers(n_workers):
    if n_workers is not None and n_workers < 1:
        raise InputError(f"--workers {n_workers}: expected an integer >= 1")


def _run_montecarlo(args):
    from ..fileio import atomic_outputs
    from ..apps.montecarlo import cell_table, load_spec, run_study, to_dataset, write_netcdf
    from ..plots.montecarlo import plot_study

    _check_workers(args.workers)
    spec = load_spec(args.spec)
    out = _out_dir(args.out)
    work_dir = out / f"montecarlo-chunks-{spec.digest()[:12]}"
    result = run_study(spec, work_dir, scheduler=args.scheduler, n_workers=args.workers, desc=spec.name)
    ds = to_dataset(spec, result.rows)
    with atomic_outputs(out) as stage:
        write_netcdf(ds, stage / "montecarlo.nc")
        fixed = "".join(f", {k} {v}" for k, v in spec.fixed.items())
        figures = plot_study(ds, stage, f"{spec.name}: {spec.scenario.name}{fixed}, seeds {spec.seed}.."
                                        f"{spec.seed + spec.n_seeds - 1}")
    ChunkStore(work_dir).remove()
    return {
        "study": "montecarlo",
        "name": spec.name,
        "netcdf": str(out / "montecarlo.nc"),
        "figures": [str(out / f.name) for f in figures],
        "parameters": {k: list(v) for k, v in spec.axes.items()},
        "fixed": spec.fixed,
        "n_seeds": spec.n_seeds,
        "n_runs": spec.n_runs,
        "n_chunks": result.n_chunks,
        "n_chunks_resumed": result.n_resumed,
        "n_workers": result.n_workers,
        "elapsed_s": result.elapsed_s,
        "cells": cell_table(ds),
    }


def _stat(s, fmt):
    def num(v):
        return "n/a" if v is None else format(v, fmt)

    return f"{num(s['mean'])} ± {num(s['std'])} [{num(s['p10'])}, {num(s['p90'])}]"


def _summary_montecarlo(doc):
    where = f"{doc['n_workers']} Dask workers" if doc["n_workers"] else "this process"
    lines = [f"{doc['netcdf']}: study {doc['name']}, {doc['n_runs']} runs ({doc['n_seeds']} seeds per cell) in "
             f"{doc['n_chunks']} chunks, {doc['n_chunks_resumed']} resumed, {doc['elapsed_s']:.1f} s on {where}",
             "fused error over seeds: mean ± std [10th, 90th percentile]"]
    names = list(doc["parameters"])
    table = [names + ["position m", "velocity m/s", "n"]]
    for c in doc["cells"]:
        p, v = c["fused_pos_err_mean_m"], c["fused_vel_err_mean_mps"]
        table.append([f"{c['parameters'][k]:g}" if isinstance(c["parameters"][k], float) else str(c["parameters"][k])
                      for k in names] + [_stat(p, ".2f"), _stat(v, ".4f"), str(p["n"])])
    widths = [max(len(r[i]) for r in table) for i in range(len(table[0]))]
    lines += ["  ".join(x.rjust(w) for x, w in zip(r, widths)) for r in table]
    return "\n".join(lines)


def summary(doc):
    if doc["study"] == "montecarlo":
        return _summary_montecarlo(doc)
    return "\n".join([
        f"{doc['netcdf']}: {doc['n_epochs']} epochs {doc['start_utc']} .. {doc['end_utc']}, "
        f"{doc['grid_deg']:g} deg grid, {doc['n_satellites']} satellites, mask {doc['mask_deg']:g} deg",
        f"visible satellites: mean {doc['n_visible_mean']:.1f}, max {doc['n_visible_max']}",
        f"cell-epochs with a Doppler fix (>= 7): {doc['fix_fraction']:.1%}; median Doppler GDOP "
        + ("n/a" if doc["gdop_median"] is None else f"{doc['gdop_median']:.1f} m/Hz"),
    ])
