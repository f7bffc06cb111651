"""Finished chunks on disk, so that an interrupted study resumes where it stopped.

A work directory holds one ``chunk-NNNNNN.npz`` per finished chunk (its run
indices and metric rows), each written under a temporary name and renamed
(:func:`leosop.fileio.atomic_path`): a file that exists is complete. The
directory's name carries the study's digest
(:meth:`leosop.montecarlo.spec.StudySpec.digest`), so chunks of another spec,
element-set file or leosop version are never mixed in.
"""

import shutil
import zipfile
from pathlib import Path

import numpy as np

from ..fileio import atomic_path

__all__ = ["ChunkStore"]


class ChunkStore:
    """The chunk files of one study.

    Parameters
    ----------
    folder : path-like
        The study's work directory (created on the first write).
    n_metrics : int
        Columns of every chunk's rows; a file with other columns is not reused.
    """

    def __init__(self, folder, n_metrics):
        self.folder = Path(folder)
        self.n_metrics = n_metrics

    def path(self, index):
        return self.folder / f"chunk-{index:06d}.npz"

    def save(self, index, run_index, rows):
        """Write chunk ``index``: ``run_index`` (n,) and ``rows`` (n, n_metrics)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        with atomic_path(self.path(index)) as tmp:
            np.savez(tmp, run_index=np.asarray(run_index, dtype=np.int64), rows=np.asarray(rows, dtype=float))

    def load(self, index, run_index):
        """Rows of chunk ``index`` if its file exists and holds exactly ``run_index``; else None."""
        path = self.path(index)
        if not path.is_file():
            return None
        try:
            with np.load(path) as data:
                stored, rows = data["run_index"], data["rows"]
        except (OSError, ValueError, KeyError, zipfile.BadZipFile):  # unreadable: run the chunk again
            return None
        if not np.array_equal(stored, run_index) or rows.shape != (len(run_index), self.n_metrics):
            return None
        return rows

    def remove(self):
        """Delete the work directory (after the final output is written)."""
        shutil.rmtree(self.folder, ignore_errors=True)
