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
from plc.ladder.plcopen_functions import (
    FUNCTION_BLOCKS,
    STANDARD_FUNCTIONS,
    FunctionSpec,
    formal_inputs,
    supported_blocks_text,
)

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
_VAR_SECTIONS = {
    "localVars",
    "inputVars",
    "outputVars",
    "inOutVars",
    "globalVars",
    "tempVars",
    "externalVars",
}


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
        self.global_names: set[str] = set()
        self.unsupported: dict[str, str] = {}  # upper-case name -> IEC type left out
        self.types: dict[str, str] = {}  # upper-case name -> tag type

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
            pass
        if text.startswith("'") or text.startswith('"'):
            self.error(
                node, f"string literal {text} needs a STRING, which the ladder runtime lacks"
            )
        elif text.split(".")[0].upper() in self.unsupported:
            kind = self.unsupported[text.split(".")[0].upper()]
            self.error(
                node,
                f"{text!r} is a {kind} variable, which the ladder runtime does not support "
                "(BOOL, the integer types, TIME, TON, TOF, CTU)",
            )
        return Operand("tag", text, node.line, node.col)

    def instr(self, mnemonic: str, operands: list[str | Operand], node: Node) -> Instr:
        ops = [o if isinstance(o, Operand) else self.op(o, node) for o in operands]
        return Instr(mnemonic, ops, node.line, node.col)

    # -- variables -------------------------------------------------------------------------
    def variables(self, pou: Node) -> None:
        # The configuration's globals first: an `externalVars` entry of the POU names one of
        # them (same variable, declared once with the global's address and initial value).
        globals_: list[Node] = []
        for conf in self.root.iter("configuration"):
            globals_ += conf.findall("globalVars")
            for res in conf.findall("resource"):
                globals_ += res.findall("globalVars")
        for section in globals_:
            for var in section.findall("variable"):
                self.variable(var, _retained(section))
        self.global_names = set(self.declared)
        iface = pou.find("interface")
        sections = (
            [c for c in iface.children if c.tag in _VAR_SECTIONS] if iface is not None else []
        )
        for section in sections:
            for var in section.findall("variable"):
                self.variable(var, _retained(section), external=section.tag == "externalVars")

    def variable(self, var: Node, retain: bool, external: bool = False) -> None:
        name = var.attrib.get("name", "")
        if name.upper() in self.declared or name.upper() in self.unsupported:
            return  # an externalVar naming a global declared above
        type_node = var.find("type")
        kind = ""
        if type_node is not None and type_node.children:
            t = type_node.children[0]
            kind = t.attrib.get("name", "") if t.tag == "derived" else t.tag
        kind = kind.upper()
        tag_type = _TYPE_MAP.get(kind) or ("INT" if kind in _INT_TYPES else None)
        if tag_type is None:
            self.unsupported[name.upper()] = kind or "?"
            self.sink.warning(
                var.line,
                var.col,
                f"variable {name!r} of type {kind or '?'} is not "
                "supported by the ladder runtime and was left out",
            )
            return
        if external:
            # OpenPLC shares such a variable with code outside the program (an Arduino
            # sketch, another POU); with no global of that name in the file it is a tag of
            # this program, as in a project that declares it in the resource.
            self.sink.warning(
                var.line,
                var.col,
                f"external variable {name!r} has no global declaration in this file: "
                "declared as a tag of the program",
            )
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
        self.types[name.upper()] = tag_type

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
            return self.block_power(node, formal)
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
        """A value input: a constant or variable, a function's OUT, a timer's ET / counter's CV."""
        srcs = self.sources(self.block_input(block, formal))
        if not srcs:
            if required:
                self.error(
                    block, f"input {formal} of {block.attrib.get('typeName')} is not connected"
                )
            return None
        value = self.value_of(*srcs[0])
        if value is None:
            self.error(
                block, f"input {formal} must come from a variable, a constant or a value output"
            )
        return value

    def value_of(self, ref: str, formal: str) -> Operand | None:
        """The operand a value connection carries (None: it carries power flow, not a value)."""
        src = self.nodes.get(ref)
        if src is None:
            return None
        if src.tag in ("inVariable", "inOutVariable"):
            return self.op(self.expr_text(src), src)
        if src.tag == "block":
            type_name = src.attrib.get("typeName", "").upper()
            spec = STANDARD_FUNCTIONS.get(type_name)
            if spec is not None and spec.kind != "compare" and formal.upper() == "OUT":
                return Operand("tag", self.result_tag(src), src.line, src.col)
            if type_name in FUNCTION_BLOCKS and formal.upper() in ("ET", "CV"):
                inst = src.attrib.get("instanceName", "")
                return Operand("tag", f"{inst}.ACC", src.line, src.col)
        return None

    def carries_value(self, ref: str, formal: str) -> bool:
        """Whether a connection is data flow (an INT) rather than power flow (a BOOL)."""
        src = self.nodes.get(ref)
        if src is None:
            return False
        if src.tag == "block":
            return self.value_of(ref, formal) is not None
        if src.tag in ("inVariable", "inOutVariable"):
            srcs = self.sources(src.find("connectionPointIn"))
            if src.tag == "inOutVariable" and srcs:
                return self.carries_value(*srcs[0])
            text = self.expr_text(src)
            try:
                parse_int(text)
                return True
            except ValueError:
                return self.types.get(text.split(".")[0].upper()) == "INT"
        return False

    def assignment(self, node: Node, target: str) -> list[list[Element]] | None:
        """An outVariable / inOutVariable fed by a value: `MOV value target`, under the
        feeding function's ENO (OpenPLC assigns a function's OUT only when ENO is true)."""
        ref, formal = self.sources(node.find("connectionPointIn"))[0]
        value = self.value_of(ref, formal)
        if value is None:
            return None
        src = self.nodes[ref]
        enable = self.elements(self.enable(src)) if src.tag == "block" else []
        return [[*enable, self.instr("MOV", [value, target], node)]]

    def condition_in(self, block: Node, formal: str) -> tuple:
        """A BOOL input of a function (SEL's G): a variable, or whatever power flow feeds it."""
        point = self.block_input(block, formal)
        srcs = self.sources(point)
        if len(srcs) == 1:
            src = self.nodes.get(srcs[0][0])
            if src is not None and src.tag in ("inVariable", "inOutVariable"):
                text = self.expr_text(src)
                if text.upper() in ("TRUE", "FALSE"):
                    return TRUE if text.upper() == "TRUE" else ("leaf", self.never(src))
                return ("leaf", self.instr("XIC", [text], src))
        return self.power_in(point, block)

    def never(self, node: Node) -> Instr:
        """A condition that is always false (a FALSE constant on a BOOL input)."""
        return self.instr("NEQ", ["0", "0"], node)

    def enable(self, block: Node) -> tuple:
        """A function's EN: its power flow, or TRUE when EN is not wired (FBD style)."""
        point = self.block_input(block, "EN")
        return self.power_in(point, block) if self.sources(point) else TRUE

    def result_tag(self, block: Node) -> str:
        """The hidden INT tag a value function writes its OUT to."""
        lid = block.attrib.get("localId", "0")
        name = f"_F{lid}"
        if name.upper() not in self.declared:
            type_name = block.attrib.get("typeName", "").upper()
            self.program.tags.append(
                TagDecl(name, "INT", block.line, block.col, comment=f"OUT of {type_name} {lid}")
            )
            self.declared.add(name.upper())
        return name

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
            elif t == "outVariable" or (
                t == "inOutVariable" and self.sources(node.find("connectionPointIn"))
            ):
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

    def block_power(self, node: Node, formal: str):
        """The power flow out of a block's BOOL output."""
        type_name = node.attrib.get("typeName", "").upper()
        inst = node.attrib.get("instanceName", "")
        if type_name in FUNCTION_BLOCKS and formal == "Q":
            return ("leaf", self.instr("XIC", [f"{inst}.DN"], node))
        if formal == "ENO" and (type_name in FUNCTION_BLOCKS or type_name in STANDARD_FUNCTIONS):
            return self.enable(node)
        spec = STANDARD_FUNCTIONS.get(type_name)
        if spec is not None and spec.kind == "compare" and formal == "OUT":
            return _and([self.enable(node), *self.comparison(node, spec)])
        self.error(node, f"block output {formal or '?'} of {type_name} cannot drive power flow")
        return TRUE

    def wired_inputs(self, node: Node) -> list[str]:
        iv = node.find("inputVariables")
        if iv is None:
            return []
        return [
            v.attrib.get("formalParameter", "").upper()
            for v in iv.findall("variable")
            if self.sources(v.find("connectionPointIn"))
        ]

    def call_inputs(self, node: Node, spec: FunctionSpec) -> list[Operand] | None:
        formals = formal_inputs(spec, self.wired_inputs(node))
        # SEL's G is a BOOL condition (condition_in), not a value
        values = [self.value_in(node, f) for f in formals if f != "G"]
        if any(v is None for v in values):
            return None
        return values  # type: ignore[return-value]

    def comparison(self, node: Node, spec: FunctionSpec) -> list[tuple]:
        values = self.call_inputs(node, spec)
        if values is None:
            return []
        if len(values) < 2:
            self.error(node, f"{spec.name} needs at least two inputs, got {len(values)}")
            return []
        return [
            ("leaf", self.instr(spec.mnemonic, [a, b], node))
            for a, b in zip(values, values[1:], strict=False)
        ]

    def block(self, node: Node) -> list[list[Element]] | None:
        type_name = node.attrib.get("typeName", "").upper()
        inst = node.attrib.get("instanceName", "")
        spec = STANDARD_FUNCTIONS.get(type_name)
        if spec is not None:
            return self.function(node, spec)
        if type_name not in FUNCTION_BLOCKS:
            self.error(
                node,
                f"unsupported block {type_name!r} (the import knows the {supported_blocks_text()}"
                "; other blocks belong to a target's or vendor's library)",
            )
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
        # IEC CTU: R has priority over CU, and CU counts on its own rising edge (its edge
        # memory is not touched by R). A ladder CTU counts on the rising of its whole rung
        # and RES clears that memory, so CU's edge and R are made helper bits first:
        # `<CU> ONS _C<id>_S OTE _C<id>`, `<R> OTE _R<id>`, `XIC _R<id> RES inst`,
        # `XIC _C<id> XIO _R<id> CTU inst PV`.
        pv = self.value_in(node, "PV")
        if pv is None:
            return None
        lid = node.attrib.get("localId", "0")
        pulse, store, reset_bit = f"_C{lid}", f"_C{lid}_S", f"_R{lid}"
        power = self.power_in(self.block_input(node, "CU"), node)
        rungs: list[list[Element]] = []
        count = [self.instr("XIC", [pulse], node)]
        reset_point = self.block_input(node, "R")
        if self.sources(reset_point):
            self.helper_bit(node, reset_bit, f"R of {inst} (imported)")
            reset = self.power_in(reset_point, node)
            rungs.append([*self.elements(reset), self.instr("OTE", [reset_bit], node)])
            rungs.append([self.instr("XIC", [reset_bit], node), self.instr("RES", [inst], node)])
            count.append(self.instr("XIO", [reset_bit], node))
        self.helper_bit(node, pulse, f"rising edge of CU of {inst} (imported)")
        self.helper_bit(node, store, f"CU of {inst} last scan (imported)")
        cu_edge = [self.instr("ONS", [store], node), self.instr("OTE", [pulse], node)]
        rungs.append([*self.elements(power), *cu_edge])
        rungs.append([*count, self.instr("CTU", [inst, pv], node)])
        return rungs

    def helper_bit(self, node: Node, name: str, comment: str) -> None:
        if name.upper() not in self.declared:
            self.program.tags.append(TagDecl(name, "BOOL", node.line, node.col, comment=comment))
            self.declared.add(name.upper())

    def function(self, node: Node, spec: FunctionSpec) -> list[list[Element]] | None:
        """The rungs that compute a value function's OUT into its hidden tag (none for a
        comparison, which is evaluated inline where its OUT is used)."""
        if spec.kind == "compare":
            if not self.feeds_anything(node):
                self.sink.warning(node.line, node.col, f"the OUT of {spec.name} is not connected")
            return []
        values = self.call_inputs(node, spec)
        if values is None:
            return None
        en = self.elements(self.enable(node))
        out = self.result_tag(node)

        def rung(*instrs: Instr, cond: tuple = TRUE) -> list[Element]:
            return [*en, *self.elements(cond), *instrs]

        def ins(mnemonic: str, *ops: Operand | str) -> Instr:
            return self.instr(mnemonic, list(ops), node)

        if spec.kind == "move":
            return [rung(ins("MOV", values[0], out))]
        if spec.kind == "arith":
            if len(values) < 2:
                self.error(node, f"{spec.name} needs at least two inputs, got {len(values)}")
                return None
            rungs = [rung(ins(spec.mnemonic, values[0], values[1], out))]
            rungs += [rung(ins(spec.mnemonic, out, v, out)) for v in values[2:]]
            return rungs
        if spec.name == "SEL":
            g = self.condition_in(node, "G")
            return [rung(ins("MOV", values[0], out)), rung(ins("MOV", values[1], out), cond=g)]
        if spec.name in ("MAX", "MIN"):
            if not values:
                self.error(node, f"{spec.name} needs at least one input")
                return None
            rungs = [rung(ins("MOV", values[0], out))]
            for v in values[1:]:
                rungs.append(rung(ins(spec.mnemonic, v, out), ins("MOV", v, out)))
            return rungs
        if spec.name == "LIMIT":
            mn, value, mx = values
            return [
                rung(ins("MOV", value, out)),
                rung(ins("LES", out, mn), ins("MOV", mn, out)),
                rung(ins("GRT", out, mx), ins("MOV", mx, out)),
            ]
        # MUX: OUT = IN<K>; a K with no input leaves OUT as it was (IEC calls it an error)
        k, inputs = values[0], values[1:]
        return [rung(ins("EQU", k, str(i)), ins("MOV", v, out)) for i, v in enumerate(inputs)]

    def feeds_anything(self, node: Node) -> bool:
        lid = node.attrib.get("localId")
        return any(
            c.attrib.get("refLocalId") == lid
            for other in self.nodes.values()
            for c in other.iter("connection")
        )

    def out_variable(self, node: Node) -> list[list[Element]] | None:
        """An outVariable, or an inOutVariable wired on its input side: an assignment of a
        value, or a coil-like `OTE` of the power flow."""
        srcs = self.sources(node.find("connectionPointIn"))
        target = self.expr_text(node)
        if len(srcs) != 1:
            self.error(node, f"{node.tag} needs exactly one connection")
            return None
        if self.carries_value(*srcs[0]):
            return self.assignment(node, target)
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
            self.sink.error(
                self.root.line,
                self.root.col,
                f"no {what} with an LD body in the file{_languages(pous)}",
            )
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
        groups = _producers_before_readers([(node, rungs) for node, rungs, _ in ordered])
        rungs_in_order = [(node, elements) for node, rungs in groups for elements in rungs]
        number = 0
        for elements, out, comment in self.edge_rungs:
            self.program.rungs.append(Rung(number, [*elements, out], out.line, out.col, comment))
            number += 1
        for node, elements in rungs_in_order:
            comment = f"{node.tag} {node.attrib.get('localId', '')}"
            self.program.rungs.append(Rung(number, elements, node.line, node.col, comment))
            number += 1
        return self.program


