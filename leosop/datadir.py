"""The folder of real public data sets that the toolkit reads but does not ship.

Some bundled inputs need files that may not be copied into the package (the
real element-set snapshot of the ``high-latitude`` scenario carries no
licence to redistribute). They name such a file as ``$LEOSOP_DATA/<path>``,
``<path>`` relative to the data folder, which is laid out as the project's
shared data tree (``tle/``, ``rinex/``, ... each with its PROVENANCE.md). The
folder comes from an option (``--data DIR``) or, without one, from the
environment variable ``LEOSOP_DATA``; nothing is looked for beside the
package or the current directory, so an installed toolkit behaves as a
checkout does.
"""

import os
from pathlib import Path

from .errors import InputError

__all__ = ["ENV_VAR", "PREFIX", "is_data_ref", "data_folder", "resolve_data_ref"]

#: Environment variable naming the data folder.
ENV_VAR = "LEOSOP_DATA"
#: How a file inside the data folder is named in bundled inputs.
PREFIX = f"${ENV_VAR}/"


def is_data_ref(name):
    """Whether ``name`` (str or None) is a ``$LEOSOP_DATA/...`` reference."""
    return isinstance(name, str) and name.startswith(PREFIX)


def data_folder(data_dir=None):
    """The data folder: ``data_dir`` if given, else ``$LEOSOP_DATA``, else None."""
    if data_dir is not None:
        return Path(data_dir)
    env = os.environ.get(ENV_VAR)
    return Path(env) if env else None


def resolve_data_ref(name, *, data_dir=None, needed_by):
    """The path a ``$LEOSOP_DATA/...`` reference stands for.

    Parameters
    ----------
    name : str
        A reference (:func:`is_data_ref`).
    data_dir : path-like, optional
        The folder given by an option; default ``$LEOSOP_DATA``.
    needed_by : str
        What needs the file, for the message (e.g. ``"scenario high-latitude"``).

    Returns
    -------
    pathlib.Path
        An existing file.

    Raises
    ------
    InputError
        One line naming the file and how to give the folder, when no folder
        is given or the file is not in it.
    """
    relative = name[len(PREFIX):]
    folder = data_folder(data_dir)
    if folder is None:
        raise InputError(f"{needed_by} needs {name}: give the data folder with data_dir or set {ENV_VAR} "
                         f"(the folder holding {relative})", param="data_dir")
    path = folder / relative
    if not path.is_file():
        source = "data_dir" if data_dir is not None else ENV_VAR
        raise InputError(f"{path}: not found ({needed_by} needs {name}; data folder {folder} from {source})",
                         param="data_dir")
    return path
