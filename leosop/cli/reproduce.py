"""``leosop reproduce TARGET``: a table or figure of the seed papers, ours beside theirs.

The targets, their papers and functions are the registry
:data:`leosop.apps.repro.TARGETS`. Without ``--json`` the document is printed as
text: by the target module's ``format_table(doc)`` when it has one, else as a
flat table of its ``rows``.
"""

import argparse
import sys

from ..apps.repro import TARGETS, flat_row, run_target, target_module
from . import add_command


def register(subparsers):
    width = max(map(len, TARGETS))
    p = add_command(subparsers, "reproduce", sys.modules[__name__],
                    help="reproduce a table or figure of the seed papers beside the published numbers",
                    description="Reproduce a table or figure of the seed papers; ours beside the published "
                                "numbers.\n\ntargets:\n"
                                + "\n".join(f"  {k:<{width}}  {t.help}" for k, t in TARGETS.items()))
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("target", metavar="TARGET", help=f"one of: {', '.join(TARGETS)}")
    p.add_argument("--seed", type=int, default=0, help="random seed of Monte Carlo targets (default 0)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler address for parallel targets (default: a local cluster; 'serial' runs "
                        "in this process)")
    p.add_argument("--full", action="store_true", help="the paper's full grid / more trials (slower)")
    p.add_argument("--data", metavar="DIR", help="folder of the real data a target needs (ppp-ins: the GRG "
                   "orbits and clocks of 2020-06-25; multi: the 2021-08-06 TLE snapshot of its high-latitude row; "
                   "default $LEOSOP_DATA)")


def run(args):
    # --out: NAME.json, NAME.csv and the target's figures, all or nothing (leosop.apps.repro.run_target).
    return run_target(args.target, out_dir=args.out, seed=args.seed, scheduler=args.scheduler, full=args.full,
                      data_dir=args.data)


def _cell(v):
    if isinstance(v, list):
        return "/".join(_cell(x) for x in v)
    return "-" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)


def summary(doc):
    module = target_module(doc["target"])
    if hasattr(module, "format_table"):
        return module.format_table(doc)
    lines = [f"{doc['target']}: {TARGETS[doc['target']].help}"]
    rows = [flat_row(r) for r in doc.get("rows", [])]
    if rows:
        cols = list(dict.fromkeys(k for r in rows for k in r))
        table = [cols] + [[_cell(r.get(c)) for c in cols] for r in rows]
        widths = [max(len(t[i]) for t in table) for i in range(len(cols))]
        lines += ["  ".join(x.rjust(w) for x, w in zip(t, widths)) for t in table]
    rest = {k: v for k, v in doc.items() if k not in ("target", "rows")}
    lines += [f"{k}: {_cell(v)}" for k, v in flat_row(rest).items()]
    return "\n".join(lines)
