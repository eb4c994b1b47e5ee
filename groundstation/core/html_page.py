"""What the self-contained HTML reports share (the campaign's, the identification's):
the page's base style, escaping, a table cell.  Each report adds the row styles of its
own tables; neither loads anything from outside the page."""

from __future__ import annotations

import html
from typing import Any

#: the look both report pages share; a page appends the styles of its own rows
BASE_STYLE = """
body { font-family: sans-serif; margin: 1.5em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.85em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }
th { background: #eee; } td.text { text-align: left; }
img { max-width: 100%; display: block; margin: 0.5em 0 1.5em; }
pre { background: #f6f6f6; padding: 0.5em; white-space: pre-wrap; }
"""


def escaped(v: Any) -> str:
    """`v` as HTML text (None: empty)."""
    return html.escape("" if v is None else str(v))


def cell(v: Any, text: bool = False) -> str:
    """A table cell: numbers right-aligned (the table's default), `text` left-aligned."""
    return f'<td class="text">{escaped(v)}</td>' if text else f"<td>{escaped(v)}</td>"
