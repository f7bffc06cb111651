"""Library errors name the library's parameters; the CLI prints them as its options (issue 25).

A user of the Python API never typed ``--block-s``: the library says
``block_s 0.001: ...`` and lists ``block_s`` in the error's ``params``; the
CLI's error handler turns it into the option the user typed.
"""

import ast
import re
from pathlib import Path

import pytest

import leosop
from leosop.cli import build_parser, main, option_message, param_option
from leosop.errors import ExternalError, InputError
from leosop.orbits.grid import check_grid_deg

LIBRARY = Path(leosop.__file__).parent
ERRORS = {"InputError", "ExternalError", "ValueError"}


def _library_trees():
    """(path, ast) of every module of the library outside leosop/cli/."""
    for path in sorted(LIBRARY.rglob("*.py")):
        if "cli" not in path.relative_to(LIBRARY).parts:
            yield path, ast.parse(path.read_text(encoding="utf-8"))


def _error_calls(tree):
    """The calls of an error type in ``tree``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = getattr(node.func, "id", getattr(node.func, "attr", None))
            if name in ERRORS:
                yield node


def _literal_text(node):
    """The literal text of an expression: its string constants, joined ('' when it holds none).

    Covers "..." + "...", f-strings and the arguments of calls in the
    message (``", ".join(...)``); format specs such as ``.3g`` come along and
    hold no option.
    """
    return " ".join(n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str))


OPTION = re.compile(r"--[a-z]")


def test_no_library_error_message_names_an_option():
    found = []
    for path, tree in _library_trees():
        for call in _error_calls(tree):
            if call.args and OPTION.search(_literal_text(call.args[0])):
                found.append(f"{path.relative_to(LIBRARY)}:{call.lineno}")
        for node in ast.walk(tree):  # defaults such as option="--grid-deg" end up in messages too
            if isinstance(node, ast.arguments):
                for default in [*node.defaults, *node.kw_defaults]:
                    if default is not None and OPTION.search(_literal_text(default)):
                        found.append(f"{path.relative_to(LIBRARY)}:{default.lineno} (default)")
    assert found == []


def _cli_options():
    """Every option string of every (sub)command parser."""
    options, parsers = set(), [build_parser()]
    while parsers:
        parser = parsers.pop()
        for action in parser._actions:  # argparse keeps no public list of a parser's actions
            options.update(action.option_strings)
            if isinstance(action.choices, dict):
                parsers.extend(action.choices.values())
    return options


def test_every_named_parameter_is_an_option_of_the_cli():
    params = set()
    for _, tree in _library_trees():
        for call in _error_calls(tree):
            for kw in call.keywords:
                if kw.arg == "param":
                    values = kw.value.elts if isinstance(kw.value, ast.Tuple) else [kw.value]
                    params.update(v.value for v in values if isinstance(v, ast.Constant))
    assert {"block_s", "dtype", "level", "grid_deg", "families", "spec"} <= params  # the walk sees them
    options = _cli_options()
    assert sorted(p for p in params if param_option(p).split()[0] not in options) == []


def test_the_python_message_names_the_parameter_and_the_cli_the_option(tmp_path, capsys):
    with pytest.raises(InputError) as err:
        check_grid_deg(7.0)
    assert err.value.params == ("grid_deg",)
    python = str(err.value)
    assert python.startswith("grid_deg 7: must divide 180")
    assert main(["study", "gdop-map", "--grid-deg", "7", "--out", str(tmp_path / "maps")]) == 2
    assert capsys.readouterr().err == f"leosop study: error: --grid-deg{python[len('grid_deg'):]}\n"


@pytest.mark.parametrize("error, message", [
    (InputError("x.raw: a raw file needs dtype and sample_rate_hz", param=("dtype", "sample_rate_hz")),
     "x.raw: a raw file needs --dtype and --sample-rate-hz"),
    # the first whole word only: paths and file names holding the name stay, prose after it too
    (InputError("spec /tmp/spec/a.json: not readable", param="spec"), "--imu-spec /tmp/spec/a.json: not readable"),
    (InputError("spec spec.json: not readable", param="spec"), "--imu-spec spec.json: not readable"),
    (ExternalError("scheduler tcp://h:9: cannot connect to a Dask scheduler", param="scheduler"),
     "--scheduler tcp://h:9: cannot connect to a Dask scheduler"),
    (InputError("d: not found (data folder d from data_dir)", param="data_dir"),
     "d: not found (data folder d from --data DIR)"),
    # element sets reach the library as a Constellation, the CLI as --tle; a column of the same name stays
    (InputError("m.csv: satellite states from constellation need a time_utc column", param="constellation"),
     "m.csv: satellite states from --tle need a time_utc column"),
    (InputError("m.csv:3: give sigma_hz or a sigma_hz column: ...", param="sigma_hz"),
     "m.csv:3: give --sigma-hz or a sigma_hz column: ..."),
    (InputError("block_s 0.001: too short"), "block_s 0.001: too short"),  # no param: unchanged
])
def test_option_message(error, message):
    assert option_message(error) == message
