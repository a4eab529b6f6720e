"""Code generator: the whole checked program becomes the source of ONE Python function.

    def _ladder_scan(ix, qx, mx, iw, qw, mw, v, dt):

The image areas and the slot list arrive as arguments, so inside the function they are fast
local variables; `dt` is the scan's time step in ms (virtual time: timers never read a clock).
Each rung is a short run of straight-line statements headed by a comment naming its number
and source line. Power flow is a Python boolean expression while it stays pure and becomes a
temporary (`p1`, `p2` ...) only when something with a side effect needs it twice.
Forward jumps become `if not (j0 or j1):` guards around the skipped rungs.
"""

from __future__ import annotations

import re

from plc.ladder.analysis import RBranch, RElement, Resolved, RInstr, RRung
from plc.ladder.ast import format_elements
from plc.ladder.symbols import SLOT_DIV_ZERO, SLOT_FAULT_RUNG, SLOT_OVERFLOW

FUNC_NAME = "_ladder_scan"
_SIMPLE = re.compile(r"^(True|[a-z_][a-z0-9_]*)$")
_COMPARE = {"EQU": "==", "NEQ": "!=", "LES": "<", "LEQ": "<=", "GRT": ">", "GEQ": ">="}
_ARITH = {"ADD": "+", "SUB": "-", "MUL": "*"}


def _tdiv(a: int, b: int) -> int:
    """IEC integer division truncates toward zero (Python's // floors)."""
    q = abs(a) // abs(b)
    return q if (a < 0) == (b < 0) else -q


def _tmod(a: int, b: int) -> int:
    """IEC MOD: the remainder takes the sign of the dividend."""
    return a - b * _tdiv(a, b)


def _lim(low: int, test: int, high: int) -> bool:
    """Rockwell LIM: inside [low, high]; when low > high, outside the open range (high, low)."""
    if low <= high:
        return low <= test <= high
    return test >= low or test <= high


RUNTIME_GLOBALS = {"_tdiv": _tdiv, "_tmod": _tmod, "_lim": _lim}


