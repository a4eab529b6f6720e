"""The official companion-specification NodeSet2 files, parsed for comparison with the
project's own declarations (cnc/faces/opcua/model.py). Read from the shared reference
folder, never copied."""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import pytest

from tests.reference import MISSING, OPCUA_NODESETS

NS = {"u": "http://opcfoundation.org/UA/2011/03/UANodeSet.xsd"}
UA = "http://opcfoundation.org/UA/"
FILES = (
    "Opc.Ua.Di.NodeSet2.xml",
    "Opc.Ua.Machinery.NodeSet2.xml",
    "Opc.Ua.IA.NodeSet2.xml",
    "Opc.Ua.MachineTool.NodeSet2.xml",
)
REF_NAMES = {
    "HasComponent": 47,
    "HasProperty": 46,
    "HasAddIn": 17604,
    "HasSubtype": 45,
    "HasTypeDefinition": 40,
    "HasModellingRule": 37,
    "HasOrderedComponent": 49,
    "HasInterface": 17603,
}


@dataclass(frozen=True)
class Node:
    node: tuple[str, int]
    node_class: str
    name: tuple[str, str]
    refs: tuple[tuple[int, bool, tuple[str, int]], ...]
    data_type: tuple[str, int] | None
    fields: tuple[tuple[str, int], ...]
    value: int | None = None  # an integer Value (a state's StateNumber), else None

    def targets(self, ref: int, forward: bool = True) -> list[tuple[str, int]]:
        return [t for r, f, t in self.refs if r == ref and f == forward]


@functools.cache
def nodes() -> dict[tuple[str, int], Node]:
    if not OPCUA_NODESETS.is_dir():
        pytest.skip(MISSING)
    out: dict[tuple[str, int], Node] = {}
    for fname in FILES:
        root = ET.parse(OPCUA_NODESETS / fname).getroot()
        uris = [u.text for u in root.find("u:NamespaceUris", NS)]
        aliases = {a.get("Alias"): a.text for a in root.find("u:Aliases", NS)}

        def ref(text: str, uris=uris, aliases=aliases) -> tuple[str, int]:
            text = aliases.get(text, text)
            if text in REF_NAMES:
                return (UA, REF_NAMES[text])
            if text.startswith("ns="):
                index, rest = text[3:].split(";", 1)
                return (uris[int(index) - 1], int(rest[2:]))
            return (UA, int(text[2:]))

        for el in root:
            if not el.get("NodeId"):
                continue
            browse = el.get("BrowseName")
            if ":" in browse:
                index, text = browse.split(":", 1)
                name = (uris[int(index) - 1], text)
            else:
                name = (UA, browse)
            refs = tuple(
                (ref(r.get("ReferenceType"))[1], r.get("IsForward", "true") != "false", ref(r.text))
                for r in el.find("u:References", NS)
            )
            definition = el.find("u:Definition", NS)
            fields = tuple((f.get("Name"), int(f.get("Value", "0"))) for f in (definition or []))
            value_el = el.find("u:Value", NS)
            value = None
            if (
                value_el is not None
                and len(value_el)
                and value_el[0].tag.split("}")[-1] in ("Int32", "UInt32")
            ):
                value = int(value_el[0].text)
            dt = el.get("DataType")
            out[ref(el.get("NodeId"))] = Node(
                ref(el.get("NodeId")),
                el.tag.split("}")[1],
                name,
                refs,
                ref(dt) if dt and dt.startswith(("ns=", "i=")) or dt in aliases else None,
                fields,
                value,
            )
    return out
