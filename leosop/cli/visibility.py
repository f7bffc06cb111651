"""``leosop visibility``: visible satellites and Doppler GDOP over time at a site.

``--constellation`` takes one or several families of the carrier table. With
several, every satellite transmits on its family's carrier, each family is a
receiver clock of its own, and ``gdop`` is that of the mix (position,
velocity and one clock per family seen: null below ``6 + k`` satellites of
``k`` families); the JSON document adds ``families`` and
``n_visible_by_family`` and the CSV a ``n_visible_<family>`` column each.

Long spans run in bounded memory: the grid goes by in chunks of
``--chunk-s`` (:mod:`leosop.orbits.chunks`), ``visibility.csv`` and
``passes.csv`` are written as the chunks come, and what is kept of the whole
span is a few numbers per epoch (count and GDOPs for the figure and the
statistics, ~20 bytes). The results do not depend on the chunk. The JSON
document holds the contract's per-epoch lists up to ``--json-max-epochs``
epochs (default a day at 1 s, a ~25 MB document): the size is known before
any work, and a longer span's lists would cost memory in proportion to it.
Beyond that those keys are null, ``per_epoch`` says why and points at the
files that hold them: ``visibility.csv`` (one row per epoch) and
``passes.csv``, whose rise-set intervals are the visible sets (a satellite
is visible at every grid epoch from ``rise_utc`` to ``set_utc`` inclusive).
``stats`` and ``n_passes`` are always there.
"""

import csv
import math
import sys
import warnings
from pathlib import Path

import numpy as np

from ..constellations import DEFAULT_FAMILY, REGISTRY, carriers_hz
from ..errors import InputError
from ..fileio import atomic_outputs, write_json
from ..frames import geodetic_to_ecef
from ..orbits import load_constellation
from ..orbits.chunks import PassStitcher, visibility_chunks
from ..orbits.propagate import drop_failing
from ..timebase import format_utc, seconds_since, utc_from_seconds
from . import add_command
from .options import mask_deg, parse_site, parse_time, positive, warn_stale

#: Defaults of the bundled main job: Xi'an ([Shen 2024]'s start point), one hour
#: from the bundled element sets' epoch, the paper's 40 deg mask.
DEFAULT_SITE = "34.342,108.940,400"
DEFAULT_MASK_DEG = 40.0
#: Chunk length: an hour (3,600 epochs at 1 s, ~60 MB of working memory for 10,000 satellites at a 40 deg mask);
#: a whole number of the 60 s screening steps.
DEFAULT_CHUNK_S = 3600.0
#: Per-epoch lists in the JSON document up to this many epochs: a day at 1 s, both ends included.
DEFAULT_JSON_MAX_EPOCHS = 86_401
#: Points per curve of visibility.png at most: a longer span is drawn as each bin's minimum and maximum (the
#: envelope its ~700 pixel columns show anyway), so the figure's memory does not grow with the span.
PLOT_MAX_POINTS = 20_000


#: What ``--help`` says about the outputs, the Doppler GDOP's meaning above all.
_DESCRIPTION = (
    "Visible satellites above the mask, their passes and the Doppler-positioning GDOP at a site over time. "
    "Doppler GDOP ([Shen 2024] eq. 10) = sqrt(trace((H^T H)^-1)) over the 7 states position [m], velocity "
    "[m/s] and receiver frequency offset [Hz], H in Hz per state unit: the root-sum-square of their standard "
    "deviations for 1 Hz of Doppler noise. Position dominates, so GDOP x Doppler sigma [Hz] ~ 3D position error "
    "[m]; empty/null below 7 satellites (6 + one per constellation). --out DIR writes visibility.csv "
    "(n_visible, gdop: the Doppler GDOP in m per Hz, and the unitless range DOPs per epoch), passes.csv (rise, "
    "culmination, set, max elevation per pass), visibility.json, visibility.png and skyplot.png.")


