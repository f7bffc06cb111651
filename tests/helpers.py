"""Helpers shared by tests of several packages: data paths, central differences, a LEO test geometry, consistency,
one-line input errors.

Real data are read from ``../shared/data`` beside the repository (see each
folder's PROVENANCE.md there) and never copied into the repository. Tests
that need a folder skip cleanly when it is absent. Import as
``from tests.helpers import data_path`` (tests/conftest.py says why).
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from leosop import frames
from leosop.errors import InputError

#: The repository (tests/ sits at its top).
REPO_ROOT = Path(__file__).resolve().parents[1]
#: The real public data sets, beside the repository (never copied into it).
DATA_DIR = REPO_ROOT.parent / "shared" / "data"


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


def peak_rss_mb(*args):
    """Peak resident memory [MB] of one ``leosop`` run in a child process of its own (os.wait4's rusage; Linux)."""
    proc = subprocess.Popen([sys.executable, "-m", "leosop", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    stderr = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, stderr.decode()
    return usage.ru_maxrss / 1024  # kB on Linux


def one_line_error(call, *match):
    """Call ``call()``, which must raise InputError with a one-line message holding every ``match``; the message."""
    with pytest.raises(InputError) as info:
        call()
    text = str(info.value)
    assert "\n" not in text
    for part in match:
        assert part in text
    return text


def central_difference_jacobian(func, step):
    """Jacobian of ``func`` at zero by central differences, exact to O(step^2).

    Parameters
    ----------
    func : callable
        Maps an offset, ndarray (n,), to ndarray (m,).
    step : array_like, (n,)
        Step of each coordinate.

    Returns
    -------
    ndarray, (m, n)
        Column ``i`` is ``(func(step[i] e_i) - func(-step[i] e_i)) / (2 step[i])``.
    """
    step = np.asarray(step, dtype=float)
    columns = []
    for i, h in enumerate(step):  # one coordinate at a time: func takes a single offset
        e = np.zeros(step.size)
        e[i] = h
        columns.append((np.asarray(func(e)) - np.asarray(func(-e))) / (2 * h))
    return np.stack(columns, axis=-1)


def leo_geometry(state):
    """A LEO satellite as seen from an INS state: 550 km up and 700 km east (~900 km away), moving north.

    Parameters
    ----------
    state : leosop.ins.strapdown.NavState
        Gives the receiver's ``lat_rad``, ``lon_rad``, ``alt_m``.

    Returns
    -------
    pos_rx_ecef_m, pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (3,)
        The satellite moves at 7.6 km/s north and climbs at 100 m/s.
    east, north : ndarray, (3,)
        Unit vectors of the receiver's local level in ECEF.
    """
    pos_rx = frames.geodetic_to_ecef(state.lat_rad, state.lon_rad, state.alt_m)
    up = pos_rx / np.linalg.norm(pos_rx)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    return pos_rx, pos_rx + 550e3 * up + 700e3 * east, 7.6e3 * north + 100.0 * up, east, north


def assert_filter_consistent(nees_pos_vel, nis_sum, nis_dof, lag_a, lag_b):
    """NEES, NIS and whiteness of a filter over seeded runs.

    Parameters
    ----------
    nees_pos_vel : array_like
        NEES of position and velocity (6 dof) at every epoch of every run.
    nis_sum, nis_dof : float, int
        Sum of all normalised innovation squares and their total dof.
    lag_a, lag_b : array_like
        Whitened innovations and their successors one epoch later.

    Mean NEES within [0.5, 2] of its dimension (issue 6); the NIS sum inside
    the 99.9 % two-sided chi-square interval; the lag-1 correlation, ~N(0, 1/n)
    for n white pairs under the null, below 4/sqrt(n).
    """
    nees = np.asarray(nees_pos_vel, dtype=float)
    assert 0.5 * 6 <= nees.mean() <= 2.0 * 6, nees.mean() / 6
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], nis_dof)
    assert lo <= nis_sum <= hi, (nis_sum / nis_dof, lo / nis_dof, hi / nis_dof)
    a, b = np.ravel(lag_a), np.ravel(lag_b)
    assert abs(np.corrcoef(a, b)[0, 1]) < 4.0 / np.sqrt(a.size)
