"""The figure gallery (docs/gallery.md, docs/gallery/*.png) is what tools/make_gallery.py writes from the code.

The page's fixed text (introduction, commands, captions, the Monte Carlo spec)
is compared with what the script renders now, every figure a page shows must
be committed and small, and the quickest run is redrawn and its printed
summary compared with the page's, so stale numbers fail here.
"""

import importlib.util
import re

import pytest

from tests.helpers import REPO_ROOT

DOCS = REPO_ROOT / "docs"
IMAGE = re.compile(r"!\[[^\]]*\]\((gallery/[^)\s]+\.png)\)")
#: The whole gallery stays light for a docs checkout.
TOTAL_BUDGET_BYTES = 2_000_000


@pytest.fixture(scope="module")
def gallery():
    pytest.importorskip("PIL")
    spec = importlib.util.spec_from_file_location("make_gallery", REPO_ROOT / "tools" / "make_gallery.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_page_is_what_the_script_renders(gallery):
    page = (DOCS / "gallery.md").read_text()
    sections = gallery.parse(page)
    assert [name for name, _, _ in sections] == list(gallery.RUNS), "a run is missing: redraw the whole gallery"
    assert gallery.render(sections) == page, "docs/gallery.md is stale: run python tools/make_gallery.py"


def test_every_figure_the_docs_show_is_committed_and_small():
    shown = {target for page in DOCS.glob("*.md") for target in IMAGE.findall(page.read_text())}
    assert shown, "no gallery figure shown"
    for target in sorted(shown):
        path = DOCS / target
        assert path.is_file(), f"docs show {target}, which is not committed"
    committed = sorted((DOCS / "gallery").glob("*.png"))
    assert {f"gallery/{p.name}" for p in committed} <= shown, "a figure nobody shows is committed"
    assert sum(p.stat().st_size for p in committed) < TOTAL_BUDGET_BYTES


def test_the_quickest_run_still_prints_what_the_page_says(gallery, tmp_path):
    gallery.main(["--only", "visibility", "--docs", str(tmp_path)])
    (name, printed, figures), = gallery.parse((tmp_path / "gallery.md").read_text())
    committed = {n: (p, f) for n, p, f in gallery.parse((DOCS / "gallery.md").read_text())}
    assert (printed, figures) == committed[name], "docs/gallery.md is stale: run python tools/make_gallery.py"
    for png in figures:
        drawn = tmp_path / "gallery" / f"{name}-{png}"
        assert 0 < drawn.stat().st_size <= gallery.PNG_BUDGET_BYTES
