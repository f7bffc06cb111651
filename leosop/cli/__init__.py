"""Command line: ``leosop SUBCOMMAND ...`` (also ``python -m leosop``).

Rules shared by every subcommand (DESIGN 4.1): ``--json`` prints one JSON
document on stdout and nothing else goes there; progress and logs go to
stderr; ``--out DIR`` receives files; exit status 0 on success, 2 on bad input
(one-line message on stderr), 1 otherwise.

The shared layer here holds for every subcommand: option errors are one line
(no usage block); option values may be negative numbers (``--site
-33.9,18.4,0``); every ``float`` option must be finite; ``--seed`` must be
>= 0; ``--out`` and ``-o`` are checked before any work; warnings become one
line each (numpy's internal ``RuntimeWarning`` only with ``LEOSOP_DEBUG``);
SIGTERM is handled like Ctrl-C, so staged output files are removed, and a stop
request is kept even where the interrupt is swallowed (:mod:`leosop.interrupt`).

Each subcommand lives in its own module of this package with two functions:
``register(subparsers)`` adds its parser (via :func:`add_command`) and
``run(args)`` returns the JSON document as a dict; an optional
``summary(doc)`` renders it for humans.
"""

import argparse
import difflib
import importlib
import json
import os
import re
import sys
import warnings

# The toolkit's matrix products are small and many (per-block decimation,
# 15-state filters): a multi-threaded BLAS only adds contention, 10x slower
# on a busy 2-core machine. Set before numpy loads; a user's setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from ..errors import ExternalError, InputError  # noqa: E402
from ..fileio import check_output_dir, check_output_file, json_ready  # noqa: E402
from ..interrupt import check, requested, stop_on_signals  # noqa: E402
from .options import finite_float  # noqa: E402

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ("visibility", "tle", "position", "simulate", "align", "reproduce", "generate", "doppler", "doctor",
            "replay", "study", "ppp", "export", "fuse", "imu")


class _Parser(argparse.ArgumentParser):
    """Argument parser with the shared rules: one-line errors, negative values, finite floats."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # Anything starting with '-' and a digit, '.digit', inf or nan is a value, not an option.
        self._negative_number_matcher = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)
        self.register("type", float, finite_float)

    def error(self, message):
        """Print one line (no usage block) and exit with status 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):
        """Parse, refusing unknown arguments here, so the error names this (sub)command.

        argparse hands a subcommand's unknown arguments up to the top parser,
        whose error would read ``leosop: error``; each parser refuses its own
        instead, with the nearest option it has when one is close.
        """
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}{self._suggestion(extras)}")
        return namespace, extras

    def _suggestion(self, extras):
        """`` (did you mean --x?)`` for the first unknown option close to one of this parser's options."""
        options = list(self._option_string_actions)  # argparse keeps no public list of a parser's options
        for arg in extras:
            if arg.startswith("-"):
                close = difflib.get_close_matches(arg.split("=", 1)[0], options, n=1)
                if close:
                    return f" (did you mean {close[0]}?)"
        return ""


def add_command(subparsers, name, module, *, help, description=None, out=True):
    """Add a subcommand parser with the common ``--json`` and ``--out`` options.

    ``out=False`` leaves ``--out`` to the actions of a command that has them
    (``tle``, ``study``): each says what, if anything, it writes there.
    """
    parser = subparsers.add_parser(name, help=help, description=description or help)
    parser.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    if out:
        parser.add_argument("--out", metavar="DIR", help="directory for output files (CSV, PNG, JSON)")
    parser.set_defaults(_module=module)
    return parser


def add_action(actions, name, *, help, description=None):
    """Add an action parser (``leosop tle info``) below a command made by :func:`add_command`.

    Its ``--json`` leaves the attribute unset when absent (argparse would
    otherwise overwrite the command's ``--json`` with False), so the flag
    works before or after the action's name.
    """
    parser = actions.add_parser(name, help=help, description=description or help)
    parser.add_argument("--json", action="store_true", default=argparse.SUPPRESS,
                        help="print one JSON document on stdout")
    return parser


