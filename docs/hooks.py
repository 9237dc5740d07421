"""MkDocs hook: the docstrings' Sphinx roles render as code in the API reference.

The library's docstrings name other objects the Sphinx way (``:class:`Bus```,
``:meth:`~Drive.stop```). mkdocstrings leaves the role in front of the code
span; this drops it, and shortens a ``~``-prefixed path to its last part, as
Sphinx shows it. (They stay code, not links: many are relative names.)
"""

from __future__ import annotations

import re
from typing import Any

_ROLE = re.compile(r":(?:class|mod|func|meth|data|attr|exc|obj|const):<code>(~?)([^<]*)</code>")


def _code(match: re.Match[str]) -> str:
    tilde, target = match.groups()
    return f"<code>{target.rsplit('.', 1)[-1] if tilde else target}</code>"


def on_page_content(html: str, **kwargs: Any) -> str:
    return _ROLE.sub(_code, html)
