"""mkdocs hook: the docstrings use Sphinx cross-reference roles (:func:`name`), which
mkdocstrings renders literally as ``:func:<code>name</code>``; keep the code, drop the role."""

from __future__ import annotations

import re

_ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const|ref|term)::?(?=<code>)")


def on_page_content(html: str, **kwargs) -> str:
    return _ROLE.sub("", html)
