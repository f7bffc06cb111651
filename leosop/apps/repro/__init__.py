"""Paper reproductions: one home for every table and figure of the seed papers, ours beside theirs.

:data:`TARGETS` is the registry ``leosop reproduce`` takes its choices and
help from: one :class:`Target` per name, naming its paper ([Shen 2024],
[Qu 2024], [Chu 2009], [Liu 2016]), what it reproduces and the function that
does it. A target function takes keyword-only options among ``seed``,
``scheduler``, ``full``, ``data_dir`` and ``out_dir`` (it receives those it declares) and
returns a JSON document with the paper's numbers under ``"paper"``; its
module may define ``format_table(doc)`` for the text output.

:func:`run_target` runs one; with an output directory (``reproduce --out
DIR``) it writes, all or nothing, ``NAME.json`` (the document, NAME the
target with ``_`` for ``-``), ``NAME.csv`` (its ``rows``, one column per
value, nested keys joined by ``.``, lists by ``/``; a target that lays out its own table
writes it) and the target's figures: the function gets ``out_dir`` (the
staging directory) when it declares it.

Modules: :mod:`.doppler_tables` ([Shen 2024] Tables 2-3, estimator run
time), :mod:`.fusion_tables` ([Shen 2024] Tables 4-6, Starlink/INS),
:mod:`.multi` (multi-constellation LEO/INS in thin skies), :mod:`.alignment`
([Qu 2024], coarse alignment), :mod:`.error_model` ([Chu 2009], short-time
INS error models), :mod:`.ppp_ins_study` ([Liu 2016], tight PPP/INS,
simulated).

Dependencies point downward only: this package imports the library
(signal, ins, fusion, gnss, ...) and the other applications; only ``cli``
imports it (tests/project/test_layers.py). Target functions are imported when a target runs, so listing the
targets costs nothing.

Figures: a reproduction's live in its module here, every other in
:mod:`leosop.plots` (one module per source of data); :mod:`leosop.plots.core`
is the one place matplotlib is configured and figures are saved.
"""

import dataclasses
import importlib
import inspect

from ...errors import InputError
from ...fileio import atomic_outputs, write_csv, write_json

__all__ = ["Target", "TARGETS", "target_function", "target_module", "run_target", "flat_row"]


@dataclasses.dataclass(frozen=True)
class Target:
    """One reproducible table or figure.

    Attributes
    ----------
    paper : str
        The paper's citation key, e.g. ``"[Shen 2024]"``.
    item : str
        What of the paper it reproduces, e.g. ``"Table 4"``.
    description : str
        One line on what is compared.
    function : str
        ``"module:function"`` computing the JSON document.
    """

    paper: str
    item: str
    description: str
    function: str

    @property
    def help(self):
        """One-line help: ``"[Shen 2024] Table 4: ..."``."""
        return f"{self.paper} {self.item}: {self.description}"


#: Registry of reproducible targets (names are part of the CLI contract).
TARGETS = {
    "align-fig2": Target("[Qu 2024]", "Fig. 1-2", "max alignment errors vs pitch, all attitudes",
                         "leosop.apps.repro.alignment:fig2"),
    "align-table1": Target("[Qu 2024]", "Table 1", "turntable alignment at 80 deg pitch",
                           "leosop.apps.repro.alignment:table1"),
    "errmodel-table3": Target("[Chu 2009]", "Table 3", "150 s errors of the 9-state error model",
                              "leosop.apps.repro.error_model:table3"),
    "errmodel-validate": Target("[Chu 2009]", "sec. 3", "short-time error models vs strapdown",
                                "leosop.apps.repro.error_model:validate"),
    "table2": Target("[Shen 2024]", "Table 2", "grid ML vs FMLEF (and fast) run time, N = 3e5",
                     "leosop.apps.repro.doppler_tables:table2"),
    "table3": Target("[Shen 2024]", "Table 3", "grid ML vs FMLEF (and fast) run time per block length",
                     "leosop.apps.repro.doppler_tables:table3"),
    "table4": Target("[Shen 2024]", "Table 4", "INS alone vs Starlink/INS, Xi'an-Baoji flight",
                     "leosop.apps.repro.fusion_tables:table4"),
    "table5": Target("[Shen 2024]", "Table 5", "Starlink/INS errors vs correction period",
                     "leosop.apps.repro.fusion_tables:table5"),
    "table6": Target("[Shen 2024]", "Table 6", "Starlink/INS errors vs orbit error",
                     "leosop.apps.repro.fusion_tables:table6"),
    "ppp-ins": Target("[Liu 2016]", "sec. 4", "vehicle test, simulated: float vs fixed PPP/INS",
                      "leosop.apps.repro.ppp_ins_study:ppp_ins_table"),
    "multi": Target("[Shen 2024]", "extension", "multi-constellation LEO/INS in thin skies: loose vs tight, "
                    "Starlink vs all", "leosop.apps.repro.multi:multi"),
}


def target_module(name):
    """The module holding target ``name``'s function.

    Raises
    ------
    InputError
        ``name`` is not a registered target.
    """
    if name not in TARGETS:
        raise InputError(f"reproduce: unknown target {name!r}; expected one of {', '.join(TARGETS)}")
    return importlib.import_module(TARGETS[name].function.split(":")[0])


def target_function(name):
    """The function computing target ``name``'s JSON document (see :func:`target_module`)."""
    return getattr(target_module(name), TARGETS[name].function.split(":")[1])


def flat_row(obj, prefix=""):
    """A nested dict as one level, ``{"a.b": value}`` (lists kept as values)."""
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            out.update(flat_row(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: obj}


def _csv_cell(value):
    """A CSV cell: empty for None, lists joined with ``/``."""
    if isinstance(value, list):
        return "/".join(_csv_cell(v) for v in value)
    return "" if value is None else str(value)


def run_target(name, *, out_dir=None, **options):
    """Run target ``name`` with the ``options`` its function declares; its document, ``{"target": name, ...}``.

    Parameters
    ----------
    name : str
        A key of :data:`TARGETS`.
    out_dir : path-like, optional
        Where to write ``NAME.json``, ``NAME.csv`` and the figures (module
        docstring); nothing of them is left there should the run fail.
    **options
        Among ``seed``, ``scheduler``, ``full``, ``data_dir`` (the data
        folder, :mod:`leosop.datadir`); those the function does not declare
        are not passed.
    """
    func = target_function(name)
    accepted = inspect.signature(func).parameters
    kwargs = {k: v for k, v in options.items() if k in accepted}
    if out_dir is None:
        return {"target": name, **func(**kwargs)}
    with atomic_outputs(out_dir) as stage:
        doc = {"target": name, **func(**kwargs, **({"out_dir": stage} if "out_dir" in accepted else {}))}
        stem = name.replace("-", "_")
        write_json(stage / f"{stem}.json", doc)
        rows = [flat_row(r) for r in doc.get("rows", [])]
        if rows and not (stage / f"{stem}.csv").exists():
            header = list(dict.fromkeys(k for r in rows for k in r))
            write_csv(stage / f"{stem}.csv", header, [[_csv_cell(r.get(k)) for k in header] for r in rows])
    return doc
