"""Output files that are either complete or absent.

Every file the toolkit writes goes through :func:`atomic_path`: data are
written to a temporary name in the same directory and renamed into place, so
an error or an interrupt never leaves a half-written output. A command's set
of outputs is all-or-nothing through :func:`atomic_files` (named files, moved
in order) or :func:`atomic_outputs` (a staged ``--out`` directory). Errors
name the user's path, never the temporary one, and directories made for an
output that is not made are removed again. :func:`check_output_file` and
:func:`check_output_dir` refuse impossible destinations before any work.
"""

import contextlib
import csv
import errno
import json
import math
import os
import tempfile
from pathlib import Path

from .errors import InputError
from .interrupt import check

__all__ = ["atomic_path", "atomic_files", "atomic_outputs", "check_input_file", "check_output_file", "check_output_dir",
           "write_json", "write_csv"]


def _missing_dirs(directory):
    """``directory`` and its ancestors that do not exist yet, deepest first."""
    missing, d = [], Path(directory)
    while not d.exists() and not d.is_symlink() and d != d.parent:
        missing.append(d)
        d = d.parent
    return missing


def _remove_dirs(dirs):
    """Remove directories we created (deepest first) if they are still empty."""
    for d in dirs:
        with contextlib.suppress(OSError):
            d.rmdir()


def _renamed(exc, tmp, path):
    """``exc`` naming the user's ``path`` where it named the temporary ``tmp``.

    Before ``tmp`` exists (``tmp`` None), a candidate temporary name of
    ``path`` is replaced too.
    """
    if not isinstance(exc, OSError) or exc.errno is None or exc.filename is None:
        return exc
    name = str(exc.filename)
    if tmp is not None and (name == str(tmp) or name.startswith(f"{tmp}{os.sep}")):
        return OSError(exc.errno, exc.strerror, str(path) + name[len(str(tmp)):])
    if tmp is None and Path(name).name.startswith(f".{Path(path).name}."):
        return OSError(exc.errno, exc.strerror, str(path))
    return exc


def check_input_file(path, what):
    """Refuse an input path that is not a readable regular file, saying which of those it is.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file should be, for the message (``"measurement file"``).

    Raises
    ------
    InputError
        ``path`` does not exist, is a directory, is not a regular file (a
        device such as ``/dev/null``, a pipe, a socket) or cannot be read.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such {what}")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a {what}")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file (a device, pipe or socket), expected a {what}")
    if not os.access(path, os.R_OK):
        raise InputError(f"{path}: no permission to read the {what}")


def check_output_file(path, option):
    """Refuse an output file path that cannot be written atomically (InputError naming ``option``).

    Empty paths, existing directories and devices (``/dev/null``) and paths
    below a file are refused before any work is done.
    """
    text = str(path)
    if not text.strip():
        raise InputError(f"{option} {text!r}: empty path, expected a file name", param=_param(option))
    path = Path(text)
    if path.exists() and not path.is_file():
        raise InputError(f"{option} {path}: exists and is not a regular file", param=_param(option))
    _check_parent(path, path.parent, option)


def check_output_dir(path, option="out_dir"):
    """Refuse an output directory path that is empty, a file, a device or below a file."""
    text = str(path)
    if not text.strip():
        raise InputError(f"{option} {text!r}: empty path, expected a directory", param=_param(option))
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise InputError(f"{option} {path}: exists and is not a directory", param=_param(option))
    _check_parent(path, path, option)


def _param(option):
    """``option`` as the parameter an InputError names: a library name (``out_dir``), not a CLI option (``-o``)."""
    return option if option.isidentifier() else ()


def _check_parent(path, directory, option):
    for d in (directory, *directory.parents):
        if d.exists():
            if not d.is_dir():
                raise InputError(f"{option} {path}: {d} is not a directory", param=_param(option))
            if not os.access(d, os.W_OK | os.X_OK):
                raise InputError(f"{option} {path}: no permission to write in {d}", param=_param(option))
            return


@contextlib.contextmanager
def _staged(path):
    """Yield a temporary file next to ``path``; on failure remove it and any directory made for it."""
    if path.exists() and not path.is_file():
        raise InputError(f"{path}: exists and is not a regular file")
    created = _missing_dirs(path.parent)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{path.suffix}", dir=path.parent)
        os.close(fd)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        yield Path(tmp)
    except BaseException as exc:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        _remove_dirs(created)
        renamed = _renamed(exc, tmp, path)
        if renamed is not exc:
            raise renamed from None
        raise


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    Errors name ``path``, not the temporary file; a directory created for
    ``path`` is removed again when the output is not made.
    """
    path = Path(path)
    with _staged(path) as tmp:
        yield tmp
        check()
        os.replace(tmp, path)


