"""Semantic check: resolve every operand against the tag table and the image, type-check it,
and check labels, jumps, rung shape, duplicate outputs and the estimated scan time.

The result (`Resolved`) is what the code generator consumes: every operand is already a
`Ref` naming a Python expression (`ix[3]`, `v[17]`, `42`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from plc.image import INT_MAX, INT_MIN, ImageSize
from plc.ladder.ast import Branch, Element, Instr, Operand, Program, Rung
from plc.ladder.diagnostics import DiagnosticSink
from plc.ladder.instructions import (
    COUNTER_MEMBERS,
    INSTRUCTIONS,
    MEMBER_ALIASES,
    TIMER_MEMBERS,
    InstrSpec,
)
from plc.ladder.symbols import (
    Location,
    Symbol,
    SymbolTable,
    format_address,
    new_table,
    parse_address,
)

PRESET_MAX = 2**31 - 1
RUNG_COST_NS = 100


@dataclass(frozen=True, slots=True)
class Ref:
    """A resolved operand: `expr` is the Python expression the generated code uses."""

    kind: str  # bit, word, timer, counter, label, const
    expr: str
    key: str = ""  # canonical identity for duplicate-output checks
    symbol: Symbol | None = None
    value: int | None = None


@dataclass(slots=True)
class RInstr:
    spec: InstrSpec
    refs: list[Ref]
    src: Instr


@dataclass(slots=True)
class RBranch:
    legs: list[list[RElement]]
    src: Branch


RElement = RInstr | RBranch


@dataclass(slots=True)
class RRung:
    number: int
    line: int
    elements: list[RElement]
    label: str | None = None
    jumps: list[str] = field(default_factory=list)
    text: str = ""


@dataclass(slots=True)
class Resolved:
    program: Program
    table: SymbolTable
    rungs: list[RRung]
    labels: dict[str, int]  # label -> rung number
    estimate_us: float
    alarms: list[tuple[int, str, str, int]] = field(default_factory=list)  # no, text, area, idx


def _is_input_area(area: str) -> bool:
    return area in ("IX", "IW")


class _Checker:
    def __init__(self, program: Program, size: ImageSize, sink: DiagnosticSink) -> None:
        self.program = program
        self.size = size
        self.sink = sink
        self.table = new_table(size)
        self.address_owner: dict[tuple[str, int], str] = {}
        self._ref_cache: dict[tuple[str, str, str], Ref] = {}

    # -- tag table -------------------------------------------------------------------------
    def declare(self) -> None:
        for decl in self.program.tags:
            if self.table.lookup(decl.name) is not None:
                sym = self.table.lookup(decl.name)
                if sym is not None and sym.decl is None:
                    self.sink.error(decl.line, decl.col, f"{decl.name!r} is a system tag name")
                else:
                    prev = sym.decl.line if sym and sym.decl else 0
                    self.sink.error(
                        decl.line, decl.col, f"tag {decl.name!r} already declared on line {prev}"
                    )
                continue
            loc: Location | None = None
            if decl.address is not None:
                loc = self._tag_location(decl)
                if loc is None:
                    continue
            if decl.init is not None:
                ok = decl.init in (0, 1) if decl.type == "BOOL" else INT_MIN <= decl.init <= INT_MAX
                if decl.type in ("TIMER", "COUNTER"):
                    self.sink.error(decl.line, decl.col, f"{decl.type} tags take no initial value")
                    continue
                if not ok:
                    self.sink.error(
                        decl.line, decl.col, f"initial value {decl.init} does not fit {decl.type}"
                    )
                    continue
                if loc is not None:
                    self.sink.warning(
                        decl.line, decl.col, "initial value ignored on a located tag (AT ...)"
                    )
            self.table.add(decl, decl.name, decl.type, loc, decl.init)

    def _tag_location(self, decl) -> Location | None:
        a = decl.address
        parsed = self._address(a)
        if parsed is None:
            return None
        area, index = parsed
        if decl.type in ("TIMER", "COUNTER"):
            self.sink.error(a.line, a.col, f"{decl.type} tags cannot be located (AT)")
            return None
        want_bit = decl.type == "BOOL"
        if want_bit != area.endswith("X"):
            need = "a bit address (%IX/%QX/%MX)" if want_bit else "a word address (%IW/%QW/%MW)"
            self.sink.error(
                a.line, a.col, f"{decl.type} tag {decl.name!r} needs {need}, got {a.text}"
            )
            return None
        other = self.address_owner.get((area, index))
        if other is not None:
            self.sink.warning(a.line, a.col, f"{a.text} is also the address of tag {other!r}")
        self.address_owner[(area, index)] = decl.name
        return Location(area, index)

    def _address(self, op: Operand) -> tuple[str, int] | None:
        parsed = parse_address(op.text)
        if isinstance(parsed, str):
            self.sink.error(op.line, op.col, parsed)
            return None
        area, index = parsed
        limit = self.size.of(area)
        if index >= limit:
            unit = "bits" if area.endswith("X") else "words"
            self.sink.error(
                op.line, op.col, f"{op.text} is outside the image (%{area} has {limit} {unit})"
            )
            return None
        return area, index

    # -- operands ----------------------------------------------------------------------------
    def operand(self, op: Operand, kind: str, mnemonic: str) -> Ref | None:
        key = (op.kind, op.text.upper(), kind)
        hit = self._ref_cache.get(key)
        if hit is not None:
            return hit
        ref = self._operand(op, kind, mnemonic)
        if ref is not None:
            self._ref_cache[key] = ref
        return ref

    def _operand(self, op: Operand, kind: str, mnemonic: str) -> Ref | None:
        err = self.sink.error
        if kind == "label":
            if op.kind != "tag" or "." in op.text:
                err(op.line, op.col, f"{mnemonic} needs a label name, got {op.text!r}")
                return None
            return Ref("label", op.text.upper(), op.text.upper())
        if op.kind in ("int", "time"):
            assert op.value is not None
            if kind == "preset":
                if not 0 <= op.value <= PRESET_MAX:
                    err(op.line, op.col, f"preset {op.value} ms out of range 0..{PRESET_MAX}")
                    return None
                return Ref("const", str(op.value), value=op.value)
            if kind == "word":
                if not INT_MIN <= op.value <= INT_MAX:
                    err(
                        op.line,
                        op.col,
                        f"literal {op.value} does not fit INT ({INT_MIN}..{INT_MAX})",
                    )
                    return None
                return Ref("const", str(op.value), value=op.value)
            err(
                op.line,
                op.col,
                f"{mnemonic} needs {_describe(kind)} here, got the literal {op.text}",
            )
            return None
        if op.kind == "address":
            parsed = self._address(op)
            if parsed is None:
                return None
            area, index = parsed
            return self._check_scalar(op, kind, mnemonic, Location(area, index), op.text, None)
        # a tag, maybe with a member
        base, _, member = op.text.partition(".")
        sym = self.table.lookup(base)
        if sym is None:
            err(op.line, op.col, f"undeclared tag {base!r}")
            return None
        if member:
            return self._member(op, kind, mnemonic, sym, member.upper())
        if sym.type in ("TIMER", "COUNTER"):
            want = {"timer": "TIMER", "counter": "COUNTER"}.get(kind)
            if kind == "tc" or want == sym.type:
                return Ref(sym.type.lower(), sym.name, sym.name.upper(), sym)
            err(
                op.line,
                op.col,
                f"{mnemonic} needs {_describe(kind)} here, got {sym.type} tag {sym.name!r}"
                + (" (use a member such as .DN or .ACC)" if kind in ("bit", "word") else ""),
            )
            return None
        assert sym.location is not None
        return self._check_scalar(
            op, kind, mnemonic, sym.location, f"{sym.type} tag {sym.name!r}", sym
        )

    def _check_scalar(self, op, kind, mnemonic, loc: Location, what: str, sym) -> Ref | None:
        is_bit = loc.area.endswith("X") if loc.area != "V" else sym.type == "BOOL"
        key = format_address(loc.area, loc.index) if loc.area != "V" else sym.name.upper()
        if kind in ("timer", "counter", "tc"):
            self.sink.error(op.line, op.col, f"{mnemonic} needs {_describe(kind)} here, got {what}")
            return None
        want_bit = kind in ("bit", "bit_w")
        if want_bit != is_bit:
            self.sink.error(
                op.line,
                op.col,
                f"{mnemonic} needs {_describe(kind)} here, got {what}"
                + (
                    " (a bit where a word is needed)"
                    if is_bit
                    else " (a word where a bit is needed)"
                ),
            )
            return None
        if kind.endswith("_w") and _is_input_area(loc.area):
            self.sink.error(
                op.line,
                op.col,
                f"{mnemonic} cannot write the input {what}; inputs are written by the I/O scan only",
            )
            return None
        return Ref("bit" if is_bit else "word", loc.expr, key, sym)

    def _member(self, op, kind, mnemonic, sym: Symbol, member: str) -> Ref | None:
        table = (
            TIMER_MEMBERS
            if sym.type == "TIMER"
            else COUNTER_MEMBERS
            if sym.type == "COUNTER"
            else None
        )
        if table is None:
            self.sink.error(op.line, op.col, f"{sym.type} tag {sym.name!r} has no members")
            return None
        if member not in table:
            self.sink.error(
                op.line, op.col, f"{sym.type} has no member .{member} (members: {', '.join(table)})"
            )
            return None
        mkind = table[member]
        canon = MEMBER_ALIASES.get(member, member)
        expr = f"v[{sym.members[canon]}]"
        key = f"{sym.name.upper()}.{canon}"
        want_bit = kind in ("bit", "bit_w")
        if kind in ("timer", "counter", "tc", "label") or want_bit != (mkind == "bit"):
            self.sink.error(
                op.line,
                op.col,
                f"{mnemonic} needs {_describe(kind)} here, got the {mkind} member {op.text}",
            )
            return None
        if kind.endswith("_w") and canon != "ACC":
            self.sink.error(
                op.line,
                op.col,
                f"{op.text} is written by the {sym.type.lower()} instruction only"
                + (" (set the preset through the instruction's operand)" if canon == "PRE" else ""),
            )
            return None
        return Ref(mkind, expr, key, sym)

    # -- rungs -------------------------------------------------------------------------------
    def rungs(self) -> tuple[list[RRung], dict[str, int], float]:
        labels: dict[str, int] = {}
        label_at: dict[str, Instr] = {}
        out: list[RRung] = []
        cost_ns = 0.0
        for rung in self.program.rungs:
            rr = RRung(rung.number, rung.line, [])
            rr.elements = self.elements(rung.elements, rr, top=True, first=True) or []
            cost_ns += RUNG_COST_NS + _cost(rung.elements)
            self.shape(rung)
            if rr.label is not None:
                first = rung.elements[0]
                assert isinstance(first, Instr)
                if rr.label in labels:
                    prev = label_at[rr.label]
                    self.sink.error(
                        first.line,
                        first.operands[0].col,
                        f"label {rr.label} already defined on line {prev.line}",
                    )
                else:
                    labels[rr.label] = rung.number
                    label_at[rr.label] = first
            out.append(rr)
        return out, labels, cost_ns / 1000.0

    def elements(
        self, items: list[Element], rr: RRung, top: bool, first: bool
    ) -> list[RElement] | None:
        res: list[RElement] = []
        for pos, el in enumerate(items):
            if isinstance(el, Branch):
                legs = [self.elements(leg, rr, top=False, first=False) for leg in el.legs]
                res.append(RBranch([leg or [] for leg in legs], el))
                continue
            spec = INSTRUCTIONS[el.mnemonic]
            if el.mnemonic == "LBL":
                if not (top and first and pos == 0):
                    self.sink.error(
                        el.line, el.col, "LBL must be the first instruction of its rung"
                    )
                else:
                    rr.label = el.operands[0].text.upper()
            refs = [
                self.operand(op, kind, el.mnemonic)
                for op, kind in zip(el.operands, spec.operands, strict=True)
            ]
            if any(r is None for r in refs):
                continue
            if el.mnemonic == "JMP":
                rr.jumps.append(refs[0].expr)
            res.append(RInstr(spec, refs, el))
        return res

    def shape(self, rung: Rung) -> None:
        if not _has_output(rung.elements):
            self.sink.error(rung.line, rung.col, "rung has no output instruction")
            return
        last = rung.elements[-1]
        if isinstance(last, Instr) and INSTRUCTIONS[last.mnemonic].position == "input":
            self.sink.error(
                last.line,
                last.col,
                f"rung ends with the input instruction {last.mnemonic}; nothing uses its result",
            )


def _describe(kind: str) -> str:
    return {
        "bit": "a bit (BOOL tag, %IX/%QX/%MX, .DN member)",
        "bit_w": "a writable bit (BOOL tag, %QX/%MX)",
        "word": "a word (INT tag, %IW/%QW/%MW, .ACC member or INT literal)",
        "word_w": "a writable word (INT tag, %QW/%MW, .ACC member)",
        "preset": "a preset in ms (literal, T#.. or a word)",
        "timer": "a TIMER tag",
        "counter": "a COUNTER tag",
        "tc": "a TIMER or COUNTER tag",
        "label": "a label",
    }[kind]


def _has_output(items: list[Element]) -> bool:
    for el in items:
        if isinstance(el, Branch):
            if any(_has_output(leg) for leg in el.legs):
                return True
        elif INSTRUCTIONS[el.mnemonic].position == "output":
            return True
    return False


def _cost(items: list[Element]) -> float:
    total = 0.0
    for el in items:
        if isinstance(el, Branch):
            total += 80 + sum(_cost(leg) for leg in el.legs)
        else:
            total += INSTRUCTIONS[el.mnemonic].cost_ns
    return total


def _walk(items: list[RElement]):
    for el in items:
        if isinstance(el, RBranch):
            for leg in el.legs:
                yield from _walk(leg)
        else:
            yield el


def analyse(
    program: Program,
    sink: DiagnosticSink,
    size: ImageSize | None = None,
    watchdog_ms: float | None = None,
) -> Resolved:
    """Check `program`, adding diagnostics to `sink`; the result is valid only without errors."""
    checker = _Checker(program, size or ImageSize(), sink)
    checker.declare()
    rungs, labels, estimate_us = checker.rungs()
    # jumps: target must exist and lie after the jump (forward only keeps the scan bounded)
    for rr in rungs:
        for el in _walk(rr.elements):
            if el.spec.mnemonic != "JMP":
                continue
            label = el.refs[0].expr
            op = el.src.operands[0]
            target = labels.get(label)
            if target is None:
                sink.error(op.line, op.col, f"JMP to undefined label {label}")
            elif target <= rr.number:
                sink.error(
                    op.line,
                    op.col,
                    f"backward JMP to {label} (rung {target}) refused: only forward jumps "
                    "are allowed so that every scan stays bounded",
                )
    # duplicate outputs: the last rung wins, which is rarely what the author meant
    seen: dict[str, Instr] = {}
    timers: dict[str, Instr] = {}
    for rr in rungs:
        for el in _walk(rr.elements):
            m = el.spec.mnemonic
            if m in ("OTE", "OTN"):
                key = el.refs[0].key
                if key in seen:
                    first = seen[key]
                    op = el.src.operands[0]
                    sink.warning(
                        op.line,
                        op.col,
                        f"duplicate output: {op.text} is also written by {first.mnemonic} on line "
                        f"{first.line}; the later rung wins",
                    )
                else:
                    seen[key] = el.src
            elif m in ("TON", "TOF", "RTO", "CTU", "CTD"):
                key = el.refs[0].key
                if key in timers and not (m in ("CTU", "CTD") and timers[key].mnemonic != m):
                    op = el.src.operands[0]
                    sink.warning(
                        op.line,
                        op.col,
                        f"{op.text} is also driven by {timers[key].mnemonic} on line "
                        f"{timers[key].line}",
                    )
                else:
                    timers[key] = el.src
    if watchdog_ms is not None:
        est_ms = estimate_us / 1000.0
        where = (program.rungs[0].line, 1) if program.rungs else (1, 1)
        if est_ms > watchdog_ms:
            sink.error(
                *where,
                f"estimated scan time {est_ms:.3f} ms exceeds the watchdog "
                f"limit {watchdog_ms:g} ms",
            )
        elif est_ms > 0.5 * watchdog_ms:
            sink.warning(
                *where,
                f"estimated scan time {est_ms:.3f} ms is over half the watchdog "
                f"limit {watchdog_ms:g} ms",
            )
    alarms: list[tuple[int, str, str, int]] = []
    numbers: dict[int, int] = {}
    for a in program.alarms:
        if not 1 <= a.number <= 8999:
            sink.error(
                a.line,
                a.col,
                f"alarm number {a.number} outside 1..8999 (9000+ are the runtime's own)",
            )
            continue
        if a.number in numbers:
            sink.error(
                a.line, a.col, f"alarm {a.number} already declared on line {numbers[a.number]}"
            )
            continue
        numbers[a.number] = a.line
        ref = checker.operand(a.tag, "bit", "ALARM")
        if ref is None:
            continue
        area, _, rest = ref.expr.partition("[")
        alarms.append((a.number, a.text, area.upper(), int(rest.rstrip("]"))))
    return Resolved(program, checker.table, rungs, labels, estimate_us, alarms)
