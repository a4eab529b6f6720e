"""Import PLCopen TC6 XML (tc6_0200 / tc6_0201) ladder bodies, as drawn in OpenPLC Editor
and Beremiz, into the same program tree the text parser makes.

Supported in an `<LD>` body: leftPowerRail, rightPowerRail, contact (negated, edge rising /
falling), coil (negated, storage set / reset, edge rising / falling), block TON / TOF / CTU
(IN, PT / CU, R, PV inputs; Q, ET / CV outputs), inVariable (constants and variables for
block inputs), outVariable (block ET / CV outputs), comment. The wiring graph is turned back
into series (AND) and parallel (OR, several connections into one point) structure; every
coil, block and outVariable becomes one rung. Edge contacts and edge coils get hidden helper
tags (`_E<localId>`), edge detection rungs run before the rungs that use them.

Diagnostics carry the XML file's line and column of the offending element.
"""

from __future__ import annotations

import os
import xml.parsers.expat
from dataclasses import dataclass, field

from plc.ladder.ast import Branch, Element, Instr, Operand, Program, Rung, TagDecl
from plc.ladder.diagnostics import DiagnosticSink
from plc.ladder.parser import parse_int, parse_time_ms

_INT_TYPES = {
    "INT",
    "SINT",
    "DINT",
    "LINT",
    "UINT",
    "USINT",
    "UDINT",
    "WORD",
    "BYTE",
    "DWORD",
    "TIME",
}
_TYPE_MAP = {"BOOL": "BOOL", "TON": "TIMER", "TOF": "TIMER", "CTU": "COUNTER"}
_VAR_SECTIONS = {"localVars", "inputVars", "outputVars", "inOutVars", "globalVars", "tempVars"}


@dataclass(slots=True)
class Node:
    tag: str
    attrib: dict[str, str]
    line: int
    col: int
    children: list[Node] = field(default_factory=list)
    text: str = ""

    def find(self, tag: str) -> Node | None:
        return next((c for c in self.children if c.tag == tag), None)

    def findall(self, tag: str) -> list[Node]:
        return [c for c in self.children if c.tag == tag]

    def iter(self, tag: str):
        if self.tag == tag:
            yield self
        for c in self.children:
            yield from c.iter(tag)

    def all_text(self) -> str:
        return self.text + "".join(c.all_text() for c in self.children)


def _parse_xml(data: bytes) -> Node:
    parser = xml.parsers.expat.ParserCreate(namespace_separator=" ")
    root = Node("", {}, 0, 0)
    stack = [root]

    def start(name: str, attrs: dict[str, str]) -> None:
        local = name.rsplit(" ", 1)[-1]
        attrib = {k.rsplit(" ", 1)[-1]: v for k, v in attrs.items()}
        node = Node(local, attrib, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1)
        stack[-1].children.append(node)
        stack.append(node)

    def end(name: str) -> None:
        stack.pop()

    def chars(text: str) -> None:
        stack[-1].text += text

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.Parse(data, True)
    return root.children[0]


# Power-flow expressions rebuilt from the graph.
TRUE = ("true",)


def _and(parts):
    flat = []
    for p in parts:
        if p == TRUE:
            continue
        flat.extend(p[1] if p[0] == "and" else [p])
    if not flat:
        return TRUE
    return flat[0] if len(flat) == 1 else ("and", flat)


def _or(parts):
    if not parts or any(p == TRUE for p in parts):
        return TRUE
    flat = []
    for p in parts:
        flat.extend(p[1] if p[0] == "or" else [p])
    return flat[0] if len(flat) == 1 else ("or", flat)