@contextlib.contextmanager
def atomic_files(paths):
    """Yield temporary paths for several output files; all are moved into place on success, or none.

    They are moved in the order given (a data file before the metadata that
    describes it); should a move fail, the files already moved are removed.
    """
    paths = [Path(p) for p in paths]
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(_staged(p)) for p in paths]
        yield tmps
        check()
        moved = []
        try:
            for tmp, path in zip(tmps, paths):
                os.replace(tmp, path)
                moved.append(path)
        except BaseException:
            for path in moved:
                with contextlib.suppress(OSError):
                    path.unlink()
            raise


@contextlib.contextmanager
def atomic_outputs(out_dir):
    """Yield a staging directory; move every file in it into ``out_dir`` on success.

    A command's set of output files is then all-or-nothing: an error while
    any of them is being made leaves ``out_dir`` as it was (not even created).
    Errors name the file in ``out_dir``, not its staged copy.
    """
    check_output_dir(out_dir)
    out_dir = Path(out_dir)
    created = _missing_dirs(out_dir)
    stage = None
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=".stage.", suffix=".part", dir=out_dir))
        yield stage
        check()
        _commit(stage, out_dir)
    except BaseException as exc:
        _clear(stage)
        _remove_dirs(created)
        renamed = _renamed(exc, stage, out_dir) if stage is not None else exc
        if renamed is not exc:
            raise renamed from None
        raise
    _clear(stage)


def _commit(stage, out_dir):
    """Move every file of ``stage`` into ``out_dir``: all, or none and ``out_dir`` as it was.

    A directory in the way of one file fails before anything moves; the
    files being replaced are kept aside until every move is done and put
    back should one fail.
    """
    items = sorted(stage.iterdir())
    for item in items:
        target = out_dir / item.name
        if target.is_dir() and not target.is_symlink():
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(target))
    aside = Path(tempfile.mkdtemp(prefix=".old.", suffix=".part", dir=out_dir))
    kept, moved = [], []
    try:
        for item in items:
            target = out_dir / item.name
            if target.exists() or target.is_symlink():
                os.replace(target, aside / item.name)
                kept.append(item.name)
            os.replace(item, target)
            moved.append(item.name)
    except BaseException:
        for name in moved:
            with contextlib.suppress(OSError):
                (out_dir / name).unlink()
        for name in kept:
            with contextlib.suppress(OSError):
                os.replace(aside / name, out_dir / name)
        raise
    finally:
        _clear(aside)


def _clear(stage):
    """Remove a staging directory and the files left in it."""
    if stage is None or not stage.exists():
        return
    for item in stage.iterdir():
        with contextlib.suppress(OSError):
            item.unlink()
    with contextlib.suppress(OSError):
        stage.rmdir()


#: Exact types `json_ready` passes through unchanged (a subclass such as ``numpy.float64`` is not one).
_PLAIN = frozenset({str, int, bool, type(None)})


def json_ready(obj):
    """JSON-ready copy: NaN/inf become null, numpy arrays and scalars become Python values.

    Strict JSON (RFC 8259) has no NaN or Infinity; ``json.dumps`` writes them
    as bare tokens that other parsers refuse, so every JSON the toolkit
    writes goes through here and then ``json.dumps(..., allow_nan=False)``.
    """
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        # Fast paths for flat lists (visibility's 2.3 M satellite ids): one pass over the types in C.
        kinds = set(map(type, obj))
        if kinds <= _PLAIN:
            return list(obj)
        if kinds == {float}:
            return [v if math.isfinite(v) else None for v in obj]
        return [json_ready(v) for v in obj]
    if hasattr(obj, "tolist"):
        return json_ready(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def json_text(obj, *, compact=False):
    """Strict JSON text of ``obj`` (see `json_ready`); indented by 2 unless ``compact``."""
    obj = json_ready(obj)
    if compact:
        return json.dumps(obj, separators=(",", ":"), allow_nan=False)
    return json.dumps(obj, indent=2, allow_nan=False)


def write_json(path, obj, *, compact=False):
    """Write ``obj`` as strict JSON (NaN and inf as null), atomically.

    Parameters
    ----------
    path : str or Path
    obj : JSON-serialisable object
    compact : bool
        One line without spaces, for large documents (per-epoch lists such as
        ``visibility.json``: indenting puts every number on its own line and
        makes the file several times larger); else indented by 2 for reading.
    """
    text = json_text(obj, compact=compact)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n")


def write_csv(path, header, rows):
    """Write a header and rows as CSV, atomically."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        writer.writerows(rows)
