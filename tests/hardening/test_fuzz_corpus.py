"""Inputs that once broke a reader (found by ``tools/fuzz_readers.py``), replayed.

Each ``crash-*`` file in ``tests/hardening/fuzz_corpus/<target>/`` must now be read or
refused with an InputError. ``oom-*`` files made a reader allocate gigabytes;
they are kept for the reader's owner but not replayed here. Findings in readers this change does not own are listed in
``OPEN`` with the owner's fix; they are strict xfails, so fixing the reader
turns them into failures here until they leave the list.
"""

import importlib.util
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT

CORPUS = Path(__file__).resolve().parent / "fuzz_corpus"

_spec = importlib.util.spec_from_file_location("fuzz_readers", REPO_ROOT / "tools" / "fuzz_readers.py")
fuzz_readers = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz_readers)

#: Findings still open, by file name: where the fix belongs.
OPEN = {}


def _cases():
    for path in sorted(CORPUS.glob("*/crash-*")):
        key = f"{path.parent.name}/{path.name}"
        marks = [pytest.mark.xfail(strict=True, reason=OPEN[key])] if key in OPEN else []
        yield pytest.param(path.parent.name, path, id=key, marks=marks)


def test_corpus_covers_known_targets():
    targets = {p.name for p in CORPUS.iterdir() if p.is_dir()}
    assert targets and targets <= set(fuzz_readers.TARGETS)
    assert all((CORPUS / key).is_file() for key in OPEN)


@pytest.mark.parametrize("target, path", list(_cases()))
def test_crashing_input_is_now_handled(tmp_path, target, path):
    failure = fuzz_readers.check_one(target, path.read_bytes(), tmp_path)
    assert failure is None, failure