def register(subparsers):
    p = add_command(subparsers, "visibility", sys.modules[__name__],
                    help="visible satellites and Doppler-positioning GDOP over time at a site",
                    description=_DESCRIPTION)
    p.add_argument("--site", default=DEFAULT_SITE, metavar="LAT_DEG,LON_DEG,ALT_M",
                   help=f"receiver site (default {DEFAULT_SITE}, Xi'an)")
    p.add_argument("--start", metavar="ISO", help="UTC start (default: the median element-set epoch)")
    p.add_argument("--duration-s", type=float, default=3600.0, help="span in seconds (default 3600)")
    p.add_argument("--step-s", type=float, default=1.0, help="epoch step in seconds (default 1)")
    p.add_argument("--mask-deg", type=float, default=DEFAULT_MASK_DEG, help="elevation mask (default 40)")
    p.add_argument("--tle", metavar="FILE", help="TLE or OMM (.json/.csv) file (default: bundled Walker set)")
    p.add_argument("--constellation", nargs="+", metavar="NAME",
                   help=f"use only these families of a mixed file ({', '.join(sorted(REGISTRY))}); several: one "
                   "receiver clock each, GDOP of the mix")
    p.add_argument("--carrier-hz", type=float, help="carrier for the Doppler GDOP (default: the family's; one "
                   "family only)")
    p.add_argument("--skip-bad", action="store_true", help="skip malformed TLE records with a warning")
    p.add_argument("--no-screen", action="store_true", help="propagate every satellite every epoch (slow)")
    p.add_argument("--chunk-s", type=float, default=DEFAULT_CHUNK_S,
                   help=f"work through the span in chunks of this length (default {DEFAULT_CHUNK_S:g}); memory is "
                   "set by the chunk, the results do not depend on it")
    p.add_argument("--json-max-epochs", type=int, default=DEFAULT_JSON_MAX_EPOCHS, metavar="N",
                   help=f"per-epoch lists in the JSON document up to N epochs (default {DEFAULT_JSON_MAX_EPOCHS}, "
                   "a day at 1 s); beyond, they are null and the document points at visibility.csv and passes.csv")


def run(args):
    lat, lon, alt = parse_site(args.site)
    duration = positive(args.duration_s, "--duration-s")
    step = positive(args.step_s, "--step-s")
    mask = mask_deg(args.mask_deg)
    chunk_epochs = max(1, round(positive(args.chunk_s, "--chunk-s") / step))
    if args.json_max_epochs < 0:
        raise InputError(f"--json-max-epochs {args.json_max_epochs}: must be an integer >= 0")
    if args.carrier_hz is not None:
        positive(args.carrier_hz, "--carrier-hz")
    if duration / step > 5_000_000:
        raise InputError(f"--duration-s/--step-s: {duration / step + 1:.3g} epochs is too many (at most 5,000,000)")
    n_epochs = int(np.floor(duration / step + 1e-9)) + 1

    families = _families(args.constellation)
    if len(families) > 1 and args.carrier_hz is not None:
        raise InputError("--carrier-hz applies to one constellation; with several each uses its own carrier "
                         "from the carrier table")
    const = load_constellation(args.tle, skip_bad=args.skip_bad)
    if families:
        for fam in families:
            if not (const.families == fam).any():
                raise InputError(f"{args.tle or 'bundled TLE'}: no {fam} satellites in the file")
        const = const.subset(np.isin(const.families, families))
    if args.start:
        start = parse_time(args.start)
    else:
        median_ns = np.median(const.epochs_utc.astype(np.int64)).astype(np.int64)
        start = median_ns.astype("datetime64[ns]").astype("datetime64[m]").astype("datetime64[ns]")
    warn_stale(const, start)
    ends = utc_from_seconds(np.array([0, n_epochs - 1]) * step, start)
    const = drop_failing(const, ends, what=f"{format_utc(ends[0])} .. {format_utc(ends[1])}")
    family = families[0] if families else next((f for f in const.families if f), DEFAULT_FAMILY)
    carrier_hz = args.carrier_hz or REGISTRY[family].carrier_hz
    clock_group = None
    if len(families) > 1:
        # Each satellite on its family's carrier, each family its own receiver clock.
        clock_group = np.array([families.index(f) for f in const.families])
        carrier_hz = carriers_hz(const.families)

    in_doc = n_epochs <= args.json_max_epochs
    if not in_doc:
        where = "visibility.csv and passes.csv in --out" if args.out else "files only with --out DIR"
        warnings.warn(f"{n_epochs} epochs > --json-max-epochs {args.json_max_epochs}: the per-epoch lists are left "
                      f"out of the JSON document ({where})")
    site = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    run = _Run(const, start, step, n_epochs, families, in_doc)
    chunks = visibility_chunks(const, start, step, n_epochs, site, mask, chunk_epochs=chunk_epochs,
                               screen=not args.no_screen)
    if not args.out:
        for a, vis in chunks:
            run.add(a, vis, carrier_hz, clock_group)
        return run.document(files=False)
    from ..plots.sky import SKYPLOT_WINDOW_S, plot_skyplot, plot_visibility

    title = f"{Path(const.source).name} at {lat:.3f}, {lon:.3f} deg, {alt:g} m"
    with atomic_outputs(Path(args.out)) as stage, open(stage / "visibility.csv", "w", newline="") as rows, \
            open(stage / "passes.csv", "w", newline="") as passes:
        run.write_to(rows, csv.writer(passes))
        for a, vis in chunks:
            run.add(a, vis, carrier_hz, clock_group, sky_window_s=SKYPLOT_WINDOW_S)
        run.close_passes()
        doc = run.document(files=True)
        write_json(stage / "visibility.json", doc, compact=True)
        times, (n_vis, gdop, gdop_range) = _envelope(start, step, run.n_visible, run.gdop, run.gdop_range)
        plot_visibility(stage / "visibility.png", times, n_vis, gdop, gdop_range, mask_deg=mask, title=title)
        az, el, t_s, ids = (np.concatenate(x) for x in zip(*run.sky))
        plot_skyplot(stage / "skyplot.png", az, el, t_s, ids, start, mask_deg=mask, title=title)
    return doc


