"""``leosop tle``: fetch current element sets, or summarise a file."""

import sys

import numpy as np

from ..orbits import load_constellation
from ..orbits.fetch import fetch_group
from ..timebase import format_utc
from . import add_command


def register(subparsers):
    p = add_command(subparsers, "tle", sys.modules[__name__], help="fetch or summarise element-set files")
    sub = p.add_subparsers(dest="tle_command", metavar="ACTION", required=True)
    f = sub.add_parser("fetch", help="download a CelesTrak group (needs the network)")
    f.add_argument("group", metavar="GROUP", help="CelesTrak group, e.g. starlink, oneweb, iridium-NEXT, active")
    f.add_argument("-o", "--output", required=True, metavar="FILE", help="file to write")
    f.add_argument("--format", default="tle", choices=("tle", "json", "csv"), help="TLE or OMM JSON/CSV")
    f.add_argument("--url", help="endpoint instead of CelesTrak's gp.php")
    i = sub.add_parser("info", help="count satellites by family and show the epoch span")
    i.add_argument("file", metavar="FILE")
    i.add_argument("--skip-bad", action="store_true", help="skip malformed records with a warning")
    for q in (f, i):
        q.add_argument("--json", action="store_true", help="print one JSON document on stdout")


def run(args):
    if args.tle_command == "fetch":
        const = fetch_group(args.group, args.output, fmt=args.format, base_url=args.url)
        doc = _describe(const)
        doc["written"] = args.output
        return doc
    return _describe(load_constellation(args.file, skip_bad=args.skip_bad))


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


def summary(doc):
    fam = ", ".join(f"{k} {v}" for k, v in doc["by_family"].items())
    head = f"wrote {doc['written']}: " if "written" in doc else f"{doc['source']}: "
    return (f"{head}{doc['n_sats']} satellites ({fam}); epochs {doc['epoch_min_utc']} .. "
            f"{doc['epoch_max_utc']} (median {doc['epoch_median_utc']})")
