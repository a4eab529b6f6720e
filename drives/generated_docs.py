"""Sections of a Markdown doc that are rendered from a source file, kept in step with it.

A doc marks each such section with two HTML comments (invisible on the rendered page):

    <!-- generated from drives/fault_registry.py: fault-kinds -->
    ...the rendered text, rewritten by the generator...
    <!-- end generated -->

`GeneratedSections(source, renderers)` knows one source's renderers by section name:
`sync(text)` renders every section of that source anew, `names(text)` lists them, `rewrite`
is what a `python -m ...docgen` entry point does to the files. A test per doc asserts
`sync(text) == text`, so a doc that disagrees with its source fails until it is regenerated.

Users: `drives.fault_docgen` (the fault tables) and `cnc.interp.docgen` (the G/M code
tables). It imports nothing of ours, so it sits in the lowest package; any may use it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

END = "<!-- end generated -->"


class GeneratedSections:
    """The generated sections of one source file, by name, and how to render each."""

    def __init__(self, source: str, renderers: Mapping[str, Callable[[], str]]) -> None:
        self.source = source
        self.renderers = renderers
        start = r"<!-- generated from " + re.escape(source) + r": (?P<name>[a-z-]+) -->\n"
        self._start = re.compile(start)
        self._section = re.compile("(" + start + r")(?P<body>.*?)(" + re.escape(END) + ")", re.S)

    def names(self, text: str, where: str = "text") -> list[str]:
        """The names of this source's generated sections in `text`, in order."""
        return [m.group("name") for m in self._sections(text, where)]

    def sync(self, text: str, where: str = "text") -> str:
        """`text` with every section of this source rendered anew (other text untouched).

        ValueError, naming `where` and the line, for a section whose name has no renderer
        and for a start marker without its end marker.
        """
        parts, at = [], 0
        for m in self._sections(text, where):
            parts += [text[at : m.end(1)], self.renderers[m.group("name")](), END]
            at = m.end()
        return "".join(parts) + text[at:]

    def rewrite(self, paths: Iterable[str | Path]) -> list[Path]:
        """Re-render the sections of each file in place; the files that changed."""
        changed = []
        for name in paths:
            path = Path(name)
            old = path.read_text(encoding="utf-8")
            new = self.sync(old, str(path))
            if new != old:
                path.write_text(new, encoding="utf-8")
                changed.append(path)
        return changed

    def _sections(self, text: str, where: str) -> list[re.Match[str]]:
        found = list(self._section.finditer(text))
        closed = {m.start() for m in found}
        for m in found:
            if self._start.search(m.group("body")):  # the next section began first
                closed.discard(m.start())
        for m in self._start.finditer(text):
            if m.start() not in closed:
                raise ValueError(
                    f"{where}:{_line(text, m.start())}: generated section {m.group('name')!r}"
                    f" from {self.source} has no {END}"
                )
        for m in found:
            if m.group("name") not in self.renderers:
                raise ValueError(
                    f"{where}:{_line(text, m.start())}: no generated section "
                    f"{m.group('name')!r} from {self.source}; known: "
                    + ", ".join(sorted(self.renderers))
                )
        return found


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1