def build_parser(command=None):
    """The ``leosop`` argument parser with every subcommand, or with only ``command``'s.

    Each command module imports what its work needs (scipy, pyfftw, dask, ...,
    ~1.2 s together): ``command`` registers only that module, the others
    become bare names (still valid choices, absent from ``--help``), so
    ``leosop visibility ...`` loads what ``visibility`` needs. The parser of
    ``command`` is then the same as in the full parser.
    """
    from .. import __version__

    parser = _Parser(
        prog="leosop", description="Navigation with LEO satellite signals of opportunity."
    )
    parser.add_argument("--version", action="version", version=f"leosop {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if command is None or name == command:
            importlib.import_module(f"{__name__}.{name}").register(subparsers)
        else:
            subparsers.add_parser(name)
    return parser


def _check_common(args):
    """Checks of options several subcommands share, before any work is done."""
    seed = getattr(args, "seed", None)
    if isinstance(seed, int) and seed < 0:
        raise InputError(f"--seed {seed}: must be an integer >= 0")
    if getattr(args, "out", None) is not None:
        check_output_dir(args.out, "--out")
    if isinstance(getattr(args, "output", None), str):
        check_output_file(args.output, "-o")


def _show_warning(command):
    """A ``warnings.showwarning`` printing one line per warning on stderr."""
    debug = bool(os.environ.get("LEOSOP_DEBUG"))

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, UserWarning) and not debug:
            return  # numpy/Python internals (RuntimeWarning, DeprecationWarning): not the user's business
        text = " ".join(str(message).split())
        print(f"leosop {command}: warning: {text}", file=sys.stderr)

    return show


def main(argv=None):
    """Entry point; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    # Only a command in first place is known before parsing; anything else (--help, a typo) needs every command.
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None)
    args = parser.parse_args(argv)
    if args.command is None:
        print(f"leosop: error: give a command: {', '.join(COMMANDS)} (see leosop --help)", file=sys.stderr)
        return 2
    with stop_on_signals(), warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = _show_warning(args.command)
        return _run(args)


def _run(args):
    """Run the subcommand and print its output; every failure becomes an exit status."""
    module = args._module
    try:
        try:
            _check_common(args)
            doc = json_ready(module.run(args))
            check()  # a stop asked for, then swallowed inside the command: still a stop
            if args.json:
                text = json.dumps(doc, allow_nan=False) + "\n"
            else:
                text = module.summary(doc) + "\n" if hasattr(module, "summary") else ""
        except Exception:
            if requested():  # a stop asked for and turned into another error on the way (leosop.interrupt)
                raise KeyboardInterrupt from None
            raise
    except InputError as exc:
        return _fail(args, f"error: {option_message(exc)}", 2)
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError, FileExistsError) as exc:
        return _fail(args, f"error: {exc.filename}: {exc.strerror}", 2)
    except UnicodeDecodeError as exc:
        return _fail(args, f"error: an input file is not UTF-8 text ({exc.reason} at byte {exc.start})", 2)
    except ExternalError as exc:
        return _fail(args, f"error: {option_message(exc)}", 1)
    except OSError as exc:
        if exc.filename is None:
            return _fail(args, f"error: {exc.strerror or exc}", 1)
        return _fail(args, f"error: {exc.filename}: {exc.strerror}", 1)
    except KeyboardInterrupt:
        return _fail(args, "interrupted", 1)
    except Exception as exc:  # the one place where every failure becomes an exit status
        if os.environ.get("LEOSOP_DEBUG"):
            raise
        return _fail(args, f"internal error: {type(exc).__name__}: {exc} (set LEOSOP_DEBUG=1 for a traceback)", 1)
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into `head`: the reader left, not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


#: Library parameters whose option is not ``--`` and the name with ``-`` for ``_`` (as the usage writes it).
PARAM_OPTIONS = {"name_or_path": "--scenario", "out_dir": "--out", "data_dir": "--data DIR",
                 "families": "--constellation", "constellation": "--tle", "fmt": "--format", "spec": "--imu-spec",
                 "base_url": "--url"}


def param_option(param):
    """The command-line option of a library parameter: ``block_s`` -> ``--block-s``."""
    return PARAM_OPTIONS.get(param, "--" + param.replace("_", "-"))


def option_message(exc):
    """The message of an :class:`InputError` or :class:`ExternalError` with its parameters as options.

    The first whole-word occurrence of each name in ``exc.params`` is
    replaced (the message names the parameter first, then may use the word in
    prose: "scheduler ADDR: cannot connect to a Dask scheduler"); a name
    inside a path or file name (``/x/block_s``, ``block_s.json``) is not a word.
    """
    text = str(exc)
    for param in exc.params:
        text = re.sub(rf"(?<![\w./\\-]){re.escape(param)}(?![\w/\\-]|\.\w)", param_option(param), text, count=1)
    return text


def _fail(args, message, status):
    """Print ``leosop COMMAND: message`` as one line on stderr; return ``status``."""
    print(f"leosop {args.command}: {' '.join(str(message).split())}", file=sys.stderr)
    return status


def main_exit():
    """Console-script entry point."""
    try:
        status = main()
    except KeyboardInterrupt:  # while the command's modules load or its options parse: as within a command
        print("leosop: interrupted", file=sys.stderr)
        status = 1
    sys.exit(status)
