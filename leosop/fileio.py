"""Output files that are either complete or absent.

Every file the toolkit writes goes through :func:`atomic_path`: data are
written to a temporary name in the same directory and renamed into place, so
an error or an interrupt never leaves a half-written output.
"""

import contextlib
import csv
import json
import os
import tempfile
from pathlib import Path

from .errors import InputError

__all__ = ["atomic_path", "atomic_outputs", "write_json", "write_csv"]


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{path.suffix}", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_outputs(out_dir):
    """Yield a staging directory; move every file in it into ``out_dir`` on success.

    A command's set of output files is then all-or-nothing: an error while
    any of them is being made leaves ``out_dir`` as it was.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"--out {out_dir}: exists and is not a directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".stage.", suffix=".part", dir=out_dir))
    try:
        yield stage
        for item in sorted(stage.iterdir()):
            os.replace(item, out_dir / item.name)
    finally:
        for item in stage.iterdir() if stage.exists() else ():
            with contextlib.suppress(OSError):
                item.unlink()
        with contextlib.suppress(OSError):
            stage.rmdir()


def write_json(path, obj):
    """Write ``obj`` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2) + "\n")


def write_csv(path, header, rows):
    """Write a header and rows as CSV, atomically."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        writer.writerows(rows)
