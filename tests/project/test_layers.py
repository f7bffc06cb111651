"""The package's layers: dependencies point downward only.

From the bottom: the base modules at the top of ``leosop/`` (constants, frames, errors, fileio, ...), the
library subpackages (orbits, signal, positioning, ins, fusion, gnss, ...), the applications
(:mod:`leosop.apps`) with the figures (:mod:`leosop.plots`), and the command line (:mod:`leosop.cli`). Every
``import`` and ``from ... import`` of every module is resolved to the absolute module it names (relative
ones against the importing module's package) and checked against these rules, so a violation names the
file, its line and what it imported.
"""

import ast
import importlib
import sys
from pathlib import Path

import pytest

import leosop

PACKAGE = Path(leosop.__file__).parent
#: The layers above the library: no library module may import them.
UPPER = ("leosop.apps", "leosop.plots", "leosop.cli", "leosop.__main__")
#: Deprecated aliases of moved application modules (documented import paths of 0.1.0), outside the rules.
ALIASES = {"leosop.scenarios", "leosop.simulate", "leosop.export"}


def _module(path):
    parts = ("leosop", *path.relative_to(PACKAGE).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name):
    path = PACKAGE.parent.joinpath(*name.split("."))
    return path.is_dir() or path.with_suffix(".py").is_file()


def _imports(path):
    """(line, absolute name) of every leosop import in ``path``; ``from X import a``: X.a if a module, else X."""
    module = _module(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]) if node.level else ""
            source = ".".join(part for part in (base, node.module) if part)
            names = [f"{source}.{alias.name}" if _is_module(f"{source}.{alias.name}") else source
                     for alias in node.names]
        else:
            continue
        for name in names:
            if name == "leosop" or name.startswith("leosop."):
                yield node.lineno, name


def _within(name, packages):
    return any(name == p or name.startswith(p + ".") for p in packages)


EDGES = [(_module(path), f"{path.relative_to(PACKAGE.parent)}:{line}", target)
         for path in sorted(PACKAGE.rglob("*.py")) for line, target in _imports(path)]
BASE = {_module(path) for path in PACKAGE.glob("*.py")} - {"leosop", "leosop.__main__"} - ALIASES


def test_the_walk_sees_the_layers():
    # Guards the rules below against passing vacuously (a walk that resolves nothing checks nothing).
    importers = {source for source, _, _ in EDGES}
    assert {"leosop.cli.simulate", "leosop.apps.simulate.run", "leosop.fusion.engine", "leosop.frames"} <= importers
    assert ("leosop.cli.simulate", "leosop.apps.simulate") in {(s, t) for s, _, t in EDGES}


def _library(name):
    return not _within(name, UPPER) and name not in ALIASES


def _subpackage(name):
    """Whether a leosop name lies in a subpackage (not a base module nor the package itself)."""
    parts = name.split(".")
    return len(parts) > 1 and (PACKAGE / parts[1]).is_dir()


RULES = {
    "the library never imports an application, a figure or the CLI":
        lambda source, target: _library(source) and _within(target, UPPER),
    "applications and figures never import the CLI":
        lambda source, target: (not _within(source, ("leosop.cli", "leosop.__main__"))
                                and _within(target, ("leosop.cli",))),
    "only the CLI imports the reproductions":
        lambda source, target: (not _within(source, ("leosop.cli", "leosop.apps.repro"))
                                and _within(target, ("leosop.apps.repro",))),
    "the base modules import only base modules":
        lambda source, target: source in BASE and _subpackage(target),
}


@pytest.mark.parametrize("rule", RULES)
def test_dependencies_point_downward(rule):
    bad = [f"{where} imports {target}" for source, where, target in EDGES if RULES[rule](source, target)]
    assert not bad, f"{rule}:\n" + "\n".join(bad)


@pytest.mark.parametrize("alias", sorted(ALIASES))
def test_alias_warns_and_gives_the_moved_objects(alias):
    home = importlib.import_module(alias.replace("leosop.", "leosop.apps.", 1))
    sys.modules.pop(alias, None)
    with pytest.warns(DeprecationWarning, match=f"{alias} moved to {home.__name__}"):
        module = importlib.import_module(alias)
    assert module.__all__ == home.__all__
    for name in home.__all__:
        assert getattr(module, name) is getattr(home, name), name
