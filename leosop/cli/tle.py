"""``leosop tle``: fetch current element sets, or summarise a file.

``info FILE --out DIR`` writes the summary as ``tle_info.json`` and one row
per satellite as ``satellites.csv``. ``fetch`` writes the one file named by
``-o`` and refuses ``--out``.
"""

import argparse
import sys

import numpy as np

from ..fileio import atomic_outputs, write_csv, write_json
from ..orbits import load_constellation
from ..orbits.fetch import fetch_group
from ..timebase import format_utc
from . import add_action, add_command

#: Columns of ``satellites.csv``.
SATELLITE_COLUMNS = ("sat_id", "name", "family", "epoch_utc", "inclination_deg", "eccentricity",
                     "mean_motion_rev_per_day")


class _RefuseOut(argparse.Action):
    """``fetch --out``: an option error, not a silent abbreviation of ``--output``."""

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(f"--out {values}: fetch writes one file, named by -o/--output; --out has no meaning here")


def register(subparsers):
    p = add_command(subparsers, "tle", sys.modules[__name__], help="fetch or summarise element-set files", out=False)
    sub = p.add_subparsers(dest="tle_command", metavar="ACTION", required=True)
    f = add_action(sub, "fetch", help="download a CelesTrak group (needs the network)")
    f.add_argument("group", metavar="GROUP", help="CelesTrak group, e.g. starlink, oneweb, iridium-NEXT, active")
    f.add_argument("-o", "--output", required=True, metavar="FILE", help="file to write")
    f.add_argument("--format", default="tle", choices=("tle", "json", "csv"), help="TLE or OMM JSON/CSV")
    f.add_argument("--url", help="http(s) endpoint instead of CelesTrak's gp.php")
    f.add_argument("--out", action=_RefuseOut, help=argparse.SUPPRESS)
    i = add_action(sub, "info", help="count satellites by family and show the epoch span")
    i.add_argument("file", metavar="FILE")
    i.add_argument("--skip-bad", action="store_true", help="skip malformed records with a warning")
    i.add_argument("--out", metavar="DIR", help="directory for tle_info.json (this summary) and satellites.csv "
                                                f"(one row per satellite: {', '.join(SATELLITE_COLUMNS)})")


def run(args):
    if args.tle_command == "fetch":
        const = fetch_group(args.group, args.output, fmt=args.format, base_url=args.url)
        doc = _describe(const)
        doc["written"] = args.output
        return doc
    const = load_constellation(args.file, skip_bad=args.skip_bad)
    doc = _describe(const)
    if args.out:
        with atomic_outputs(args.out) as stage:
            write_json(stage / "tle_info.json", doc)
            write_csv(stage / "satellites.csv", SATELLITE_COLUMNS, _satellite_rows(const))
    return doc


def _describe(const):
    families, counts = np.unique(const.families, return_counts=True)
    ep = np.sort(const.epochs_utc)
    return {
        "source": const.source,
        "n_sats": len(const),
        "by_family": {str(f or "other"): int(c) for f, c in zip(families, counts)},
        "epoch_min_utc": format_utc(ep[0]),
        "epoch_median_utc": format_utc(ep[len(ep) // 2]),
        "epoch_max_utc": format_utc(ep[-1]),
    }


def _satellite_rows(const):
    """One CSV row per satellite: identity, epoch and three mean elements (SGP4's, at the epoch)."""
    rev_per_day = 1440.0 / (2.0 * np.pi)  # SGP4 keeps the mean motion in rad/min
    return ([sid, name, fam or "other", epoch, f"{np.degrees(s.inclo):.4f}", f"{s.ecco:.7f}",
             f"{s.no_kozai * rev_per_day:.8f}"]
            for sid, name, fam, epoch, s in zip(const.sat_ids, const.names, const.families,
                                                format_utc(const.epochs_utc), const.satrecs))


def summary(doc):
    fam = ", ".join(f"{k} {v}" for k, v in doc["by_family"].items())
    head = f"wrote {doc['written']}: " if "written" in doc else f"{doc['source']}: "
    return (f"{head}{doc['n_sats']} satellites ({fam}); epochs {doc['epoch_min_utc']} .. "
            f"{doc['epoch_max_utc']} (median {doc['epoch_median_utc']})")