class _RungGen:
    """Emits the statements of one rung as (indent, text) pairs."""

    def __init__(
        self, rung: RRung, jump_ids: dict[tuple[int, int], str], fixed_presets: set[int]
    ) -> None:
        self.rung = rung
        self.fixed_presets = fixed_presets
        self.out: list[tuple[int, str]] = []
        self.n = 0
        self.jump_ids = jump_ids
        self.jmp_seq = 0

    def emit(self, text: str, indent: int = 0) -> None:
        self.out.append((indent, text))

    def tmp(self) -> str:
        self.n += 1
        return f"p{self.n}"

    def mat(self, power: str) -> str:
        if _SIMPLE.match(power):
            return power
        name = self.tmp()
        self.emit(f"{name} = {power}")
        return name

    def seq(self, items: list[RElement], power: str, top: bool) -> str:
        for i, el in enumerate(items):
            last = top and i == len(items) - 1
            if isinstance(el, RBranch):
                pw = self.mat(power) if len(el.legs) > 1 else power
                legs = [self.seq(leg, pw, top=False) for leg in el.legs]
                if "True" in legs:
                    power = "True"
                else:
                    power = "(" + " or ".join(legs) + ")"
                continue
            if el.spec.position == "input":
                power = self.input(el, power)
            else:
                power = self.output(el, power if last else self.mat(power))
        return power

    def input(self, el: RInstr, power: str) -> str:
        m = el.spec.mnemonic
        r = [ref.expr for ref in el.refs]
        if m == "LBL":
            return power
        if m == "ONS":
            pw = self.mat(power)
            out = self.tmp()
            self.emit(f"{out} = not {r[0]}" if pw == "True" else f"{out} = {pw} and not {r[0]}")
            self.emit(f"{r[0]} = {pw}")
            return out
        if m == "XIC":
            cond = r[0]
        elif m == "XIO":
            cond = f"not {r[0]}"
        elif m in _COMPARE:
            cond = f"{r[0]} {_COMPARE[m]} {r[1]}"
        else:  # LIM
            low, test, high = el.refs
            if low.value is not None and high.value is not None:
                if low.value <= high.value:
                    cond = f"{low.expr} <= {test.expr} <= {high.expr}"
                else:
                    cond = f"({test.expr} >= {low.expr} or {test.expr} <= {high.expr})"
            else:
                cond = f"_lim({low.expr}, {test.expr}, {high.expr})"
        return cond if power == "True" else f"{power} and {cond}"

    def guarded(self, power: str, lines: list[str]) -> None:
        if power == "True":
            for line in lines:
                self.emit(line)
            return
        self.emit(f"if {power}:")
        for line in lines:
            self.emit(line, 1)

    def output(self, el: RInstr, power: str) -> str:
        m = el.spec.mnemonic
        refs = el.refs
        r = [ref.expr for ref in refs]
        if m == "OTE":
            self.emit(f"{r[0]} = {power}")
        elif m == "OTN":
            self.emit(f"{r[0]} = not ({power})" if " " in power else f"{r[0]} = not {power}")
        elif m == "OTL":
            self.guarded(power, [f"{r[0]} = True"])
        elif m == "OTU":
            self.guarded(power, [f"{r[0]} = False"])
        elif m in ("OSR", "OSF"):
            pw = self.mat(power)
            store, bit = r
            if m == "OSR":
                expr = f"not {store}" if pw == "True" else f"{pw} and not {store}"
            else:
                expr = "False" if pw == "True" else f"{store} and not {pw}"
            self.emit(f"{bit} = {expr}")
            self.emit(f"{store} = {pw}")
        elif m in ("TON", "TOF", "RTO"):
            self.timer(m, refs, power)
        elif m in ("CTU", "CTD"):
            self.counter(m, refs, power)
        elif m == "RES":
            sym = refs[0].symbol
            assert sym is not None
            s = sym.members
            if sym.type == "TIMER":
                body = [f"v[{s['ACC']}] = 0", f"v[{s['EN']}] = v[{s['TT']}] = v[{s['DN']}] = False"]
            else:
                body = [
                    f"v[{s['ACC']}] = 0",
                    f"v[{s['CU']}] = v[{s['CD']}] = v[{s['DN']}] = v[{s['OV']}] = v[{s['UN']}] = False",
                ]
            self.guarded(power, body)
        elif m in _ARITH:
            self.guarded(power, [f"_r = {r[0]} {_ARITH[m]} {r[1]}", *_wrap_lines(), f"{r[2]} = _r"])
        elif m in ("DIV", "MOD"):
            fn = "_tdiv" if m == "DIV" else "_tmod"
            body = [
                f"_b = {r[1]}",
                "if _b == 0:",
                f"    v[{SLOT_DIV_ZERO}] = True",
                f"    v[{SLOT_FAULT_RUNG}] = {self.rung.number}",
                "else:",
                f"    _r = {fn}({r[0]}, _b)",
            ]
            if m == "DIV":
                body += ["    " + w for w in _wrap_lines()]
            body.append(f"    {r[2]} = _r")
            self.guarded(power, body)
        elif m == "MOV":
            src = refs[0]
            if src.symbol is not None and src.symbol.type == "TIMER":
                self.guarded(power, [f"_r = {src.expr}", *_wrap_lines(), f"{r[1]} = _r"])
            else:
                self.guarded(power, [f"{r[1]} = {src.expr}"])
        elif m == "JMP":
            name = self.jump_ids[(self.rung.number, self.jmp_seq)]
            self.jmp_seq += 1
            self.emit(f"{name} = {power}")
        else:  # pragma: no cover - the instruction table and this generator must agree
            raise AssertionError(f"no code generator for {m}")
        return power

    def timer(self, m: str, refs, power: str) -> None:
        sym = refs[0].symbol
        assert sym is not None
        s = {k: f"v[{i}]" for k, i in sym.members.items()}
        pre = refs[1]
        if sym.members["PRE"] in self.fixed_presets:
            pass  # constant preset: set once in the initial slot values
        elif pre.value is not None:
            self.emit(f"{s['PRE']} = {pre.value}")
        else:
            self.emit(f"_p = {pre.expr}")
            self.emit(f"{s['PRE']} = _p if _p > 0 else 0")
        accumulate = [
            f"if {s['EN']} and {s['ACC']} < {s['PRE']}:",
            f"    _a = {s['ACC']} + dt",
            f"    {s['ACC']} = _a if _a < {s['PRE']} else {s['PRE']}",
        ]
        if m in ("TON", "RTO"):
            on = [
                *accumulate,
                f"{s['EN']} = True",
                f"{s['DN']} = {s['ACC']} >= {s['PRE']}",
                f"{s['TT']} = not {s['DN']}",
            ]
            if m == "TON":
                off = [f"{s['EN']} = {s['TT']} = {s['DN']} = False", f"{s['ACC']} = 0"]
            else:
                off = [f"{s['EN']} = {s['TT']} = False", f"{s['DN']} = {s['ACC']} >= {s['PRE']}"]
        else:  # TOF
            on = [f"{s['EN']} = {s['DN']} = True", f"{s['TT']} = False", f"{s['ACC']} = 0"]
            off = [
                f"if {s['EN']}:",
                f"    {s['EN']} = False",
                f"    {s['ACC']} = 0",
                f"    {s['TT']} = {s['DN']}",
                f"elif {s['TT']}:",
                f"    _a = {s['ACC']} + dt",
                f"    {s['ACC']} = _a if _a < {s['PRE']} else {s['PRE']}",
                f"if {s['TT']} and {s['ACC']} >= {s['PRE']}:",
                f"    {s['TT']} = {s['DN']} = False",
            ]
        self._if_else(power, on, off)

    def counter(self, m: str, refs, power: str) -> None:
        sym = refs[0].symbol
        assert sym is not None
        s = {k: f"v[{i}]" for k, i in sym.members.items()}
        if sym.members["PRE"] not in self.fixed_presets:
            self.emit(f"{s['PRE']} = {refs[1].expr}")
        edge = s["CU"] if m == "CTU" else s["CD"]
        if m == "CTU":
            step = [
                "    _a = " + s["ACC"] + " + 1",
                "    if _a > 32767:",
                "        _a = -32768",
                f"        {s['OV']} = True",
            ]
        else:
            step = [
                "    _a = " + s["ACC"] + " - 1",
                "    if _a < -32768:",
                "        _a = 32767",
                f"        {s['UN']} = True",
            ]
        on = [f"if not {edge}:", *step, f"    {s['ACC']} = _a", f"{edge} = True"]
        off = [f"{edge} = False"]
        self._if_else(power, on, off)
        self.emit(f"{s['DN']} = {s['ACC']} >= {s['PRE']}")

    def _if_else(self, power: str, on: list[str], off: list[str]) -> None:
        if power == "True":
            for line in on:
                self.emit(line)
            return
        self.emit(f"if {power}:")
        for line in on:
            self.emit(line, 1)
        self.emit("else:")
        for line in off:
            self.emit(line, 1)


