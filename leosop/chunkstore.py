"""Finished pieces of a long study on disk, so that an interrupted study resumes where it stopped.

A work directory holds one ``NAME.npz`` per finished chunk, each written
under a temporary name and renamed (:func:`leosop.fileio.atomic_path`): a
file that exists is complete. The caller names the directory after
everything the results depend on (a digest of the study and
:func:`code_digest`, the code that computes it), so chunks of another study or
of older code are never mixed in, and removes it once its final output is
written. ``leosop study montecarlo`` and ``leosop study gdop-map`` use it.
"""

import functools
import hashlib
import shutil
import zipfile
from pathlib import Path

import numpy as np

from . import __version__
from .fileio import atomic_path

__all__ = ["ChunkStore", "code_digest"]

PACKAGE_DIR = Path(__file__).resolve().parent


@functools.cache
def code_digest(package_dir=PACKAGE_DIR):
    """SHA-256 (hex) of leosop's version and every ``.py`` file under ``package_dir``: relative path and bytes.

    A study's chunks are only reused by the code that wrote them. The whole
    package counts, not a list of the modules a study calls today (a
    simulation reaches most of it, and a list would go stale), so any source
    change starts a study afresh. About 1 MB of source: milliseconds, once
    per process.
    """
    root = Path(package_dir)
    h = hashlib.sha256(__version__.encode())
    for path in sorted(root.rglob("*.py"), key=lambda p: p.relative_to(root).as_posix()):
        rel = path.relative_to(root).as_posix().encode()
        data = path.read_bytes()
        h.update(len(rel).to_bytes(8, "little") + rel + len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


class ChunkStore:
    """The chunk files of one study.

    Parameters
    ----------
    folder : path-like
        The study's work directory (created on the first write).
    """

    def __init__(self, folder):
        self.folder = Path(folder)

    def save(self, name, **arrays):
        """Write chunk ``name`` holding ``arrays`` (name -> ndarray)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        with atomic_path(self.folder / f"{name}.npz") as tmp:
            np.savez(tmp, **arrays)

    def load(self, name):
        """The arrays of chunk ``name``, or None when it is absent or unreadable (then run it again)."""
        path = self.folder / f"{name}.npz"
        if not path.is_file():
            return None
        try:
            with np.load(path) as data:
                return {k: data[k] for k in data.files}
        except (OSError, ValueError, zipfile.BadZipFile):
            return None

    def names(self):
        """Names of the chunks on disk, sorted."""
        return sorted(p.stem for p in self.folder.glob("*.npz")) if self.folder.is_dir() else []

    def remove(self):
        """Delete the work directory (after the final output is written)."""
        shutil.rmtree(self.folder, ignore_errors=True)
