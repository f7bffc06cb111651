"""Lazy re-exports for the subpackages' facades: a public name is imported from its home module on first use.

A facade (``leosop.signal``, ``leosop.positioning``) names what a user calls
in one place. Importing any module of a package runs the package's
``__init__`` first, so eager re-exports there would load the heavy
dependencies of the whole package (pyfftw, which imports dask; scipy.stats)
even for a light module such as ``leosop.signal.iq``. A facade therefore
writes its re-exports as ordinary imports under ``if TYPE_CHECKING:`` (what
type checkers and readers see) beside a literal ``__all__``, and
:func:`lazy_exports` reads those imports and gives the package a module
``__getattr__`` (PEP 562) that performs each one on first access: the
pattern of the Scientific Python lazy-loading proposal (SPEC 1, 2022).
"""

import ast
import importlib
import sys
from collections.abc import Callable
from pathlib import Path

__all__ = ["lazy_exports", "type_checking_imports"]


def type_checking_imports(init_path: str | Path) -> dict[str, tuple[str, str]]:
    """The names a module imports under a top-level ``if TYPE_CHECKING:``, and where from.

    Parameters
    ----------
    init_path : str or Path
        The module's source file (a package's ``__init__.py``).

    Returns
    -------
    dict
        Bound name -> (module as written, relative ones with their leading
        dots, e.g. ``".iq"`` or ``"..geometry.dop"``; the name in that module).
    """
    tree = ast.parse(Path(init_path).read_text(encoding="utf-8"))
    blocks = [node.body for node in tree.body
              if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"]
    return {alias.asname or alias.name: ("." * node.level + (node.module or ""), alias.name)
            for body in blocks for node in body if isinstance(node, ast.ImportFrom) for alias in node.names}


def lazy_exports(package: str, init_path: str | Path) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """Module ``__getattr__`` and ``__dir__`` for a package whose re-exports are imported on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    init_path : str or Path
        Its ``__file__``; the names are those :func:`type_checking_imports` finds there.

    Returns
    -------
    getattr_, dir_ : callable
        To be bound as the package's ``__getattr__`` and ``__dir__``. The
        first access of a name imports it and stores it on the package, so
        later look-ups are plain attribute reads.
    """
    homes = type_checking_imports(init_path)

    def getattr_(name: str) -> object:
        if name not in homes:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module, attr = homes[name]
        value = getattr(importlib.import_module(module, package), attr)
        setattr(sys.modules[package], name, value)
        return value

    def dir_() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(homes))

    return getattr_, dir_
