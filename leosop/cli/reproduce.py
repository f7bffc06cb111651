"""``leosop reproduce TARGET``: a table or figure of the seed papers, ours beside theirs.

Each target is one line of :data:`TARGETS`: ``name: ("module:function",
help)``. The function lives in a study module, takes keyword-only options
among ``seed``, ``scheduler``, ``full`` and ``out_dir`` (it receives those it
declares) and returns the JSON document, with the paper's numbers under
``"paper"``. Without ``--json`` the document is printed as text: by the study
module's ``format_table(doc)`` when it has one, else as a flat table of its
``rows``.
"""

import importlib
import inspect
import sys

from ..errors import InputError
from . import add_command

#: Registry of reproducible targets.
TARGETS = {
    "align-fig2": ("leosop.ins.alignment_study:fig2", "[Qu 2024] Fig. 1-2: max alignment errors vs pitch"),
    "align-table1": ("leosop.ins.alignment_study:table1", "[Qu 2024] Table 1: turntable alignment at 80 deg pitch"),
    "errmodel-table3": ("leosop.ins.error_model_study:table3", "[Chu 2009] Table 3: 150 s errors of the 9-state model"),
    "errmodel-validate": ("leosop.ins.error_model_study:validate", "[Chu 2009] sec. 3: error models vs strapdown"),
    "table2": ("leosop.signal.tables:table2", "[Shen 2024] Table 2: grid ML vs FMLEF (and fast) time, N = 3e5"),
    "table3": ("leosop.signal.tables:table3", "[Shen 2024] Table 3: grid ML vs FMLEF (and fast) time per block length"),
    "table4": ("leosop.simulate_study:table4", "[Shen 2024] Table 4: INS alone vs Starlink/INS, Xi'an-Baoji"),
    "table5": ("leosop.simulate_study:table5", "[Shen 2024] Table 5: Starlink/INS errors vs correction period"),
    "table6": ("leosop.simulate_study:table6", "[Shen 2024] Table 6: Starlink/INS errors vs orbit error"),
    "ppp-ins": ("leosop.gnss.ppp_ins_study:ppp_ins_table", "[Liu 2016] vehicle test, simulated: float vs fixed PPP/INS"),
    "multi": ("leosop.multi_study:multi", "multi-constellation LEO/INS in thin skies: loose vs tight, Starlink vs all"),
}


def register(subparsers):
    p = add_command(subparsers, "reproduce", sys.modules[__name__],
                    help="reproduce a table or figure of the seed papers beside the published numbers",
                    description="Targets: " + "; ".join(f"{k}: {v[1]}" for k, v in TARGETS.items()))
    p.add_argument("target", metavar="TARGET", help=f"one of: {', '.join(TARGETS)}")
    p.add_argument("--seed", type=int, default=0, help="random seed of Monte Carlo targets (default 0)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler address for parallel targets (default: a local cluster; 'serial' runs "
                        "in this process)")
    p.add_argument("--full", action="store_true", help="the paper's full grid / more trials (slower)")


def target_function(name):
    """The study function registered as ``name``."""
    if name not in TARGETS:
        raise InputError(f"reproduce: unknown target {name!r}; expected one of {', '.join(TARGETS)}")
    module, func = TARGETS[name][0].split(":")
    return getattr(importlib.import_module(module), func)


def run(args):
    func = target_function(args.target)
    options = {"seed": args.seed, "scheduler": args.scheduler, "full": args.full, "out_dir": args.out}
    accepted = inspect.signature(func).parameters
    doc = func(**{k: v for k, v in options.items() if k in accepted})
    return {"target": args.target, **doc}


def _flat(obj, prefix=""):
    """Nested dicts as ``{"a.b": value}``; lists of numbers joined with '/'."""
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    if isinstance(obj, list):
        obj = "/".join(_cell(v) for v in obj)
    return {prefix[:-1]: obj}


def _cell(v):
    return "-" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)


def summary(doc):
    module = importlib.import_module(TARGETS[doc["target"]][0].split(":")[0])
    if hasattr(module, "format_table"):
        return module.format_table(doc)
    lines = [f"{doc['target']}: {TARGETS[doc['target']][1]}"]
    rows = [_flat(r) for r in doc.get("rows", [])]
    if rows:
        cols = list(dict.fromkeys(k for r in rows for k in r))
        table = [cols] + [[_cell(r.get(c)) for c in cols] for r in rows]
        widths = [max(len(t[i]) for t in table) for i in range(len(cols))]
        lines += ["  ".join(x.rjust(w) for x, w in zip(t, widths)) for t in table]
    rest = {k: v for k, v in doc.items() if k not in ("target", "rows")}
    lines += [f"{k}: {_cell(v)}" for k, v in _flat(rest).items()]
    return "\n".join(lines)
