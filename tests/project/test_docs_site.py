"""The documentation site (mkdocs.yml) builds in strict mode, with each facade's public names in its API reference.

MkDocs renders docs/ and mkdocstrings the numpydoc docstrings; strict mode
turns every warning into a failure: a broken link or anchor, a page left out
of the nav, a docstring griffe cannot parse, a missing snippet. Most facade
names are exported lazily (``leosop.lazy``), which a static reader could
miss, so each rendered reference page is checked against its module's
``__all__``, and the gallery page against the figures it shows.
"""

import ast
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT

DOCS = REPO_ROOT / "docs"
#: What mkdocs.yml loads: MkDocs, mkdocstrings with its Python handler, the "#:" comment extension.
REQUIRED = ("mkdocs", "mkdocstrings", "mkdocstrings_handlers", "griffe_sphinx")
#: docs/reference/NAME.md renders one module: "::: leosop.orbits".
DIRECTIVE = re.compile(r"^::: ([\w.]+)\s*$", re.M)
IMAGE = re.compile(r"!\[[^\]]*\]\((gallery/[^)\s]+\.png)\)")


def _public_names(module):
    """A module's literal ``__all__``, read from its source (importing leosop.fusion.engine takes seconds)."""
    tree = ast.parse(Path(importlib.util.find_spec(module).origin).read_text())
    return next(ast.literal_eval(node.value) for node in tree.body
                if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets))


def _reference_pages():
    return sorted((p.stem, m) for p in (DOCS / "reference").glob("*.md") for m in DIRECTIVE.findall(p.read_text()))


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    missing = [name for name in REQUIRED if importlib.util.find_spec(name) is None]
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (pip install .[docs])")
    out = tmp_path_factory.mktemp("site")
    # About 6 s on one core (mkdocstrings reads the package's sources); the timeout only stops a hang.
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        pytest.fail(f"python -m mkdocs build --strict:\n{done.stdout}{done.stderr}", pytrace=False)
    return out


def test_every_facade_has_a_reference_page():
    modules = {module for _, module in _reference_pages()}
    assert modules == {"leosop.orbits", "leosop.positioning", "leosop.signal", "leosop.fusion.engine",
                       "leosop.gnss.ppp", "leosop.frames"}


@pytest.mark.parametrize(("page", "module"), _reference_pages())
def test_reference_page_documents_every_public_name(site, page, module):
    html = (site / "reference" / page / "index.html").read_text()
    anchors = set(re.findall(r'id="([\w.]+)"', html))
    assert module in anchors, f"reference/{page}.md does not render {module}"
    missing = [name for name in _public_names(module) if f"{module}.{name}" not in anchors]
    assert not missing, f"reference/{page}.md: {module} names in __all__ without an entry: {missing}"


def test_gallery_page_shows_the_committed_figures(site):
    shown = IMAGE.findall((DOCS / "gallery.md").read_text())
    assert shown, "docs/gallery.md shows no figure"
    for target in shown:
        assert (site / target).read_bytes() == (DOCS / target).read_bytes(), f"{target} not copied to the site"
    # The page is served as gallery/index.html: its image sources resolve against that folder.
    page_dir = site / "gallery"
    sources = re.findall(r'<img [^>]*src="([^"]+)"', (page_dir / "index.html").read_text())
    assert {(page_dir / src).resolve() for src in sources} == {(site / target).resolve() for target in shown}
