"""A built wheel, installed outside the source tree, runs the main job.

The bundled element set is package data; this test catches it being found
through the source tree again (a plain ``pip install .`` broke ``leosop
simulate`` that way). The wheel is built without isolation and installed
without dependencies into a fresh venv that sees the running environment's
site-packages through a ``.pth`` file (whatever that environment is: a venv,
a user install, the system Python), so the test needs no network. The venv's
own site-packages comes first on its path, so it imports the wheel, not the
source tree or an editable install (the ``.pth`` lines add directories only;
the ``.pth`` hooks inside them, such as an editable finder, do not run).
"""

import json
import os
import shutil
import site
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT


pytest.importorskip("wheel", reason="building a wheel needs the 'wheel' package (test extra)")
pytest.importorskip("setuptools", minversion="77",
                    reason="building without isolation needs the test extra's setuptools >= 77 (SPDX licence field)")


def _run(cmd, cwd, **kw):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=600, **kw)


def _site_dirs():
    """The running interpreter's package directories (venv, system, user)."""
    dirs = list(site.getsitepackages())
    if site.ENABLE_USER_SITE:
        dirs.append(site.getusersitepackages())
    dirs += [p for p in sys.path if p.rstrip("/").endswith(("site-packages", "dist-packages"))]
    return [d for d in dict.fromkeys(dirs) if Path(d).is_dir()]


def _see_running_environment(python, cwd):
    """Make the new venv see the running environment's dependencies."""
    probe = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=cwd)
    assert probe.returncode == 0, probe.stderr
    own = Path(probe.stdout.strip())
    (own / "_leosop_test_deps.pth").write_text("\n".join(_site_dirs()) + "\n")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    base = tmp_path_factory.mktemp("wheel")
    # Built from a copy without build/ and egg-info: their leftovers from an
    # earlier build would put files in the wheel that a clean clone lacks.
    src = base / "src"
    shutil.copytree(REPO_ROOT, src, symlinks=True,
                    ignore=shutil.ignore_patterns("build", "*.egg-info", ".git", "__pycache__", ".pytest_cache"))
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                  "-w", str(base / "dist"), str(src)], cwd=base)
    assert built.returncode == 0, built.stderr
    (wheel,) = (base / "dist").glob("leosop-*.whl")
    venv.create(base / "env", system_site_packages=False, with_pip=True)
    python = base / "env" / "bin" / "python"
    _see_running_environment(python, base)
    inst = _run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], cwd=base)
    assert inst.returncode == 0, inst.stderr
    return python, base / "elsewhere"


def test_wheel_carries_the_bundled_data(installed):
    python, cwd = installed
    cwd.mkdir(exist_ok=True)
    probe = ("import leosop, json; from leosop.orbits import DEFAULT_TLE, load_constellation;"
             "print(json.dumps([leosop.__file__, str(DEFAULT_TLE), len(load_constellation())]))")
    out = _run([str(python), "-c", probe], cwd=cwd)
    assert out.returncode == 0, out.stderr
    pkg_file, tle, n_sats = json.loads(out.stdout)
    env_dir = str(python.parents[1])
    assert pkg_file.startswith(env_dir), f"imported {pkg_file}, not the installed wheel"
    assert tle.startswith(env_dir) and n_sats == 4408


def test_installed_simulate_runs_from_another_directory(installed):
    python, cwd = installed
    cwd.mkdir(exist_ok=True)
    out = _run([str(python), "-m", "leosop", "simulate", "--level", "measurement", "--json"], cwd=cwd)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    # The default flight at measurement level fuses to a few metres (README); 10 m is
    # the scenario goal, so a broken install or data set cannot pass.
    assert doc["fused"]["pos_err_mean_m"] < 10.0 and doc["fused"]["availability"] == 1.0


def test_wheel_carries_every_bundled_data_file(installed):
    # Every file under leosop/data/ that the code reads (scenarios, study
    # specs, element sets, the example recording) is in the installed package;
    # a new data folder missing from pyproject's package-data fails here.
    python, cwd = installed
    cwd.mkdir(exist_ok=True)
    probe = "import leosop, pathlib; print(pathlib.Path(leosop.__file__).parent / 'data')"
    out = _run([str(python), "-c", probe], cwd=cwd)
    assert out.returncode == 0, out.stderr
    installed_dir = Path(out.stdout.strip())
    source_dir = REPO_ROOT / "leosop" / "data"

    def listing(d):
        return {p.relative_to(d).as_posix() for p in d.rglob("*")
                if p.is_file() and p.name != "README.md" and "__pycache__" not in p.parts}

    assert listing(source_dir) - listing(installed_dir) == set()