def _envelope(start, step_s, *series):
    """The per-epoch series for the figure: whole up to :data:`PLOT_MAX_POINTS` epochs, else binned.

    Parameters
    ----------
    start : numpy.datetime64
    step_s : float
    *series : ndarray, (n_epochs,)

    Returns
    -------
    times : ndarray of datetime64[ns], (n_points,)
        The epochs, or each bin's first epoch twice.
    list of ndarray, (n_points,)
        The series, or each bin's minimum then maximum (NaN where a bin has no finite value).
    """
    n = len(series[0])
    k = -(-2 * n // PLOT_MAX_POINTS)  # epochs per bin, two points each
    if k <= 1:
        return utc_from_seconds(np.arange(n) * step_s, start), list(series)
    n_bins = -(-n // k)
    out = []
    for x in series:
        bins = np.full(n_bins * k, np.nan)
        bins[:n] = x
        bins = bins.reshape(n_bins, k)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN bins (too few satellites) stay NaN
            out.append(np.stack([np.nanmin(bins, 1), np.nanmax(bins, 1)], 1).ravel())
    return np.repeat(utc_from_seconds(np.arange(0, n, k) * step_s, start), 2), out


def _families(names):
    """Requested families, validated against the constellation registry, in order without repeats."""
    if not names:
        return []
    out = []
    for name in names:
        for key in (k.strip().lower() for k in name.split(",") if k.strip()):
            if key not in REGISTRY:
                known = ", ".join(sorted(REGISTRY))
                raise InputError(f"--constellation {key!r}: unknown constellation; known: {known}")
            if key not in out:
                out.append(key)
    return out


class _Run:
    """What a run keeps of the whole span, filled chunk by chunk, and the files it streams.

    Kept per epoch: visible count, Doppler and range GDOP (and the counts per
    family), for the statistics and the figure; the contract's per-epoch
    lists only when ``in_doc``; the sky plot's first window of points.
    """

    def __init__(self, const, start, step_s, n_epochs, families, in_doc):
        self.const, self.start, self.step_s, self.families, self.in_doc = const, start, step_s, families, in_doc
        self.n_visible = np.zeros(n_epochs, np.int32)
        self.gdop = np.full(n_epochs, np.nan)
        self.gdop_range = np.full(n_epochs, np.nan)
        self.by_family = np.zeros((n_epochs, len(families)), np.int32) if len(families) > 1 else None
        self.lists = {"epochs_utc": [], "visible_ids": []} if in_doc else None
        self.stitcher = PassStitcher(const.sat_ids, n_epochs)
        self.sky = [(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, str))]
        self.csv = self.passes_csv = None

    def write_to(self, rows, passes):
        """Stream the epochs to ``rows`` (``visibility.csv``, a text file) and the passes to ``passes`` (a csv
        writer).

        The epoch rows are joined here rather than by a csv writer (~20 % faster; no field needs quoting),
        with the csv module's ``\\r\\n`` line ends.
        """
        fams = self.families if self.by_family is not None else []
        self.csv, self.passes_csv = rows, passes
        self.csv.write(",".join(["time_utc", "t_s", "n_visible", "gdop", "gdop_range", "pdop_range", "hdop_range",
                                 "vdop_range"] + [f"n_visible_{f}" for f in fams]) + "\r\n")
        self.passes_csv.writerow(["sat_id", "rise_utc", "culmination_utc", "set_utc", "max_elev_deg", "truncated"])

    def add(self, a, vis, carrier_hz, clock_group, *, sky_window_s=None):
        """Take the chunk whose first epoch is ``a``: keep its per-epoch numbers, write its rows."""
        b = a + len(vis.times_utc)
        self.n_visible[a:b] = vis.n_visible
        self.gdop[a:b] = vis.doppler_gdop(carrier_hz, clock_group)
        if self.by_family is not None:
            self.by_family[a:b] = vis.n_visible_by_group(clock_group)
        epochs = format_utc(vis.times_utc)
        if self.in_doc:
            self.lists["epochs_utc"] += epochs
            self.lists["visible_ids"] += vis.visible_ids()
        passes = self.stitcher.add(a, vis)
        if self.csv is None:
            return
        dops = vis.range_dops()
        self.gdop_range[a:b] = dops["gdop"]
        t_s = seconds_since(vis.times_utc, self.start)
        cols = [self.gdop[a:b], dops["gdop"], dops["pdop"], dops["hdop"], dops["vdop"]]
        text = [[f"{x:.4f}" if math.isfinite(x) else "" for x in c.tolist()] for c in cols]
        per_family = ["".join(f",{n}" for n in nf) for nf in self.by_family[a:b].tolist()] \
            if self.by_family is not None else [""] * len(epochs)
        self.csv.write("".join(f"{e},{t:.3f},{n},{g},{gr},{p},{h},{v}{nf}\r\n" for e, t, n, g, gr, p, h, v, nf in
                               zip(epochs, t_s.tolist(), self.n_visible[a:b].tolist(), *text, per_family)))
        self._write_passes(passes)
        t_pair = seconds_since(vis.times_utc[vis.epoch_index], self.start)
        near = t_pair <= sky_window_s
        if near.any():
            self.sky.append((vis.az_rad[near], vis.elev_rad[near], t_pair[near],
                             vis.sat_ids[vis.sat_index[near]]))

    def close_passes(self):
        """Write the passes held until the end."""
        self._write_passes(self.stitcher.finish())

    def _write_passes(self, passes):
        # One format_utc call for all the instants (per pass, it was most of the cost).
        t = format_utc(np.array([(p.rise_utc, p.culmination_utc, p.set_utc) for p in passes], "datetime64[ns]"))
        self.passes_csv.writerows([p.sat_id, *t[3 * i:3 * i + 3], f"{p.max_elev_deg:.3f}", int(p.truncated)]
                                  for i, p in enumerate(passes))

    def document(self, *, files):
        """The JSON document: the contract's keys (per-epoch lists or null), ``stats``, ``per_epoch``."""
        fixable = np.isfinite(self.gdop)
        g = self.gdop[fixable]
        stats = {"n_visible_min": int(self.n_visible.min()), "n_visible_median": float(np.median(self.n_visible)),
                 "n_visible_max": int(self.n_visible.max()), "fixable_fraction": float(fixable.mean()),
                 "gdop_median": float(np.median(g)) if g.size else None,
                 "gdop_max": float(g.max()) if g.size else None}
        if not files:
            self.stitcher.finish()
        doc = {
            "epochs_utc": self.lists["epochs_utc"] if self.in_doc else None,
            "n_visible": self.n_visible.tolist() if self.in_doc else None,
            "gdop": self.gdop.tolist() if self.in_doc else None,
            "visible_ids": self.lists["visible_ids"] if self.in_doc else None,
            "n_epochs": len(self.n_visible),
            "start_utc": format_utc(self.start),
            "step_s": self.step_s,
            "n_passes": self.stitcher.n_passes,
            "stats": stats,
            "per_epoch": {"in_document": self.in_doc, "files": {
                "epochs_utc": "visibility.csv:time_utc", "n_visible": "visibility.csv:n_visible",
                "gdop": "visibility.csv:gdop",
                "visible_ids": "passes.csv:sat_id,rise_utc,set_utc (visible at every epoch from rise to set)",
            } if files else None},
        }
        if self.by_family is not None:
            doc["families"] = self.families
            doc["n_visible_by_family"] = {f: self.by_family[:, j].tolist() if self.in_doc else None
                                          for j, f in enumerate(self.families)}
            stats["n_visible_by_family"] = {
                f: {"min": int(c.min()), "median": float(np.median(c)), "max": int(c.max())}
                for f, c in zip(self.families, self.by_family.T)}
        return doc


def summary(doc):
    st = doc["stats"]
    lines = [
        f"{doc['n_epochs']} epochs of {doc['step_s']:g} s from {doc['start_utc']}, {doc['n_passes']} passes",
        (f"visible satellites: min {st['n_visible_min']}, median {st['n_visible_median']:g}, "
         f"max {st['n_visible_max']}"),
        f"epochs with >= 7 satellites (Doppler fix possible): {st['fixable_fraction']:.1%}" if "families" not in doc
        else f"epochs with >= 6 + one per constellation seen (Doppler fix possible): {st['fixable_fraction']:.1%}",
    ]
    for fam, c in st.get("n_visible_by_family", {}).items():
        lines.append(f"  {fam}: min {c['min']}, median {c['median']:g}, max {c['max']}")
    if st["gdop_median"] is not None:
        lines.append(f"Doppler GDOP (m of position per Hz of Doppler noise): median {st['gdop_median']:.1f}, "
                     f"max {st['gdop_max']:.1f}")
    if not doc["per_epoch"]["in_document"]:
        lines.append("per-epoch lists: " + ("in visibility.csv and passes.csv" if doc["per_epoch"]["files"] else
                                            "not kept (--out DIR writes them)"))
    return "\n".join(lines)