class _Importer:
    def __init__(self, root: Node, file: str, sink: DiagnosticSink) -> None:
        self.root = root
        self.file = file
        self.sink = sink
        self.program = Program("main", file)
        self.nodes: dict[str, Node] = {}
        self.memo: dict[tuple[str, str], tuple] = {}
        self.visiting: set[tuple[str, str]] = set()
        self.edge_rungs: list[tuple[list[Element], Instr, str]] = []
        self.declared: set[str] = set()

    def error(self, node: Node, msg: str) -> None:
        self.sink.error(node.line, node.col, msg)

    def op(self, text: str, node: Node) -> Operand:
        text = text.strip()
        if text.startswith("%"):
            return Operand("address", text.upper(), node.line, node.col)
        if text.upper().startswith("T#") or text.upper().startswith("TIME#"):
            body = "T#" + text.split("#", 1)[1]
            ms = parse_time_ms(body)
            if ms is None:
                self.error(node, f"malformed time literal {text!r}")
                ms = 0
            return Operand("time", body, node.line, node.col, ms)
        try:
            return Operand("int", text, node.line, node.col, parse_int(text))
        except ValueError:
            return Operand("tag", text, node.line, node.col)

    def instr(self, mnemonic: str, operands: list[str | Operand], node: Node) -> Instr:
        ops = [o if isinstance(o, Operand) else self.op(o, node) for o in operands]
        return Instr(mnemonic, ops, node.line, node.col)

    # -- variables -------------------------------------------------------------------------
    def variables(self, pou: Node) -> None:
        sections: list[Node] = []
        iface = pou.find("interface")
        if iface is not None:
            sections += [c for c in iface.children if c.tag in _VAR_SECTIONS]
        for conf in self.root.iter("configuration"):
            sections += conf.findall("globalVars")
            for res in conf.findall("resource"):
                sections += res.findall("globalVars")
        for section in sections:
            retain = (
                section.attrib.get("retain") == "true" or section.attrib.get("persistent") == "true"
            )
            for var in section.findall("variable"):
                self.variable(var, retain)

    def variable(self, var: Node, retain: bool) -> None:
        name = var.attrib.get("name", "")
        if name.upper() in self.declared:
            return  # an externalVar seen again as the global it refers to
        type_node = var.find("type")
        kind = ""
        if type_node is not None and type_node.children:
            t = type_node.children[0]
            kind = t.attrib.get("name", "") if t.tag == "derived" else t.tag
        kind = kind.upper()
        tag_type = _TYPE_MAP.get(kind) or ("INT" if kind in _INT_TYPES else None)
        if tag_type is None:
            self.sink.warning(
                var.line,
                var.col,
                f"variable {name!r} of type {kind or '?'} is not "
                "supported by the ladder runtime and was left out",
            )
            return
        decl = TagDecl(name, tag_type, var.line, var.col, retain=retain)
        address = var.attrib.get("address")
        if address:
            decl.address = Operand("address", address.upper(), var.line, var.col)
        init = var.find("initialValue")
        if init is not None and tag_type in ("BOOL", "INT"):
            simple = init.find("simpleValue")
            if simple is not None:
                value = simple.attrib.get("value", "").strip()
                upper = value.upper()
                if upper in ("TRUE", "FALSE"):
                    decl.init = 1 if upper == "TRUE" else 0
                else:
                    try:
                        decl.init = parse_int(value)
                    except ValueError:
                        self.sink.warning(var.line, var.col, f"initial value {value!r} ignored")
        doc = var.find("documentation")
        if doc is not None:
            decl.comment = " ".join(doc.all_text().split())
        self.program.tags.append(decl)
        self.declared.add(name.upper())

    # -- the graph -----------------------------------------------------------------------------
    def sources(self, point: Node | None) -> list[tuple[str, str]]:
        if point is None:
            return []
        return [
            (c.attrib.get("refLocalId", ""), c.attrib.get("formalParameter", ""))
            for c in point.findall("connection")
        ]

    def block_input(self, block: Node, formal: str) -> Node | None:
        iv = block.find("inputVariables")
        if iv is None:
            return None
        for v in iv.findall("variable"):
            if v.attrib.get("formalParameter", "").upper() == formal:
                return v.find("connectionPointIn")
        return None

    def power_in(self, point: Node | None, owner: Node):
        srcs = self.sources(point)
        if not srcs:
            self.error(
                owner,
                f"{owner.tag} {owner.attrib.get('localId', '')} is not connected on its left side",
            )
            return TRUE
        return _or([self.power_out(ref, formal, owner) for ref, formal in srcs])

    def power_out(self, ref: str, formal: str, user: Node):
        key = (ref, formal.upper())
        if key in self.memo:
            return self.memo[key]
        node = self.nodes.get(ref)
        if node is None:
            self.error(user, f"connection to unknown localId {ref!r}")
            return TRUE
        if key in self.visiting:
            self.error(node, f"feedback loop through {node.tag} {ref}")
            return TRUE
        self.visiting.add(key)
        try:
            result = self._power_out(node, formal.upper())
        finally:
            self.visiting.discard(key)
        self.memo[key] = result
        return result

    def _power_out(self, node: Node, formal: str):
        t = node.tag
        if t == "leftPowerRail":
            return TRUE
        if t == "contact":
            var = self.var_text(node)
            edge = node.attrib.get("edge", "none")
            negated = node.attrib.get("negated", "false") == "true"
            if edge in ("rising", "falling"):
                pulse = self.edge_helper(node, var, edge)
                cond = ("leaf", self.instr("XIC", [pulse], node))
            else:
                cond = ("leaf", self.instr("XIO" if negated else "XIC", [var], node))
            return _and([self.power_in(node.find("connectionPointIn"), node), cond])
        if t == "coil":
            return self.power_in(node.find("connectionPointIn"), node)
        if t == "block":
            type_name = node.attrib.get("typeName", "").upper()
            inst = node.attrib.get("instanceName", "")
            if type_name in ("TON", "TOF", "CTU") and formal == "Q":
                return ("leaf", self.instr("XIC", [f"{inst}.DN"], node))
            self.error(node, f"block output {formal or '?'} of {type_name} cannot drive power flow")
            return TRUE
        if t in ("inVariable", "inOutVariable"):
            text = self.expr_text(node)
            negated = node.attrib.get("negated", "false") == "true"
            return ("leaf", self.instr("XIO" if negated else "XIC", [text], node))
        self.error(node, f"unsupported element {t!r} in the power flow")
        return TRUE

    def var_text(self, node: Node) -> str:
        v = node.find("variable")
        text = v.all_text().strip() if v is not None else ""
        if not text:
            self.error(node, f"{node.tag} {node.attrib.get('localId', '')} names no variable")
            return "_missing"
        return text

    def expr_text(self, node: Node) -> str:
        e = node.find("expression")
        text = e.all_text().strip() if e is not None else ""
        if not text:
            self.error(node, f"{node.tag} {node.attrib.get('localId', '')} has no expression")
            return "0"
        return text

    def value_in(self, block: Node, formal: str, required: bool = True) -> Operand | None:
        srcs = self.sources(self.block_input(block, formal))
        if not srcs:
            if required:
                self.error(
                    block, f"input {formal} of {block.attrib.get('typeName')} is not connected"
                )
            return None
        ref, _ = srcs[0]
        src = self.nodes.get(ref)
        if src is None or src.tag not in ("inVariable", "inOutVariable"):
            self.error(block, f"input {formal} must come from a variable or constant")
            return None
        return self.op(self.expr_text(src), src)

    def edge_helper(self, node: Node, var: str, edge: str) -> str:
        lid = node.attrib.get("localId", "0")
        pulse, store = f"_E{lid}", f"_E{lid}_S"
        for name in (pulse, store):
            if name.upper() not in self.declared:
                self.program.tags.append(
                    TagDecl(
                        name,
                        "BOOL",
                        node.line,
                        node.col,
                        comment=f"{edge} edge of {var} (imported)",
                    )
                )
                self.declared.add(name.upper())
        first = self.instr("XIC" if edge == "rising" else "XIO", [var], node)
        self.edge_rungs.append(
            (
                [first, self.instr("ONS", [store], node)],
                self.instr("OTE", [pulse], node),
                f"{edge} edge of {var}",
            )
        )
        return pulse

    # -- rungs ------------------------------------------------------------------------------
    def elements(self, expr) -> list[Element]:
        if expr == TRUE:
            return []
        if expr[0] == "leaf":
            return [expr[1]]
        if expr[0] == "and":
            out: list[Element] = []
            for p in expr[1]:
                out.extend(self.elements(p))
            return out
        legs = [self.elements(p) for p in expr[1]]
        first = legs[0][0]
        return [Branch(legs, first.line, first.col)]

    def sinks(self, ld: Node) -> list[tuple[Node, list[Element], list[tuple[str, int]]]]:
        """Each coil / block / outVariable with the rung elements it makes."""
        out = []
        for node in ld.children:
            t = node.tag
            if t == "coil":
                out.append((node, self.coil(node)))
            elif t == "block":
                out.append((node, self.block(node)))
            elif t == "outVariable":
                out.append((node, self.out_variable(node)))
            elif t not in (
                "leftPowerRail",
                "rightPowerRail",
                "contact",
                "inVariable",
                "inOutVariable",
                "comment",
            ):
                self.error(node, f"unsupported LD element {t!r}")
        return [(n, rungs, []) for n, rungs in out if rungs is not None]

    def coil(self, node: Node) -> list[list[Element]]:
        var = self.var_text(node)
        power = self.power_in(node.find("connectionPointIn"), node)
        storage = node.attrib.get("storage", "none")
        edge = node.attrib.get("edge", "none")
        negated = node.attrib.get("negated", "false") == "true"
        lid = node.attrib.get("localId", "0")
        if edge in ("rising", "falling"):
            store = f"_E{lid}_S"
            if store.upper() not in self.declared:
                self.program.tags.append(
                    TagDecl(
                        store,
                        "BOOL",
                        node.line,
                        node.col,
                        comment=f"{edge} edge coil {var} (imported)",
                    )
                )
                self.declared.add(store.upper())
            out = self.instr("OSR" if edge == "rising" else "OSF", [store, var], node)
        elif storage == "set":
            out = self.instr("OTL", [var], node)
        elif storage == "reset":
            out = self.instr("OTU", [var], node)
        else:
            out = self.instr("OTN" if negated else "OTE", [var], node)
        return [[*self.elements(power), out]]

    def block(self, node: Node) -> list[list[Element]] | None:
        type_name = node.attrib.get("typeName", "").upper()
        inst = node.attrib.get("instanceName", "")
        if type_name not in ("TON", "TOF", "CTU"):
            self.error(node, f"unsupported block {type_name!r} (TON, TOF and CTU are imported)")
            return None
        if not inst:
            self.error(node, f"{type_name} block without instanceName")
            return None
        if type_name in ("TON", "TOF"):
            power = self.power_in(self.block_input(node, "IN"), node)
            preset = self.value_in(node, "PT")
            if preset is None:
                return None
            return [[*self.elements(power), self.instr(type_name, [inst, preset], node)]]
        rungs: list[list[Element]] = []
        reset_point = self.block_input(node, "R")
        if self.sources(reset_point):
            reset = self.power_in(reset_point, node)
            rungs.append([*self.elements(reset), self.instr("RES", [inst], node)])
        power = self.power_in(self.block_input(node, "CU"), node)
        pv = self.value_in(node, "PV")
        if pv is None:
            return None
        rungs.append([*self.elements(power), self.instr("CTU", [inst, pv], node)])
        return rungs

    def out_variable(self, node: Node) -> list[list[Element]] | None:
        srcs = self.sources(node.find("connectionPointIn"))
        target = self.expr_text(node)
        if len(srcs) != 1:
            self.error(node, "outVariable needs exactly one connection")
            return None
        ref, formal = srcs[0]
        src = self.nodes.get(ref)
        if src is not None and src.tag == "block" and formal.upper() in ("ET", "CV"):
            inst = src.attrib.get("instanceName", "")
            return [[self.instr("MOV", [f"{inst}.ACC", target], node)]]
        power = self.power_in(node.find("connectionPointIn"), node)
        return [[*self.elements(power), self.instr("OTE", [target], node)]]

    def run(self, pou_name: str | None) -> Program:
        pous = list(self.root.iter("pou"))
        chosen = None
        for pou in pous:
            body = pou.find("body")
            if body is None or body.find("LD") is None:
                continue
            if (
                pou_name is None
                and pou.attrib.get("pouType") == "program"
                or (pou_name is not None and pou.attrib.get("name") == pou_name)
            ):
                chosen = pou
                break
        if chosen is None:
            what = f"POU {pou_name!r}" if pou_name else "program POU"
            self.sink.error(self.root.line, self.root.col, f"no {what} with an LD body in the file")
            return self.program
        self.program.name = chosen.attrib.get("name", "main")
        self.variables(chosen)
        ld = chosen.find("body").find("LD")  # type: ignore[union-attr]
        for node in ld.children:
            lid = node.attrib.get("localId")
            if lid is not None:
                if lid in self.nodes:
                    self.error(node, f"duplicate localId {lid}")
                self.nodes[lid] = node
        made = self.sinks(ld)
        ordered = sorted(made, key=lambda s: _order_key(s[0]))
        # blocks first when a later-placed rung reads their output: stable topological order
        rungs_in_order: list[tuple[Node, list[Element]]] = []
        for node, rungs, _ in ordered:
            for elements in rungs:
                rungs_in_order.append((node, elements))
        instances = {
            n.attrib.get("instanceName", "").upper(): i
            for i, (n, _) in enumerate(rungs_in_order)
            if n.tag == "block"
        }
        rungs_in_order = _blocks_before_readers(rungs_in_order, instances)
        number = 0
        for elements, out, comment in self.edge_rungs:
            self.program.rungs.append(Rung(number, [*elements, out], out.line, out.col, comment))
            number += 1
        for node, elements in rungs_in_order:
            comment = f"{node.tag} {node.attrib.get('localId', '')}"
            self.program.rungs.append(Rung(number, elements, node.line, node.col, comment))
            number += 1
        return self.program


