"""The project's ruff configuration (pyproject.toml) finds nothing in leosop, tests and tools."""

import importlib.util
import subprocess
import sys

import pytest

from tests.helpers import REPO_ROOT


@pytest.mark.skipif(importlib.util.find_spec("ruff") is None, reason="ruff not installed (pip install .[test])")
def test_ruff_finds_nothing():
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise",
                           "leosop", "tests", "tools"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    if done.returncode != 0:
        pytest.fail(f"ruff check leosop tests tools:\n{done.stdout}{done.stderr}", pytrace=False)
