"""The ``leosop`` package of a git revision of this repository, exported for a side-by-side benchmark.

Benchmarks compare this tree with a baseline in the same run (ratios, not
absolute times): ``export_package(ref, dest)`` writes ``dest/leosop`` as it is
at ``ref``, so that a child process with ``cwd=dest`` imports the baseline.
"""

import subprocess
import tarfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def export_package(ref, dest):
    """Write the ``leosop`` folder of revision ``ref`` (e.g. ``main``) under the existing folder ``dest``."""
    dest = Path(dest)
    archive = subprocess.run(["git", "-C", str(REPO), "archive", ref, "leosop"], check=True,
                             capture_output=True).stdout
    tar_path = dest / "baseline.tar"
    tar_path.write_bytes(archive)
    with tarfile.open(tar_path) as tar:
        tar.extractall(dest, filter="data")
    tar_path.unlink()
