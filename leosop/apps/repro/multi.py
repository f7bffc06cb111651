"""Multi-constellation LEO/INS in thin skies: loose vs tight, Starlink alone vs all families, side by side.

The degraded-sky scenarios bundled in ``leosop/data/scenarios`` (see the
README there), each flown at measurement level with Starlink alone and with
every family of its ``leo.constellations``, loosely and tightly coupled, over
the same seeds (a seed gives the same IMU errors in every column):

- ``xian-baoji-multi``: [Shen 2024]'s flight, all four families (open sky);
- ``high-latitude``: 68 N, 25 deg mask, the 2021-08-06 active snapshot
  (no Starlink rises: the real 2021 sky had only the 53 deg shells);
- ``urban-canyon``: [Shen 2024]'s flight under a 60 deg mask;
- ``outage``: the open-sky flight with only the 3 highest satellites tracked
  from 300 to 480 s; its ``outage`` columns are the mean errors over that
  window, beside the same window of the open-sky run.

The high-latitude row needs the real snapshot its scenario names in the data
folder (``$LEOSOP_DATA``, :mod:`leosop.datadir`); without it the row says why
and is skipped, with a warning (nothing is substituted).
"""

import dataclasses
import warnings

import numpy as np

from ...errors import InputError
from ..scenarios import load_scenario, scenario_tle
from ..simulate import metrics, run_scenario
from ..studies import map_chunks

__all__ = ["SCENARIOS", "run_case", "available", "lag_pairs", "multi", "format_table"]

#: Scenarios of the comparison (bundled files, by name).
SCENARIOS = ("xian-baoji-multi", "high-latitude", "urban-canyon", "outage")
COUPLINGS = ("loose", "tight")
#: Columns: Starlink alone, or every family of the scenario.
SKIES = ("starlink", "all")


def _scenario(name, sky, outage=True):
    sc = load_scenario(name)
    leo = sc.leo
    if sky == "starlink":
        # Starlink keeps its own mask; the other families' masks go with them.
        leo = dataclasses.replace(leo, constellations=("starlink",), mask_deg_by_family={
            f: m for f, m in leo.mask_deg_by_family.items() if f == "starlink"})
    if not outage:
        leo = dataclasses.replace(leo, outage_s=None)
    return dataclasses.replace(sc, leo=leo)


def run_case(chunk, rng=None):
    """One run: ``chunk = (scenario name, sky, coupling, seed, outage, tle)``; ``rng`` unused (the seed is in it).

    ``tle`` is the scenario's element-set file (:func:`leosop.apps.scenarios.scenario_tle`), None for the bundled sky.

    Returns
    -------
    dict
        ``pos``, ``vel`` (fused mean errors, m and m/s), ``ins_pos``,
        ``availability``, ``aided`` (the fraction of epochs LEO aided), ``n_fixes``, ``window_pos``/``window_vel`` (mean
        over the scenario's outage window, else NaN), ``window_end_pos`` (at its end), ``nees`` (n,) of
        position and velocity, ``nis``/``nis_dof`` sums, and ``lag``: the
        whitened innovations at consecutive updates (loose: the 6-vectors;
        tight: each satellite's normalised Doppler), (2, m).
    """
    name, sky, coupling, seed, outage, tle = chunk
    sc = _scenario(name, sky, outage)
    r = run_scenario(sc, level="measurement", coupling=coupling, seed=seed, tle=tle)
    m = metrics(r)
    err = r.errors()["fused"]
    window = load_scenario(name).leo.outage_s
    inside = (r.t_s >= window[0]) & (r.t_s <= window[1]) if window else np.zeros(r.t_s.size, bool)
    nis, dof = r.nis()
    return {
        "pos": m["fused"]["pos_err_mean_m"], "vel": m["fused"]["vel_err_mean_mps"],
        "ins_pos": m["ins_only"]["pos_err_mean_m"], "availability": m["fused"]["availability"],
        "aided": m["fused"]["aided_fraction"], "n_fixes": m["leo_fix"]["n_fixes"],
        "window_pos": float(err[0][inside].mean()) if inside.any() else float("nan"),
        "window_vel": float(err[1][inside].mean()) if inside.any() else float("nan"),
        "window_end_pos": float(err[0][inside][-1]) if inside.any() else float("nan"),
        "nees": r.nees()[1:], "nis": float(np.nansum(nis)), "nis_dof": int(dof.sum()), "lag": lag_pairs(r),
    }


def lag_pairs(result):
    """Whitened innovations and their successors one update later, (2, m).

    Loose: the 6-vectors whitened by their ``S``; tight: each satellite's
    normalised Doppler innovation at consecutive epochs.
    """
    f = result.fused
    if f.innovation is not None:
        u = f.updated
        if not u.any():
            return np.zeros((2, 0))
        L = np.linalg.cholesky(f.innovation_cov[u])
        white = np.linalg.solve(L, f.innovation[u][..., None])[..., 0]
        return np.stack([white[:-1].ravel(), white[1:].ravel()])
    d = np.sort(f.doppler_innovation, order=("sat", "epoch"))
    nxt = (d["sat"][1:] == d["sat"][:-1]) & (d["epoch"][1:] == d["epoch"][:-1] + 1)
    return np.stack([d["normalized"][:-1][nxt], d["normalized"][1:][nxt]])


