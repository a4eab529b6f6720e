"""docs/gcode.md's code tables, rendered from the code table (cnc.interp.codes).

The doc marks each generated section with `<!-- generated from cnc/interp/codes.py: NAME -->`
and `<!-- end generated -->` (`drives.generated_docs`, shared with the drives' fault tables);
`sync_docs` renders them anew, `python -m cnc.interp.docgen docs/gcode.md` rewrites the
file, and tests/cnc/test_interp_code_table.py fails while the doc and the table differ.
"""

from __future__ import annotations

from cnc.interp.codes import render_g_table, render_m_table, render_order
from drives.generated_docs import GeneratedSections

DOCS = ("docs/gcode.md",)
RENDERERS = {"g-codes": render_g_table, "m-codes": render_m_table, "order": render_order}
SECTIONS = GeneratedSections("cnc/interp/codes.py", RENDERERS)


def sync_docs(text: str) -> str:
    """`text` (docs/gcode.md) with every generated section rendered from the table anew."""
    return SECTIONS.sync(text)


def generated_sections(text: str) -> list[str]:
    """The names of the generated sections in `text`."""
    return SECTIONS.names(text)


if __name__ == "__main__":  # python -m cnc.interp.docgen docs/gcode.md: rewrite its tables
    import sys

    for path in SECTIONS.rewrite(sys.argv[1:] or DOCS):
        print(f"{path}: code tables rewritten")
