"""Shared test fixtures: where the real public data sets live.

Real data are read from ``../shared/data`` beside the repository (see each
folder's PROVENANCE.md there) and never copied into the repository. Tests
that need a folder skip cleanly when it is absent.
"""

from pathlib import Path

import pytest

DATA_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def data_path(*parts):
    """Path of a file or folder under ``../shared/data``; skip the test if absent."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path}")
    return path
