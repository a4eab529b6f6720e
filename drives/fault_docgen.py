"""The fault tables of docs/drives.md, docs/cia402.md and docs/recovery.md, rendered from
the fault registry (drives.fault_registry).

A doc marks each generated section with `<!-- generated from drives/fault_registry.py: NAME
-->` and `<!-- end generated -->` (`drives.generated_docs`); `sync_docs` renders them anew,
`python -m drives.fault_docgen docs/drives.md docs/cia402.md docs/recovery.md` rewrites the
files, and tests/drives/test_fault_registry.py fails while a doc and the registry differ.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from drives.cia402.faults import spec
from drives.fault_registry import FAULT_KINDS, FaultKind, FaultParam, number
from drives.generated_docs import GeneratedSections

DOCS = ("docs/drives.md", "docs/cia402.md", "docs/recovery.md")


def _param(p: FaultParam) -> str:
    facts = [p.unit] if p.unit else []
    if p.default is not None:
        facts.append(f"default {number(p.default)}")
    if not (math.isinf(p.low) and math.isinf(p.high)):
        facts.append(f"{number(p.low)}..{number(p.high)}")
    return f"`{p.name}` ({', '.join(facts)})" if facts else f"`{p.name}`"


def _params(k: FaultKind) -> str:
    return ", ".join(_param(p) for p in k.params) or "—"


def _codes(k: FaultKind) -> str:
    return ", ".join(f"0x{c:04X} (0x{spec(c).register:02X})" for c in k.emcy) or "—"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _table(head: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def render_kinds() -> str:
    """docs/drives.md: every kind, its target, parameters, codes and what the master sees."""
    rows = [
        (f"`{k.name}`", k.target, _params(k), _codes(k), k.expect) for k in FAULT_KINDS.values()
    ]
    return _table(("kind", "target", "params", "EMCY (0x1001)", "the master sees"), rows)


def render_inject() -> str:
    """docs/cia402.md: the kinds Drive402.inject applies to its plant."""
    rows = [
        (f"`{k.name}`", _params(k), k.description)
        for k in FAULT_KINDS.values()
        if k.target == "drive"
    ]
    return _table(("kind", "params", "effect"), rows)


def render_detection() -> str:
    """docs/recovery.md: per kind, its class, how it is detected and what brings it back."""
    rows = [
        (f"`{k.name}`", k.recovery_class, k.detection, k.recovery)
        for k in FAULT_KINDS.values()
        if k.detectable
    ]
    return _table(("fault kind", "class", "detected (default mill)", "recovery"), rows)


def render_undetected() -> str:
    """docs/recovery.md: the kinds no monitor can see, and why."""
    rows = [
        (f"`{k.name}`", f"{k.detection}. Recovery: {k.recovery}.")
        for k in FAULT_KINDS.values()
        if not k.detectable
    ]
    return _table(("fault kind", "why"), rows)


RENDERERS: dict[str, Callable[[], str]] = {
    "fault-kinds": render_kinds,
    "inject-kinds": render_inject,
    "fault-detection": render_detection,
    "undetected-faults": render_undetected,
}
SECTIONS = GeneratedSections("drives/fault_registry.py", RENDERERS)


def sync_docs(text: str) -> str:
    """`text` with every generated fault section rendered from the registry anew."""
    return SECTIONS.sync(text)


def generated_sections(text: str) -> list[str]:
    """The names of the generated fault sections in `text`."""
    return SECTIONS.names(text)


if __name__ == "__main__":  # python -m drives.fault_docgen docs/...md: rewrite their tables
    import sys

    for path in SECTIONS.rewrite(sys.argv[1:] or DOCS):
        print(f"{path}: fault tables rewritten")
