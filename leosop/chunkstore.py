"""Finished pieces of a long study on disk, so that an interrupted study resumes where it stopped.

A work directory holds one ``NAME.npz`` per finished chunk, each written
under a temporary name and renamed (:func:`leosop.fileio.atomic_path`): a
file that exists is complete. The caller names the directory after
everything the results depend on (a digest of the study), so chunks of
another study are never mixed in, and removes it once its final output is
written. ``leosop study montecarlo`` and ``leosop study gdop-map`` use it.
"""

import shutil
import zipfile
from pathlib import Path

import numpy as np

from .fileio import atomic_path

__all__ = ["ChunkStore"]


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