def _languages(pous: list[Node]) -> str:
    """What the file's POUs are written in, for the 'no LD program' error."""
    seen = []
    for pou in pous:
        body = pou.find("body")
        lang = body.children[0].tag if body is not None and body.children else "no body"
        seen.append(f"{pou.attrib.get('pouType', '?')} {pou.attrib.get('name', '?')!r}: {lang}")
    return " (only LD bodies are imported; " + "; ".join(seen) + ")" if seen else ""


def _retained(section: Node) -> bool:
    return section.attrib.get("retain") == "true" or section.attrib.get("persistent") == "true"


def _order_key(node: Node) -> tuple[int, int, int]:
    order = int(node.attrib.get("executionOrderId", "0") or 0)
    pos = node.find("position")
    x = int(float(pos.attrib.get("x", "0"))) if pos is not None else 0
    y = int(float(pos.attrib.get("y", "0"))) if pos is not None else 0
    return (order, y, x)


def _reads(elements: list[Element]) -> set[str]:
    """Upper-case tag names (timer/counter instances without their member) a rung reads."""
    names: set[str] = set()
    for el in elements:
        if isinstance(el, Branch):
            for leg in el.legs:
                names |= _reads(leg)
        else:
            for op in el.operands:
                if op.kind == "tag":
                    names.add(op.text.split(".")[0].upper())
    return names


