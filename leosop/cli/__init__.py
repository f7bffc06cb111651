"""Command line: ``leosop SUBCOMMAND ...`` (also ``python -m leosop``).

Rules shared by every subcommand (DESIGN 4.1): ``--json`` prints one JSON
document on stdout and nothing else goes there; progress and logs go to
stderr; ``--out DIR`` receives files; exit status 0 on success, 2 on bad input
(one-line message on stderr), 1 otherwise.

Each subcommand lives in its own module of this package with two functions:
``register(subparsers)`` adds its parser (via :func:`add_command`) and
``run(args)`` returns the JSON document as a dict; an optional
``summary(doc)`` renders it for humans.
"""

import argparse
import importlib
import json
import math
import os
import sys

# The toolkit's matrix products are small and many (per-block decimation,
# 15-state filters): a multi-threaded BLAS only adds contention, 10x slower
# on a busy 2-core machine. Set before numpy loads; a user's setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from ..errors import ExternalError, InputError  # noqa: E402

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ("visibility", "tle", "position", "simulate", "align", "reproduce", "generate", "doppler", "replay", "study", "ppp")


def add_command(subparsers, name, module, *, help, description=None):
    """Add a subcommand parser with the common ``--json`` and ``--out`` options."""
    parser = subparsers.add_parser(name, help=help, description=description or help)
    parser.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    parser.add_argument("--out", metavar="DIR", help="directory for output files (CSV, PNG, JSON)")
    parser.set_defaults(_module=module)
    return parser


def build_parser():
    """The ``leosop`` argument parser with every subcommand."""
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="leosop", description="Navigation with LEO satellite signals of opportunity."
    )
    parser.add_argument("--version", action="version", version=f"leosop {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(subparsers)
    return parser


def _clean(obj):
    """JSON-ready copy: NaN/inf become null, numpy scalars become Python numbers."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _clean(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def main(argv=None):
    """Entry point; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help(sys.stderr)
        return 2
    module = args._module
    try:
        doc = _clean(module.run(args))
    except InputError as exc:
        print(f"leosop {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"leosop {args.command}: error: {exc.filename}: {exc.strerror}", file=sys.stderr)
        return 2
    except ExternalError as exc:
        print(f"leosop {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"leosop {args.command}: interrupted", file=sys.stderr)
        return 1
    except Exception as exc:  # the one place where every failure becomes an exit status
        if os.environ.get("LEOSOP_DEBUG"):
            raise
        print(f"leosop {args.command}: internal error: {type(exc).__name__}: {exc} "
              "(set LEOSOP_DEBUG=1 for a traceback)", file=sys.stderr)
        return 1
    try:
        if args.json:
            json.dump(doc, sys.stdout)
            sys.stdout.write("\n")
        elif hasattr(module, "summary"):
            print(module.summary(doc))
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into `head`: the reader left, not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


def main_exit():
    """Console-script entry point."""
    sys.exit(main())
