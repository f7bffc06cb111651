"""The documentation's examples run, and its links resolve.

Code blocks fenced as ``python runnable`` in ``docs/*.md`` are run in order,
one namespace per page, in a fresh working directory; blocks fenced
``python runnable data`` read the project's real data through the relative
path ``../shared/data`` and are skipped when it is absent. An example that
raises (its own asserts included) fails the test.
"""

import re

import pytest

from tests.helpers import DATA_DIR, REPO_ROOT


DOCS = REPO_ROOT / "docs"
BLOCK = re.compile(r"^```python runnable( data)?\n(.*?)^```", re.M | re.S)
LINK = re.compile(r"\]\(([^)#\s]+)(#[^)\s]*)?\)")
#: The pages of the uses the README and issue 13 list, each with a worked example.
USE_PAGES = ("getting-started.md", "replay.md", "visibility.md", "positioning.md", "fusion.md", "alignment.md",
             "ppp.md", "export.md")


def _pages():
    return sorted(p.name for p in DOCS.glob("*.md") if BLOCK.search(p.read_text()))


def _anchor(heading):
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


@pytest.mark.parametrize("page", _pages())
def test_runnable_examples(page, tmp_path, monkeypatch, capsys):
    work = tmp_path / "work"
    work.mkdir()
    if DATA_DIR.is_dir():
        (tmp_path / "shared").mkdir()
        (tmp_path / "shared" / "data").symlink_to(DATA_DIR, target_is_directory=True)
    monkeypatch.chdir(work)
    namespace = {"__name__": f"docs_{page}"}
    for k, match in enumerate(BLOCK.finditer((DOCS / page).read_text())):
        if match.group(1) and not DATA_DIR.is_dir():
            pytest.skip(f"{page} block {k + 1} reads ../shared/data, absent here")
        code = compile(match.group(2), f"{DOCS / page} (runnable block {k + 1})", "exec")
        exec(code, namespace)
    assert capsys.readouterr().out.strip(), f"{page}: the examples print nothing for a reader to compare"


def test_every_use_page_has_a_runnable_example_and_is_listed():
    index = (DOCS / "README.md").read_text()
    for page in USE_PAGES:
        assert page in _pages(), f"{page} has no runnable example"
        assert f"({page})" in index, f"docs/README.md does not link {page}"


@pytest.mark.parametrize("page", sorted(p.name for p in DOCS.glob("*.md")))
def test_relative_links_resolve(page):
    text = (DOCS / page).read_text()
    for target, anchor in LINK.findall(text):
        if "://" in target or target.startswith("mailto:"):
            continue
        path = (DOCS / target).resolve()
        assert path.exists(), f"{page}: broken link {target}"
        if anchor and path.suffix == ".md":
            headings = re.findall(r"^#+ (.*)$", path.read_text(), re.M)
            assert anchor[1:] in {_anchor(h) for h in headings}, f"{page}: no heading for {target}{anchor}"
