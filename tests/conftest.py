"""Shared test fixtures: where the real public data sets live.

Real data are read from ``../shared/data`` beside the repository (see each
folder's PROVENANCE.md there) and never copied into the repository. Tests
that need a folder skip cleanly when it is absent.
"""

import os
from pathlib import Path

# As the CLI does (leosop/cli/__init__.py): the filters' many small matrix products are several times slower
# under a multi-threaded BLAS on a busy machine. It acts only if numpy is not imported yet (pytest does not).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest  # noqa: E402

DATA_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def data_path(*parts):
    """Path of a file or folder under ``../shared/data``; skip the test if absent."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path}")
    return path


#: The IGS station ESBC00DNK on 2020-06-25 (``rinex/esbc_2020-177``, see its PROVENANCE.md): observations,
#: navigation, GRG orbits and integer clocks, the ANTEX subset, and the signals the PPP uses per system.
ESBC_DAY = DATA_DIR / "rinex" / "esbc_2020-177"
ESBC_OBS = ESBC_DAY / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"
ESBC_NAV = ESBC_DAY / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
ESBC_SP3 = ESBC_DAY / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz"
ESBC_CLK = ESBC_DAY / "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz"
ESBC_ATX = ESBC_DAY / "esbc_2020-177.atx"
ESBC_CODES = {"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]}