def available(name, data_dir=None):
    """None if the scenario can run here, else why not (its element-set file is absent).

    ``data_dir``: the data folder (default ``$LEOSOP_DATA``) of a file the scenario names there.
    """
    try:
        scenario_tle(load_scenario(name), data_dir)
    except InputError as exc:
        return str(exc)
    return None


def multi(*, seed=0, scheduler=None, full=False, data_dir=None):
    """Loose vs tight, Starlink alone vs all families, for every scenario of :data:`SCENARIOS`.

    Means over 2 seeds (``full``: 10) at measurement level; ``outage`` adds
    the open-sky run's errors over the outage window. ``data_dir``: the data
    folder (default ``$LEOSOP_DATA``) for ``high-latitude``'s snapshot; a
    scenario that cannot run is skipped with a warning and its row says why.
    """
    seeds = [seed + k for k in range(10 if full else 2)]
    skipped = {n: why for n in SCENARIOS if (why := available(n, data_dir)) is not None}
    for n, why in skipped.items():
        warnings.warn(f"multi: row {n} skipped: {why}", stacklevel=2)
    tles = {n: scenario_tle(load_scenario(n), data_dir) for n in SCENARIOS if n not in skipped}
    chunks = [(n, sky, c, s, True, tle) for n, tle in tles.items() for sky in SKIES for c in COUPLINGS
              for s in seeds]
    chunks += [("outage", "all", c, s, False, tles["outage"]) for c in COUPLINGS for s in seeds if "outage" in tles]
    results = {ch[:5]: r for ch, r in zip(chunks, map_chunks(run_case, chunks, seed=0, scheduler=scheduler,
                                                             desc="multi"))}
    rows = []
    for n in SCENARIOS:
        if n in skipped:
            rows.append({"scenario": n, "skipped": skipped[n]})
            continue
        row = {"scenario": n, "ins_pos_err_m": float(np.mean([results[(n, "all", "loose", s, True)]["ins_pos"]
                                                               for s in seeds]))}
        for sky in SKIES:
            for c in COUPLINGS:
                runs = [results[(n, sky, c, s, True)] for s in seeds]
                row[f"{sky}_{c}"] = {"pos_err_m": _mean(runs, "pos"), "vel_err_mps": _mean(runs, "vel"),
                                     "availability": _mean(runs, "availability"),
                                     "aided_fraction": _mean(runs, "aided"), "fixes": _mean(runs, "n_fixes")}
                if n == "outage":
                    row[f"{sky}_{c}"]["window_pos_err_m"] = _mean(runs, "window_pos")
        if n == "outage":
            for c in COUPLINGS:
                runs = [results[(n, "all", c, s, False)] for s in seeds]
                row[f"open_sky_{c}"] = {"window_pos_err_m": _mean(runs, "window_pos")}
        rows.append(row)
    return {"level": "measurement", "seeds": seeds, "rows": rows}


def _mean(runs, key):
    return float(np.mean([r[key] for r in runs]))


def format_table(doc):
    """The ``multi`` document as text: one line per scenario, errors [m] and [m/s] side by side."""
    cols = [(sky, c) for sky in SKIES for c in COUPLINGS]
    head = f"{'scenario':18s}{'INS only':>10s}" + "".join(f"{sky + ' ' + c:>20s}" for sky, c in cols)
    lines = [f"multi: loose vs tight, Starlink alone vs all families (measurement level, seeds {doc['seeds']}); "
             "mean 3D error m / m/s (% of epochs LEO aided)", head]
    for row in doc["rows"]:
        if "skipped" in row:
            lines.append(f"{row['scenario']:18s}skipped: {row['skipped']}")
            continue
        cells = [f"{row[f'{sky}_{c}']['pos_err_m']:8.2f} /{row[f'{sky}_{c}']['vel_err_mps']:6.3f}"
                 f"({100 * row[f'{sky}_{c}']['aided_fraction']:3.0f}%)" for sky, c in cols]
        lines.append(f"{row['scenario']:18s}{row['ins_pos_err_m']:10.1f}" + "".join(f"{x:>20s}" for x in cells))
        if row["scenario"] == "outage":
            w = "  ".join(f"{c} {row[f'all_{c}']['window_pos_err_m']:.2f} m (open sky "
                          f"{row[f'open_sky_{c}']['window_pos_err_m']:.2f} m)" for c in COUPLINGS)
            lines.append(f"{'':18s}during the outage, all families: {w}")
    return "\n".join(lines)