def _wrap_lines() -> list[str]:
    return [
        "if _r < -32768 or _r > 32767:",
        "    _r = ((_r + 32768) & 65535) - 32768",
        f"    v[{SLOT_OVERFLOW}] = True",
    ]


def _walk(items: list[RElement]):
    for el in items:
        if isinstance(el, RBranch):
            for leg in el.legs:
                yield from _walk(leg)
        else:
            yield el


def _fixed_presets(resolved: Resolved) -> set[int]:
    """PRE slots driven by exactly one constant: stored once in `v_init`, not every scan.

    Mutates `resolved.table.v_init` for those slots.
    """
    seen: dict[int, set[int | None]] = {}
    for rr in resolved.rungs:
        for el in _walk(rr.elements):
            if el.spec.mnemonic in ("TON", "TOF", "RTO", "CTU", "CTD"):
                sym = el.refs[0].symbol
                assert sym is not None
                seen.setdefault(sym.members["PRE"], set()).add(el.refs[1].value)
    fixed: set[int] = set()
    for slot, values in seen.items():
        if len(values) == 1 and None not in values:
            resolved.table.v_init[slot] = next(iter(values))
            fixed.add(slot)
    return fixed


def generate(resolved: Resolved) -> tuple[str, list[int | None]]:
    """Python source of the scan function and, per generated line, the rung it belongs to."""
    rungs = resolved.rungs
    # every JMP gets a flag; it guards the rungs strictly between it and its label
    jump_ids: dict[tuple[int, int], str] = {}
    covers: list[set[str]] = [set() for _ in rungs]
    for rr in rungs:
        for seq, label in enumerate(rr.jumps):
            name = f"j{len(jump_ids)}"
            jump_ids[(rr.number, seq)] = name
            target = resolved.labels[label]
            for k in range(rr.number + 1, target):
                covers[k].add(name)
    fixed_presets = _fixed_presets(resolved)
    lines: list[str] = []
    line_rung: list[int | None] = []

    def put(text: str, rung: int | None) -> None:
        lines.append(text)
        line_rung.append(rung)

    put(f"def {FUNC_NAME}(ix, qx, mx, iw, qw, mw, v, dt):", None)
    put(
        f'    """Program {resolved.program.name!r} from {resolved.program.file}, '
        f'{len(rungs)} rungs."""',
        None,
    )
    if jump_ids:
        put("    " + " = ".join(jump_ids.values()) + " = False", None)
    for rr in rungs:
        guard = covers[rr.number]
        base = 1
        text = format_elements(resolved.program.rungs[rr.number].elements)
        if len(text) > 80:
            text = text[:77] + "..."
        if guard:
            put(f"    if not ({' or '.join(sorted(guard))}):", rr.number)
            base = 2
        put("    " * base + f"# rung {rr.number} (line {rr.line}): {text}", rr.number)
        gen = _RungGen(rr, jump_ids, fixed_presets)
        gen.seq(rr.elements, "True", top=True)
        if not gen.out:
            gen.emit("pass")
        for indent, stmt in gen.out:
            put("    " * (base + indent) + stmt, rr.number)
    put("    return None", None)
    return "\n".join(lines) + "\n", line_rung
