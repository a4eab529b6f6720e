"""The `path` parameter: which data items a current/sample request is about.

The reference agent evaluates a full XPath 1.0 expression against the probe document. We
accept the subset that MTConnect clients use in practice (docs/mtconnect.md):

- location paths from the document root (`/MTConnectDevices/Devices/Device/...`) or
  anywhere (`//Axes`, `//Linear[@name="X"]//DataItem`);
- steps that are an element name or `*`, with `//` between steps;
- predicates `[@attr]`, `[@attr="value"]` / `[@attr='value']`, `[Child]`, `[n]`, chained;
- unions of such paths with `|`.

A matched DataItem selects itself; any other matched element selects every DataItem under
it. A path that cannot be parsed, or that selects nothing, is INVALID_PATH (the MTConnectError
2.5 code; cppagent says INVALID_XPATH).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

from mtconnect.errors import AgentError

_ALLOWED = re.compile(r"^[A-Za-z0-9_:@*/\[\]=\"'. \-]+$")


class PathError(AgentError, ValueError):
    """An XPath filter (`path=`) the agent cannot read."""


def split_union(path: str) -> list[str]:
    parts, depth, quote, start = [], 0, "", 0
    for i, c in enumerate(path):
        if quote:
            if c == quote:
                quote = ""
        elif c in "\"'":
            quote = c
        elif c == "[":
            depth += 1
        elif c == "]":
            depth -= 1
        elif c == "|" and depth == 0:
            parts.append(path[start:i])
            start = i + 1
    parts.append(path[start:])
    return [p.strip() for p in parts]


def select(document: ET.Element, path: str) -> set[str]:
    """Data item ids selected by `path` in `document` (an un-namespaced MTConnectDevices
    element tree)."""
    holder = ET.Element("document")
    holder.append(document)
    ids: set[str] = set()
    for part in split_union(path):
        if not part or not _ALLOWED.match(part) or not part.startswith("/"):
            raise PathError(part or path)
        # ElementPath works relative to an element: "//x" from the document node becomes
        # ".//x", "/a/b" becomes "a/b".
        rel = "." + part if part.startswith("//") else part[1:]
        if "//" in rel.replace(".//", "", 1) and rel.endswith("//"):
            raise PathError(part)
        try:
            found = holder.findall(rel)
        except Exception:  # noqa: BLE001 - ElementPath's own failure is no client's business
            # the answer names the path the client sent, never the parser's exception text
            # (e.g. "//Foo[" made ElementPath raise "'NoneType' object is not callable")
            raise PathError(part) from None
        for el in found:
            if el.tag == "DataItem":
                ids.add(el.get("id", ""))
            else:
                ids.update(d.get("id", "") for d in el.iter("DataItem"))
    ids.discard("")
    return ids
