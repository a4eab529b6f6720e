"""docs/gcode.md's code tables, rendered from the code table (cnc.interp.codes).

The doc marks each generated section with `<!-- generated from cnc/interp/codes.py: NAME -->`
and `<!-- end generated -->`; `sync_docs` renders them anew, `python -m cnc.interp.docgen
docs/gcode.md` rewrites the file, and tests/cnc/test_interp_code_table.py fails while the
doc and the table differ.
"""

from __future__ import annotations

import re

from cnc.interp.codes import render_g_table, render_m_table, render_order

RENDERERS = {"g-codes": render_g_table, "m-codes": render_m_table, "order": render_order}
_MARK = re.compile(
    r"(<!-- generated from cnc/interp/codes.py: (?P<name>[a-z-]+) -->\n)(?P<body>.*?)"
    r"(<!-- end generated -->)",
    re.S,
)


def sync_docs(text: str) -> str:
    """`text` (docs/gcode.md) with every generated section rendered from the table anew."""

    def fill(m: re.Match) -> str:
        return m.group(1) + RENDERERS[m.group("name")]() + m.group(4)

    return _MARK.sub(fill, text)


def generated_sections(text: str) -> list[str]:
    """The names of the generated sections in `text`."""
    return [m.group("name") for m in _MARK.finditer(text)]


if __name__ == "__main__":  # python -m cnc.interp.docgen docs/gcode.md: rewrite its tables
    import sys
    from pathlib import Path

    for arg in sys.argv[1:]:
        path = Path(arg)
        path.write_text(sync_docs(path.read_text(encoding="utf-8")), encoding="utf-8")