def _order_key(node: Node) -> tuple[int, int, int]:
    order = int(node.attrib.get("executionOrderId", "0") or 0)
    pos = node.find("position")
    x = int(float(pos.attrib.get("x", "0"))) if pos is not None else 0
    y = int(float(pos.attrib.get("y", "0"))) if pos is not None else 0
    return (order, y, x)


def _reads(elements: list[Element]) -> set[str]:
    names: set[str] = set()
    for el in elements:
        if isinstance(el, Branch):
            for leg in el.legs:
                names |= _reads(leg)
        else:
            for op in el.operands:
                if "." in op.text:
                    names.add(op.text.split(".")[0].upper())
    return names


def _blocks_before_readers(rungs, instances):
    """Move each block rung before the first rung that reads its instance (same scan)."""
    result = list(rungs)
    for name in instances:
        block_idx = next(
            (
                i
                for i, (n, _) in enumerate(result)
                if n.tag == "block" and n.attrib.get("instanceName", "").upper() == name
            ),
            None,
        )
        if block_idx is None:
            continue
        reader = next(
            (
                i
                for i, (n, el) in enumerate(result)
                if i < block_idx and n.tag != "block" and name in _reads(el)
            ),
            None,
        )
        if reader is not None:
            item = result.pop(block_idx)
            result.insert(reader, item)
    return result


def import_plcopen(
    source: str | bytes, file: str | None = None, pou: str | None = None
) -> tuple[Program, DiagnosticSink]:
    """Import a TC6 XML project (a path, or the XML text itself) -> (Program, diagnostics)."""
    if isinstance(source, bytes):
        data, name = source, file or "<plcopen>"
    elif source.lstrip().startswith("<"):
        data, name = source.encode(), file or "<plcopen>"
    else:
        with open(source, "rb") as f:
            data = f.read()
        name = file or os.fspath(source)
    sink = DiagnosticSink(name)
    try:
        root = _parse_xml(data)
    except xml.parsers.expat.ExpatError as exc:
        sink.error(
            exc.lineno, exc.offset + 1, f"malformed XML: {xml.parsers.expat.ErrorString(exc.code)}"
        )
        return Program("main", name), sink
    if root.tag != "project":
        sink.error(root.line, root.col, f"not a PLCopen TC6 project (root element {root.tag!r})")
        return Program("main", name), sink
    program = _Importer(root, name, sink).run(pou)
    return program, sink
