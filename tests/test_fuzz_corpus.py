"""Inputs that once broke a reader (found by ``tools/fuzz_readers.py``), replayed.

Each ``crash-*`` file in ``tests/fuzz_corpus/<target>/`` must now be read or
refused with an InputError. ``oom-*`` files made a reader allocate gigabytes;
they are kept for the reader's owner but not replayed here. Findings in readers this change does not own are listed in
``OPEN`` with the owner's fix; they are strict xfails, so fixing the reader
turns them into failures here until they leave the list.
"""

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CORPUS = Path(__file__).resolve().parent / "fuzz_corpus"

_spec = importlib.util.spec_from_file_location("fuzz_readers", REPO / "tools" / "fuzz_readers.py")
fuzz_readers = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz_readers)

#: Findings still open, by file name: where the fix belongs.
OPEN = {
    "clk/crash-0d170070d4c09eb6": "gnss/rinex.py read_text: zlib.error of a corrupt gzip stream is not caught",
    "clk/crash-6e9dd118c7add9a4": "gnss/products.py read_clk: records that leave no epoch raise IndexError",
    "clk/crash-170c749c253beeba": "gnss/products.py _epoch (via read_clk): huge epoch fields raise OverflowError",
    "clk/crash-b469fdd35903d664": "gnss/products.py _epoch (via read_clk): huge epoch fields raise OverflowError",
    "clk/crash-7ada3ff7fcd5e09f": "gnss/products.py _epoch (via read_clk): month 0 raises ValueError",
    "sp3/crash-1a3ffacf5c3f86dc": "gnss/products.py _epoch: impossible epoch fields raise ValueError/OverflowError",
    "sp3/crash-a9db9653b9f753dc": "gnss/products.py _epoch: impossible epoch fields raise ValueError/OverflowError",
    "sp3/crash-b0034b39f4582629": "gnss/products.py _epoch: month 0 raises ValueError",
    "sp3/crash-ceda122fb1a18983": "gnss/products.py _epoch: impossible epoch fields raise ValueError/OverflowError",
    "scenario/crash-235ef9dd2faf8ce7": "scenarios.py load_scenario: a non-UTF-8 file raises UnicodeDecodeError "
                                       "(the CLI turns it into exit 2, but without the file name)",
    "rinex_obs/crash-8b59836f9d30598e": "gnss/rinex.py read_obs: an impossible epoch date (day 0) raises ValueError",
    "rinex_obs/crash-0b2d4393c29d6753": "gnss/rinex.py read_obs: a non-numeric count in SYS / # / OBS TYPES raises "
                                        "ValueError",
}


def _cases():
    for path in sorted(CORPUS.glob("*/crash-*")):
        key = f"{path.parent.name}/{path.name}"
        marks = [pytest.mark.xfail(strict=True, reason=OPEN[key])] if key in OPEN else []
        yield pytest.param(path.parent.name, path, id=key, marks=marks)


def test_corpus_covers_known_targets():
    targets = {p.name for p in CORPUS.iterdir() if p.is_dir()}
    assert targets and targets <= set(fuzz_readers.TARGETS)
    assert all((CORPUS / key).is_file() for key in OPEN)


@pytest.mark.parametrize("target, path", _cases())
def test_crashing_input_is_now_handled(tmp_path, target, path):
    failure = fuzz_readers.check_one(target, path.read_bytes(), tmp_path)
    assert failure is None, failure
