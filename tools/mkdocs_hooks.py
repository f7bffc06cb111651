"""MkDocs hook (mkdocs.yml ``hooks``): the pages' runnable examples render as Python code.

``tests/project/test_docs.py`` runs the blocks fenced ```` ```python runnable ```` (and
```` ```python runnable data ````); GitHub highlights them by the first word,
but Python-Markdown's fences accept no word after the language and would
render them as paragraphs, so the site sees them as plain ```` ```python ````.
"""

import re

RUNNABLE_FENCE = re.compile(r"^```python runnable( data)?[ \t]*$", re.M)


def on_page_markdown(markdown: str, **kwargs: object) -> str:
    """Rewrite the runnable fences of one page to plain Python fences.

    Parameters
    ----------
    markdown : str
        The page's Markdown source.
    **kwargs
        The page, config and files MkDocs passes; not used.

    Returns
    -------
    str
        The same source with each runnable fence opening as ```` ```python ````.
    """
    return RUNNABLE_FENCE.sub("```python", markdown)