def _produces(node: Node) -> str | None:
    """What a sink makes that others read in the same scan: a function block's instance,
    a value function's hidden `_F<localId>`, an inOutVariable's variable."""
    if node.tag == "inOutVariable":
        e = node.find("expression")
        return e.all_text().strip().upper() if e is not None else None
    if node.tag != "block":
        return None
    type_name = node.attrib.get("typeName", "").upper()
    if type_name in FUNCTION_BLOCKS:
        return node.attrib.get("instanceName", "").upper() or None
    spec = STANDARD_FUNCTIONS.get(type_name)
    if spec is not None and spec.kind != "compare":
        return f"_F{node.attrib.get('localId', '0')}".upper()
    return None


def _producers_before_readers(groups):
    """Each block's rungs before the first rungs that read its outputs, the rest in drawing
    order. A block reading a variable that an inOutVariable assigns sees its value from
    before the assignment: that variable is the loop's feedback variable (IEC 61131-3 FBD),
    so `Cnt := SEL(Reset, ADD(1, Cnt), Init)` adds to the last scan's count. Any other
    loop keeps drawing order."""
    producer = {}
    for i, (node, _) in enumerate(groups):
        name = _produces(node)
        if name:
            producer[name] = i
    reads = [set().union(*(_reads(r) for r in rungs)) if rungs else set() for _, rungs in groups]
    done: set[int] = set()
    on_path: set[int] = set()
    result = []

    def visit(i: int) -> None:
        if i in done or i in on_path:
            return
        on_path.add(i)
        reader_is_block = groups[i][0].tag == "block"
        for name in sorted(reads[i], key=lambda n: producer.get(n, -1)):
            j = producer.get(name)
            if j is None or j == i:
                continue
            if reader_is_block and groups[j][0].tag == "inOutVariable":
                continue  # the feedback variable
            visit(j)
        on_path.discard(i)
        done.add(i)
        result.append(groups[i])

    for i in range(len(groups)):
        visit(i)
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
