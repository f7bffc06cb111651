"""``leosop simulate``: [Shen 2024]'s Starlink/INS flight end to end (the main job)."""

import sys
import warnings

from ..apps.scenarios import load_scenario, scenario_tle
from ..apps.simulate import COUPLINGS, LEVELS, fusion_label, metrics, run_scenario, solution_table
from ..datadir import ENV_VAR
from ..fileio import atomic_outputs, write_csv, write_json
from . import add_command


def register(subparsers):
    p = add_command(subparsers, "simulate", sys.modules[__name__],
                    help="simulate a LEO/INS flight end to end (default: [Shen 2024]'s Xi'an-Baoji flight, Starlink; "
                         "scenario leo.constellations mixes OneWeb, Iridium NEXT and Orbcomm in)")
    p.add_argument("--scenario", default="xian-baoji", metavar="NAME|FILE.json",
                   help="built-in scenario name (xian-baoji, or a bundled file: xian-baoji-multi, high-latitude, "
                        "urban-canyon, outage) or a scenario JSON file (default xian-baoji)")
    p.add_argument("--tle", metavar="FILE",
                   help="TLE or OMM file (default: the scenario's, else the bundled sky)")
    p.add_argument("--data", metavar="DIR",
                   help=f"data folder of the real data sets a scenario names as ${ENV_VAR}/... (high-latitude: "
                        f"tle/active_3le_2021-08-06_atqlong.txt; default: ${ENV_VAR})")
    p.add_argument("--correction-period-s", type=float, default=1.0, metavar="P",
                   help="seconds between EKF corrections of the INS (default 1)")
    p.add_argument("--orbit-error-m", type=float, metavar="E",
                   help="satellite orbit error per axis [m] (default: the scenario's, 1 m)")
    p.add_argument("--level", choices=LEVELS, default="signal",
                   help="signal: pilot blocks through the fast estimator (default); measurement: its error model")
    p.add_argument("--coupling", choices=COUPLINGS, default="loose", help="fusion (default loose)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")


def run(args):
    scenario = load_scenario(args.scenario)
    tle = args.tle if args.tle is not None else scenario_tle(scenario, args.data)
    from ..progress import progress

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run_scenario(scenario, level=args.level, correction_period_s=args.correction_period_s,
                              orbit_error_m=args.orbit_error_m, seed=args.seed, tle=tle,
                              coupling=args.coupling, progress=progress)
    for w in caught:
        print(f"leosop simulate: warning: {w.message}", file=sys.stderr)
    doc = metrics(result)
    # Beyond the contract's keys: what was run, so a metrics.json names its coupling, level and seed.
    doc["run"] = {"coupling": args.coupling, "level": args.level, "seed": args.seed,
                  "correction_period_s": args.correction_period_s,
                  "constellations": list(scenario.leo.constellations)}
    if args.out:
        from ..plots import write_figures

        with atomic_outputs(args.out) as stage:  # all files or none
            header, rows = solution_table(result)
            write_csv(stage / "solution.csv", header, rows)
            write_json(stage / "metrics.json", doc)
            write_figures(result, stage)
    return doc


def _num(value, fmt):
    return "n/a" if value is None else format(value, fmt)


def _aid(fused, leo_fix):
    """How much of the fused solution rests on LEO, in words."""
    if fused["n_updates"] == 0:
        fixes = "no LEO fix" if leo_fix["n_fixes"] == 0 else "no fix taken"
        return f"{fixes}, no update: the INS alone"
    return f"aided {fused['aided_fraction']:.3f}, {fused['n_updates']} updates"


def summary(doc):
    f, i, x, run = doc["fused"], doc["ins_only"], doc["leo_fix"], doc["run"]
    fixes = (f"position {_num(x['pos_err_mean_m'], '10.2f')} m   velocity {_num(x['vel_err_mean_mps'], '.3f')} m/s "
             f"({x['n_fixes']} fixes)" if x["n_fixes"] else "none")
    return "\n".join([
        f"scenario {doc['scenario']} ({run['coupling']} coupling, {run['level']} level, seed {run['seed']}, "
        f"correction every {run['correction_period_s']:g} s): {doc['duration_s']:g} s, "
        f"{doc['visible']['min']}-{doc['visible']['max']} satellites visible, max Doppler GDOP "
        f"{_num(doc['gdop']['max'], '.1f')} m/Hz",
        f"  INS only      position {_num(i['pos_err_mean_m'], '10.2f')} m   velocity "
        f"{_num(i['vel_err_mean_mps'], '.3f')} m/s (mean 3D error)",
        f"  LEO fixes     {fixes}",
        f"  {fusion_label(run['constellations']):<12}  position {_num(f['pos_err_mean_m'], '10.2f')} m   velocity "
        f"{_num(f['vel_err_mean_mps'], '.3f')} m/s (RMS {_num(f['pos_err_rms_m'], '.2f')} m, "
        f"availability {f['availability']:.3f}; {_aid(f, x)})",
        f"  runtime {doc['runtime_s']:.1f} s",
    ])
