"""The typed public API: mypy finds no error in its modules, and its entry points are fully annotated.

mypy checks only the bodies of annotated functions, so a clean run alone would also pass on code with no
annotations at all; the second test holds the chosen entry points to complete signatures. The modules are
listed here and, for a plain ``mypy`` run, as ``files`` in pyproject.toml's ``[tool.mypy]`` (checked equal).
The subpackages' facades (``leosop.positioning``, ``leosop.signal``) are part of it: their ``__all__`` is what
they import for type checkers, every name resolves to the object of its home module, and importing them loads
none of the heavy dependencies their names need.
"""

import importlib
import importlib.util
import inspect
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from leosop.lazy import type_checking_imports

from tests.helpers import REPO_ROOT


#: Entry points of the typed public API, by module; their modules are what mypy checks.
PUBLIC = {
    "leosop.orbits": ["load_constellation"],
    "leosop.orbits.constellation": ["Constellation.subset", "Constellation.index_of", "Constellation.select_ids",
                                    "Constellation.family"],
    "leosop.orbits.tle": ["read_tle"],
    "leosop.orbits.omm": ["read_omm"],
    "leosop.frames": ["geodetic_to_ecef", "ecef_to_geodetic", "C_e_n", "ecef_to_enu", "enu_to_ecef", "enu_to_ned",
                      "ned_to_enu", "azimuth_elevation_range", "range_rate", "rotate_to_later_ecef", "gmst1982",
                      "teme_to_ecef"],
    "leosop.geometry.dop": ["gdop", "cofactor", "range_dops"],
    "leosop.positioning": ["position_snapshots", "position_static", "position_static_passes", "satellite_states",
                           "solve_snapshots", "solve_static", "gdop", "read_measurements", "solve_static_passes",
                           "solve_pair"],
    "leosop.positioning.measurements": ["read_measurements"],
    "leosop.positioning.static_passes": ["solve_static_passes"],
    "leosop.positioning.differential_pair": ["solve_pair"],
    "leosop.positioning.snapshot": ["solve_snapshots"],
    "leosop.positioning.static": ["solve_static"],
    "leosop.positioning.solve": ["satellite_states", "position_snapshots", "position_static",
                                 "position_static_passes"],
    "leosop.signal": ["comb_baseband", "noise_sigma", "add_noise", "doppler_blocks", "site_geometry", "coarse_stft",
                      "estimate_block", "estimate_blocks", "open_sigmf", "open_raw"],
    "leosop.signal.iq": ["open_sigmf", "open_raw", "Recording.read"],
    "leosop.signal.pilot": ["PilotComb.of", "PilotComb.through_lo", "comb_baseband", "noise_sigma", "add_noise"],
    "leosop.signal.channel": ["doppler_blocks", "site_geometry", "SiteChannel.doppler_hz",
                              "SiteChannel.doppler_rate_hz_per_s", "SiteChannel.amplitude", "SiteChannel.cn0_at"],
    "leosop.signal.coarse": ["coarse_fft", "coarse_stft"],
    "leosop.signal.fine": ["fine_ml", "fine_fmlef", "fine_fast"],
    "leosop.signal.doppler": ["estimate_block", "estimate_blocks", "ml_grid_points"],
    "leosop.fusion.aids": ["Aid.predict", "Aid.design", "Aid.rate", "Aid.matrices", "Aid.screen"],
    "leosop.fusion.engine": ["run"],
    "leosop.gnss.ppp": ["run_ppp", "prepare"],
}


def _module_file(name):
    """Repository-relative path of a module, as mypy and pyproject.toml name it."""
    path = Path(*name.split("."))
    return (path / "__init__.py" if (REPO_ROOT / path).is_dir() else path.with_suffix(".py")).as_posix()


FILES = [_module_file(name) for name in PUBLIC]
#: Packages whose __init__ re-exports their public names lazily (leosop.lazy).
FACADES = ("leosop.positioning", "leosop.signal")
#: What importing a facade must not load: each costs a large part of a second (pyfftw imports dask).
HEAVY = ("pyfftw", "dask", "scipy.stats", "scipy.optimize", "scipy.interpolate", "sigmf")


def test_pyproject_lists_the_same_modules():
    config = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]
    assert sorted(config["files"]) == sorted(FILES)


@pytest.mark.parametrize("module, qualname", [(m, q) for m, names in PUBLIC.items() for q in names])
def test_entry_point_is_fully_annotated(module, qualname):
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    signature = inspect.signature(obj)
    bare = [p.name for p in signature.parameters.values()
            if p.annotation is inspect.Parameter.empty and p.name not in ("self", "cls")]
    assert not bare, f"{module}.{qualname}: parameters without a type: {', '.join(bare)}"
    assert signature.return_annotation is not inspect.Signature.empty, f"{module}.{qualname}: no return type"


@pytest.mark.skipif(importlib.util.find_spec("mypy") is None, reason="mypy not installed (pip install .[test])")
def test_mypy_finds_nothing():
    # The cache (.mypy_cache, git-ignored) makes a repeated run ~2 s; a cold one took ~7 s here.
    done = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary", *FILES], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        pytest.fail(f"mypy {' '.join(FILES)}:\n{done.stdout}{done.stderr}", pytrace=False)


@pytest.mark.parametrize("package", FACADES)
def test_facade_names_resolve_to_their_home(package):
    facade = importlib.import_module(package)
    homes = type_checking_imports(REPO_ROOT / _module_file(package))
    assert sorted(facade.__all__) == sorted(homes), f"{package}: __all__ differs from its TYPE_CHECKING imports"
    for name, (module, attr) in homes.items():
        assert getattr(facade, name) is getattr(importlib.import_module(module, package), attr), name
        assert name in dir(facade)
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        facade.not_a_name


def test_facades_import_light():
    # A fresh interpreter: this one has loaded everything already.
    code = f"import sys, {', '.join(FACADES)}; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=60,
                          check=True)
    assert done.stdout.split() == [], f"importing {', '.join(FACADES)} loaded {done.stdout.strip()}"
