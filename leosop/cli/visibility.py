"""``leosop visibility``: visible satellites and Doppler GDOP over time at a site.

``--constellation`` takes one or several families of the carrier table. With
several, every satellite transmits on its family's carrier, each family is a
receiver clock of its own, and ``gdop`` is that of the mix (position,
velocity and one clock per family seen: null below ``6 + k`` satellites of
``k`` families); the JSON document adds ``families`` and
``n_visible_by_family`` and the CSV a ``n_visible_<family>`` column each.
"""

import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import atomic_outputs, write_csv, write_json
from ..frames import geodetic_to_ecef
from ..orbits import CARRIERS, load_constellation
from ..orbits.propagate import drop_failing
from ..orbits.visibility import compute_visibility
from ..timebase import format_utc, seconds_since, utc_from_seconds
from . import add_command
from .options import mask_deg, parse_site, parse_time, positive, warn_stale

#: Defaults of the bundled main job: Xi'an ([Shen 2024]'s start point), one hour
#: from the bundled element sets' epoch, the paper's 40 deg mask.
DEFAULT_SITE = "34.342,108.940,400"
DEFAULT_MASK_DEG = 40.0


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
                   help=f"use only these families of a mixed file ({', '.join(sorted(CARRIERS))}); several: one "
                   "receiver clock each, GDOP of the mix")
    p.add_argument("--carrier-hz", type=float, help="carrier for the Doppler GDOP (default: the family's; one "
                   "family only)")
    p.add_argument("--skip-bad", action="store_true", help="skip malformed TLE records with a warning")
    p.add_argument("--no-screen", action="store_true", help="propagate every satellite every epoch (slow)")


def run(args):
    lat, lon, alt = parse_site(args.site)
    duration = positive(args.duration_s, "--duration-s")
    step = positive(args.step_s, "--step-s")
    mask = mask_deg(args.mask_deg)
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
        start = np.median(const.epochs_utc.astype(np.int64)).astype("datetime64[ns]").astype("datetime64[m]")
    warn_stale(const, start)
    times = utc_from_seconds(np.arange(n_epochs) * step, start)
    const = drop_failing(const, times[[0, -1]], what=f"{format_utc(times[0])} .. {format_utc(times[-1])}")
    family = families[0] if families else next((f for f in const.families if f), "starlink")
    carrier_hz = args.carrier_hz or CARRIERS[family].default_hz
    clock_group = None
    if len(families) > 1:
        # Each satellite on its family's carrier, each family its own receiver clock.
        clock_group = np.array([families.index(f) for f in const.families])
        carrier_hz = np.array([CARRIERS[f].default_hz for f in const.families])

    site = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    vis = compute_visibility(const, times, site, mask, screen=not args.no_screen)
    gdop = vis.doppler_gdop(carrier_hz, clock_group)
    doc = {
        "epochs_utc": format_utc(times),
        "n_visible": vis.n_visible.tolist(),
        "gdop": [None if not np.isfinite(g) else float(g) for g in gdop],
        "visible_ids": vis.visible_ids(),
    }
    if len(families) > 1:
        counts = vis.n_visible_by_group(clock_group)
        doc["families"] = families
        doc["n_visible_by_family"] = {f: counts[:, j].tolist() for j, f in enumerate(families)}
    if args.out:
        title = f"{Path(const.source).name} at {lat:.3f}, {lon:.3f} deg, {alt:g} m"
        _write_outputs(Path(args.out), doc, vis, gdop, times, mask, title)
    return doc


def _families(names):
    """Requested families, validated against the carrier table, in order without repeats."""
    if not names:
        return []
    out = []
    for name in names:
        for key in (k.strip().lower() for k in name.split(",") if k.strip()):
            if key not in CARRIERS:
                known = ", ".join(sorted(CARRIERS))
                raise InputError(f"--constellation {key!r}: unknown constellation; known: {known}")
            if key not in out:
                out.append(key)
    return out


def _write_outputs(out, doc, vis, gdop, times, mask, title):
    with atomic_outputs(out) as stage:
        _write_files(stage, doc, vis, gdop, times, mask, title)


def _write_files(out, doc, vis, gdop, times, mask, title):
    from ..plots.sky import plot_skyplot, plot_visibility

    write_json(out / "visibility.json", doc, compact=True)
    t_s = seconds_since(times, times[0])
    dops = vis.range_dops()
    blank = lambda x: "" if not np.isfinite(x) else f"{x:.4f}"  # noqa: E731
    by_family = doc.get("n_visible_by_family", {})
    per_family = list(zip(*by_family.values())) if by_family else [()] * len(t_s)
    write_csv(out / "visibility.csv",
              ["time_utc", "t_s", "n_visible", "gdop", "gdop_range", "pdop_range", "hdop_range", "vdop_range"]
              + [f"n_visible_{f}" for f in by_family],
              ([e, f"{t:.3f}", n, blank(g), blank(a), blank(b), blank(c), blank(d), *nf]
               for e, t, n, g, a, b, c, d, nf in
               zip(doc["epochs_utc"], t_s, doc["n_visible"], gdop, dops["gdop"], dops["pdop"], dops["hdop"],
                   dops["vdop"], per_family)))
    write_csv(out / "passes.csv", ["sat_id", "rise_utc", "culmination_utc", "set_utc", "max_elev_deg", "truncated"],
              ([p.sat_id, format_utc(p.rise_utc), format_utc(p.culmination_utc), format_utc(p.set_utc),
                f"{p.max_elev_deg:.3f}", int(p.truncated)] for p in vis.passes()))
    plot_visibility(out / "visibility.png", times, vis.n_visible, gdop, dops["gdop"], mask_deg=mask, title=title)
    plot_skyplot(out / "skyplot.png", vis.az_rad, vis.elev_rad, t_s[vis.epoch_index], vis.sat_ids[vis.sat_index],
                 times[0], mask_deg=mask, title=title)


def summary(doc):
    n = np.array(doc["n_visible"])
    g = np.array([np.nan if x is None else x for x in doc["gdop"]])
    fixable = np.isfinite(g)
    lines = [
        f"{len(n)} epochs from {doc['epochs_utc'][0]} to {doc['epochs_utc'][-1]}",
        f"visible satellites: min {n.min()}, median {np.median(n):g}, max {n.max()}",
        f"epochs with >= 7 satellites (Doppler fix possible): {fixable.mean():.1%}" if "families" not in doc else
        f"epochs with >= 6 + one per constellation seen (Doppler fix possible): {fixable.mean():.1%}",
    ]
    for fam, counts in doc.get("n_visible_by_family", {}).items():
        c = np.array(counts)
        lines.append(f"  {fam}: min {c.min()}, median {np.median(c):g}, max {c.max()}")
    if fixable.any():
        lines.append(f"Doppler GDOP (m of position per Hz of Doppler noise): median {np.median(g[fixable]):.1f}, "
                     f"max {g[fixable].max():.1f}")
    return "\n".join(lines)
